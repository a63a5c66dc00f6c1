"""What an error shows of a ``--set`` option: at most 60 characters of it, the rule every
config message follows for values, however long the option is."""

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.config import QUOTE_CHARS, load_config, shorten
from d3cli.errors import ConfigError

LONG = "x" * 100_000
#: What a message quotes of LONG as a value: its repr's first 57 characters and "...".
QUOTED = "'" + "x" * 56 + "..."


def _message(option: str) -> str:
    with pytest.raises(ConfigError) as info:
        load_config(overrides=[option])
    return str(info.value)


def test_shorten_keeps_short_text_and_cuts_long_text():
    assert shorten("seed.tau=2") == "seed.tau=2"
    assert shorten("a" * QUOTE_CHARS) == "a" * QUOTE_CHARS
    assert shorten("a" * (QUOTE_CHARS + 1)) == "a" * (QUOTE_CHARS - 3) + "..."


@pytest.mark.parametrize("option, rest", [
    (f"seeds.pkrn_min={LONG}", f"seeds.pkrn_min must be a number, got {QUOTED}; "
                               "fix the value of seeds.pkrn_min (see d3cli/presets/default.yaml)"),
    (f"sgbm.mode={LONG}", f"sgbm.mode must be one of sgbm, hh, 3way, hh4, got {QUOTED}; fix the value of sgbm.mode"),
    (f"nosuch.key={LONG}", "unknown section 'nosuch'; valid sections: run, pyramid, cost, features, aggregation, "
                           "seeds, diffusion, inheritance, pt, refine, sgbm, peers, camera, road"),
])
def test_a_long_set_value_is_quoted_by_its_start(option, rest):
    message = _message(option)
    assert message == f"--set {option[:57]}...: {rest}"
    assert len(message) < 400  # was 100,000 characters and more


def test_a_long_option_without_a_key_is_quoted_by_its_start():
    assert _message(LONG) == f"--set {LONG[:57]}...: expected section.key=value (e.g. diffusion.tau=2); fix the option"


def test_the_command_line_shows_one_short_error_line(tmp_path):
    result = CliRunner().invoke(main, ["run", str(tmp_path), "-o", str(tmp_path / "out"), "--set", f"sgbm.mode={LONG}"])
    assert result.exit_code == 1
    assert result.output == (f"Error: --set sgbm.mode={'x' * 47}...: sgbm.mode must be one of sgbm, hh, 3way, hh4, "
                             f"got {QUOTED}; fix the value of sgbm.mode\n")
