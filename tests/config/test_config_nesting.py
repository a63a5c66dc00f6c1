"""YAML nested thousands of levels deep is an Error naming the file, not a RecursionError
traceback (hostile input)."""

import pytest

from d3cli.config import MAX_YAML_DEPTH, load_config
from d3cli.data.layouts import discover
from d3cli.errors import ConfigError, InputError


@pytest.mark.parametrize("levels", [MAX_YAML_DEPTH + 5, 5000])
def test_deep_config_and_manifest_are_refused(tmp_path, levels):
    path = tmp_path / "deep.yaml"
    path.write_text("cost: " + "[" * levels + "]" * levels + "\n")
    with pytest.raises(ConfigError, match=rf"deep\.yaml(:1)?: YAML nested more than {MAX_YAML_DEPTH} levels deep; "
                                          r"write a flat config or manifest"):
        load_config(path)
    path.write_text("pairs: " + "[" * levels + "]" * levels + "\n")
    with pytest.raises(InputError, match=rf"deep\.yaml(:1)?: YAML nested more than {MAX_YAML_DEPTH} levels deep"):
        discover([path])


def test_deep_set_value_is_refused():
    with pytest.raises(ConfigError, match=rf"^--set cost\.window=\[{{45}}\.\.\.: YAML nested more than {MAX_YAML_DEPTH} levels"):
        load_config(overrides=["cost.window=" + "[" * 5000 + "]" * 5000])


def test_moderate_nesting_is_still_read_and_checked(tmp_path):
    path = tmp_path / "ok.yaml"
    path.write_text("cost:\n  level_windows: [[5]]\n")
    with pytest.raises(ConfigError, match="level_windows"):  # a type error, not a depth error
        load_config(path)
