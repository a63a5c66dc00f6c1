"""Hostile and odd YAML: alias bombs, non-scalar keys, FIFOs and devices, YAML 1.2
numbers, huge integers.  Each case ends in one short
``Error:`` line, never a traceback, a hang or a memory blow-up."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.config import MAX_CONFIG_INT, load_config, parse_override
from d3cli.data.layouts import discover
from d3cli.errors import ConfigError, InputError

# 368 bytes that expand to 9^9 (~387 million) strings with a plain yaml.safe_load
ALIAS_BOMB = """\
a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
i: &i [*h,*h,*h,*h,*h,*h,*h,*h,*h]
"""


def error_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("Error:")]


def test_alias_bomb_in_a_config_is_refused_before_it_expands(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(ALIAS_BOMB)
    with pytest.raises(ConfigError, match=r"bomb\.yaml: YAML aliases expand to more than 100000 values"):
        load_config(path)
    result = CliRunner().invoke(main, ["run", "-c", str(path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    (line,) = error_lines(result.output)
    assert len(line) < 300


def test_alias_bomb_in_a_manifest_is_refused(tmp_path):
    path = tmp_path / "pairs.yaml"
    path.write_text(ALIAS_BOMB)
    with pytest.raises(InputError, match=r"pairs\.yaml: YAML aliases expand to more than"):
        discover([path])


def test_small_aliases_still_work(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("cost:\n  level_windows: &w [5, 7]\npyramid:\n  levels: 3\n")
    assert load_config(path).cost.level_windows == (5, 7)


def test_recursive_alias_is_an_error(tmp_path):
    path = tmp_path / "loop.yaml"
    path.write_text("cost: &x\n  level_windows: *x\n")
    with pytest.raises(ConfigError, match=r"loop\.yaml:1: a recursive YAML alias"):
        load_config(path)


@pytest.mark.parametrize("text, kind", [("cost:\n  [window]: 5\n", "list"), ("{a: 1}: 2\n", "mapping")])
def test_non_scalar_key_is_a_config_error_with_its_line(tmp_path, text, kind):
    path = tmp_path / "key.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=rf"key\.yaml:\d+: a {kind} used as a key; keys must be plain names"):
        load_config(path)


def test_long_bad_value_is_quoted_briefly(tmp_path):
    path = tmp_path / "long.yaml"
    path.write_text("diffusion:\n  tau: " + "x" * 100_000 + "\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert len(str(info.value)) < 250 and "..." in str(info.value)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_config_on_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "cfg.fifo"
    os.mkfifo(fifo)
    # in a subprocess with a timeout: the bug was a hang on open()
    done = subprocess.run([sys.executable, "-m", "d3cli", "run", "-c", str(fifo), "-o", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert error_lines(done.stderr + done.stdout) == [
        f"Error: {fifo}: cannot read config file: not a regular file (a FIFO, socket or device); give a YAML file"]


@pytest.mark.skipif(not os.path.exists("/dev/zero"), reason="needs /dev/zero")
def test_config_on_a_device_is_refused():
    with pytest.raises(ConfigError, match=r"/dev/zero: cannot read config file: not a regular file"):
        load_config("/dev/zero")


def test_huge_config_file_is_refused(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("# " + "x" * 1_100_000 + "\n")
    with pytest.raises(ConfigError, match=r"big\.yaml: config file of \d+ bytes is larger than 1000000 bytes"):
        load_config(path)


@pytest.mark.parametrize("text, value", [("1e-3", 1e-3), ("1.2e1", 12.0), ("1e300", 1e300), ("2E+2", 200.0),
                                         (".5e1", 5.0), ("1.0e-3", 1e-3)])
def test_yaml_1_2_exponent_numbers_are_numbers(tmp_path, text, value):
    path = tmp_path / "n.yaml"
    path.write_text(f"aggregation:\n  sigma_color: {text}\n")
    assert load_config(path).aggregation.sigma_color == value
    assert parse_override(f"aggregation.sigma_color={text}")[2] == value


def test_exponent_number_for_an_integer_key_is_an_integer(tmp_path):
    assert load_config(overrides=["diffusion.max_sweeps=1e3"]).diffusion.max_sweeps == 1000


@pytest.mark.parametrize("text", ["1e20", "100000000000000000000", "-1e12"])
def test_integers_beyond_32_bits_are_refused_up_front(text):
    with pytest.raises(ConfigError, match=rf"diffusion\.max_sweeps must be an integer of at most {MAX_CONFIG_INT}"):
        load_config(overrides=[f"diffusion.max_sweeps={text}"])


def test_strings_that_look_like_words_stay_strings():
    # the exponent resolver must not turn names into numbers
    with pytest.raises(ConfigError, match="run.method must be one of"):
        load_config(overrides=["run.method=e5"])
