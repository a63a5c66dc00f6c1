"""`synth --seed` must be a seed numpy accepts: a negative one is an Error, not a traceback."""

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.data import synth
from d3cli.errors import InputError


def test_negative_seed_is_refused_before_writing(tmp_path):
    with pytest.raises(InputError) as info:
        synth.generate_dataset(tmp_path / "s", n=1, seed=-1, width=64, height=48)
    assert str(info.value) == "synth: --seed is -1; give a seed >= 0 (the same seed gives the same pairs)"
    assert not (tmp_path / "s").exists()


def test_negative_seed_on_the_command_line_is_one_error_line(tmp_path):
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "s"), "--n", "1", "--seed", "-1",
                                       "--width", "64", "--height", "48"])
    assert result.exit_code == 1
    assert result.output == "Error: synth: --seed is -1; give a seed >= 0 (the same seed gives the same pairs)\n"
