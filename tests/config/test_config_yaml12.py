"""Config numbers and booleans follow YAML 1.2 (core schema), not PyYAML's YAML 1.1:
no octal ``010``, no sexagesimal ``1:30``, no ``yes``/``on`` booleans, no ``1_000``."""

import pytest

from d3cli.config import load_config, parse_override
from d3cli.errors import ConfigError


def config_file(tmp_path, text):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    return path


def test_leading_zero_is_decimal_then_out_of_range(tmp_path):
    path = config_file(tmp_path, "pyramid:\n  levels: 010\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == f"{path}:2: pyramid.levels must be an integer in [1, 8], got 10; fix the value of pyramid.levels"


@pytest.mark.parametrize("text, levels", [("07", 7), ("0o7", 7), ("0x7", 7), ("+3", 3), ("5", 5)])
def test_yaml_1_2_integers(tmp_path, text, levels):
    assert load_config(config_file(tmp_path, f"pyramid:\n  levels: {text}\n")).pyramid.levels == levels


@pytest.mark.parametrize("text", ["1:30", "1_0", "0b11"])
def test_yaml_1_1_only_integers_are_strings(tmp_path, text):
    path = config_file(tmp_path, f"pyramid:\n  levels: {text}\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (f"{path}:2: pyramid.levels must be an integer, got '{text}'; fix the value of "
                               "pyramid.levels (see d3cli/presets/default.yaml)")


@pytest.mark.parametrize("text", ["yes", "no", "on", "off", "y", "n"])
def test_yes_no_are_not_booleans(tmp_path, text):
    path = config_file(tmp_path, f"refine:\n  fill: {text}\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (f"{path}:2: refine.fill must be true or false, got '{text}'; fix the value of "
                               "refine.fill (see d3cli/presets/default.yaml)")


@pytest.mark.parametrize("text, value", [("true", True), ("False", False), ("TRUE", True)])
def test_yaml_1_2_booleans(tmp_path, text, value):
    assert load_config(config_file(tmp_path, f"refine:\n  fill: {text}\n")).refine.fill is value


@pytest.mark.parametrize("text, value", [("1e-3", 0.001), ("2.5E2", 250.0), (".5", 0.5), ("-0.0", 0.0), ("3.", 3.0)])
def test_yaml_1_2_floats(tmp_path, text, value):
    assert load_config(config_file(tmp_path, f"cost:\n  min_variance: {text}\n")).cost.min_variance == value


def test_set_values_follow_yaml_1_2_too():
    assert parse_override("pyramid.levels=010") == ("pyramid", "levels", 10)
    assert parse_override("refine.fill=yes") == ("refine", "fill", "yes")
    assert parse_override("refine.fill=~") == ("refine", "fill", None)
    assert parse_override("run.color_range=[1, .inf]") == ("run", "color_range", [1, float("inf")])


def test_infinite_colour_range_is_refused(tmp_path):
    path = config_file(tmp_path, "run:\n  color_range: [1, .inf]\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (f"{path}:2: run.color_range must be a number, got inf; fix the value of "
                               "run.color_range (see d3cli/presets/default.yaml)")
