"""What a wheel carries and how a pip user finds it: the bundled configs by name, py.typed,
LICENSE, type hints on the public API.  (.ci/run builds the wheel itself, installs it in a
fresh environment and checks its contents; these tests check the source of each.)"""

from __future__ import annotations

import os
import re
import sys
import typing
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from d3cli import D3Stereo, DisparityResult, load_config
from d3cli.cli import main
from d3cli.config import Config, ConfigError, bundled_configs, resolve_config

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "d3cli"
NAMES = ["default", "kitti", "middlebury", "paper", "road"]

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - python 3.10
    tomllib = pytest.importorskip("tomli")


def test_the_configs_ship_inside_the_package_from_the_top_level_folder():
    configs = bundled_configs()
    assert list(configs) == NAMES
    # One copy: configs/ at the top of the repository, which users copy and edit; the
    # package's d3cli/presets is a link to it, so the wheel carries the same files.
    assert sorted(p.stem for p in (REPO / "configs").glob("*.yaml")) == NAMES
    assert not (REPO / "configs").is_symlink()
    assert (PACKAGE / "presets").is_symlink()
    assert {Path(p).resolve() for p in configs.values()} == {REPO / "configs" / f"{n}.yaml" for n in NAMES}


def test_load_config_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no configs/ folder here: only the package's copy can answer
    road = load_config("road")
    assert road == load_config(PACKAGE / "presets" / "road.yaml")
    assert road != Config()
    assert road.pyramid.levels == load_config(PACKAGE / "presets" / "road.yaml").pyramid.levels
    assert load_config("road.yaml") == road
    assert load_config("configs/road.yaml") == road  # the path in a checkout, from anywhere
    assert load_config("kitti").aggregation.sgm_p2 == 1.2


def test_a_local_file_of_that_name_wins(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "road.yaml").write_text("pyramid:\n  levels: 2\n")
    assert load_config("road").pyramid.levels == 2
    assert load_config("road.yaml").pyramid.levels == 2
    assert resolve_config("road") == (Path("road.yaml"), "file")
    (tmp_path / "road").write_text("pyramid:\n  levels: 3\n")  # the exact name first
    assert load_config("road").pyramid.levels == 3
    assert resolve_config("kitti") == (bundled_configs()["kitti"], "bundled")


def test_an_unknown_name_lists_the_bundled_ones(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError) as exc:
        load_config("roads")
    assert str(exc.value) == ("roads: no config file of that name and no bundled config 'roads'; give a YAML "
                              "file or a bundled config: default, kitti, middlebury, paper, road")
    with pytest.raises(ConfigError) as exc:
        load_config("roads.yaml")  # a file name: the usual message
    assert str(exc.value) == "roads.yaml: config file not found; check the path given to -c"


def test_run_dash_c_name_outside_a_checkout_and_its_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["run", "nothing-here", "-c", "roads", "-o", "out", "-q"])
    assert result.exit_code == 1
    assert result.output.splitlines() == [
        "Error: roads: no config file of that name and no bundled config 'roads'; give a YAML file or a "
        "bundled config: default, kitti, middlebury, paper, road"]


def test_configs_command_lists_each_name_and_where_it_resolves(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "kitti.yaml").write_text("{}\n")
    result = CliRunner().invoke(main, ["configs"])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert [line.split()[0] for line in lines] == NAMES
    assert lines[0] == f"default     {bundled_configs()['default']} (bundled)"
    assert lines[1] == f"kitti       {tmp_path.resolve() / 'kitti.yaml'} (local file, wins)"


def test_package_data_py_typed_and_license_in_the_project():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert project["tool"]["setuptools"]["package-data"]["d3cli"] == ["py.typed", "presets/*.yaml"]
    assert (PACKAGE / "py.typed").is_file()
    assert project["project"]["license"] == "MIT" and project["project"]["license-files"] == ["LICENSE"]
    license_text = (REPO / "LICENSE").read_text()
    assert license_text.startswith("MIT License\n")  # the license field and the file agree


def test_public_api_has_type_hints():
    compute = typing.get_type_hints(D3Stereo.compute)
    assert compute == {"left": np.ndarray, "right": np.ndarray, "max_disparity": typing.Optional[int],
                       "pair_dir": typing.Optional[typing.Union[str, os.PathLike]], "return": DisparityResult}
    assert typing.get_type_hints(D3Stereo.__init__) == {"cfg": typing.Optional[Config], "return": type(None)}
    fields = typing.get_type_hints(DisparityResult)
    assert fields["timings"] == dict[str, float] and fields["warnings"] == list[str]
    assert fields["disparity"] is np.ndarray and fields["valid"] is np.ndarray
    hints = typing.get_type_hints(load_config)
    assert hints["return"] is Config and hints["overrides"] == typing.Iterable[str]


def test_one_version_everywhere_and_a_changelog_section_for_it():
    import d3cli

    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    assert "version" in pyproject["project"]["dynamic"]
    assert pyproject["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "d3cli.__version__"}
    changelog = (REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    releases = re.findall(r"^## \[([^\]]+)\](?: - (\d{4}-\d{2}-\d{2}))?$", changelog, flags=re.M)
    assert releases[0] == ("Unreleased", "")
    assert releases[1][0] == d3cli.__version__ == "1.0.0"  # the newest release is this version
    # Keep a Changelog: every heading below a release is one of its kinds of change.
    kinds = set(re.findall(r"^### (.+)$", changelog, flags=re.M))
    assert kinds <= {"Added", "Changed", "Deprecated", "Removed", "Fixed", "Security"}
    section = changelog.split(f"## [{d3cli.__version__}]", 1)[1].split("\n## [", 1)[0]
    assert {"### Added", "### Changed", "### Fixed", "### Removed"} <= set(re.findall(r"^### \w+", section, flags=re.M))
