"""``run --outputs``: which per-pair files a run writes, what a rerun adds, and bad values."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from d3cli.cli import main

ALL_MAP_FILES = {"disp.pfm", "disp.png", "disp_color.png", "valid.png", "valid_overlay.png", "panel.png",
                 "error.png", "result.json"}
ROAD_FILES = {"height.pfm", "height_color.png", "defects.json", "defects.png"}


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def files(folder):
    return {p.name for p in folder.iterdir()}


def test_survey_writes_the_maps_and_json_and_a_rerun_adds_what_is_asked(tmp_path, pairs_root):
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", "-q", "--outputs", "survey")
    assert result.exit_code == 0, result.output
    assert files(out / "a") == {"disp.pfm", "valid.png", "result.json"}
    recorded = set(json.loads((out / "a" / "result.json").read_text())["files"])
    assert recorded == {"disp.pfm", "valid.png"}
    # eval and export read disp.pfm: they work on a survey run
    assert invoke("eval", out, "--gt", pairs_root, "-o", tmp_path / "ev", "-q").exit_code == 0
    # a rerun with more outputs keeps the maps (skipped) and writes the files asked for
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", "-q", "--outputs", "survey,kitti")
    assert result.exit_code == 0, result.output
    assert files(out / "a") == {"disp.pfm", "valid.png", "result.json", "disp.png"}
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 0 and "3 skipped" in result.output, result.output
    assert files(out / "a") == ALL_MAP_FILES
    stored = json.loads((out / "a" / "result.json").read_text())
    assert set(stored["files"]) == ALL_MAP_FILES - {"result.json"}
    # complete now: the next rerun skips it as it is
    before = {name: (out / "a" / name).stat().st_mtime_ns for name in ALL_MAP_FILES - {"result.json"}}
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", "-q").exit_code == 0
    assert before == {name: (out / "a" / name).stat().st_mtime_ns for name in before}


def test_a_computed_pair_writes_only_the_chosen_files(tmp_path, pairs_root):
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", "-q", "--set",
                    "run.outputs=survey,pictures")
    assert result.exit_code == 0, result.output
    assert files(out / "b") == ALL_MAP_FILES - {"disp.png"}


def test_road_outputs_follow_the_chosen_set(tmp_path):
    data = tmp_path / "synth"
    assert invoke("synth", data, "--n", "1", "--seed", "2", "--width", "320", "--height", "192", "-q").exit_code == 0
    out = tmp_path / "out"
    result = invoke("run", data, "-o", out, "--method", "sgbm", "--road-report", "--outputs", "survey")
    assert result.exit_code == 0, result.output
    assert any(line.startswith("road: 1 frame") for line in result.output.splitlines())
    (pair,) = [p for p in out.iterdir() if p.is_dir()]
    assert files(pair) == {"disp.pfm", "valid.png", "result.json", "defects.json"}
    assert invoke("run", data, "-o", out, "--method", "sgbm", "--road-report", "-q").exit_code == 0
    assert ROAD_FILES <= files(pair) and {"disp_color.png", "panel.png"} <= files(pair)
    # fewer road files asked for: the road files left out go (they would describe another report)
    assert invoke("run", data, "-o", out, "--method", "sgbm", "--road-report", "-q", "--outputs",
                  "survey,height").exit_code == 0
    assert ROAD_FILES & files(pair) == {"height.pfm", "defects.json"}


@pytest.mark.parametrize("value", ["maps", "survey,", "all,png", ""])
def test_a_bad_outputs_value_is_one_error_line(tmp_path, pairs_root, value):
    result = invoke("run", pairs_root, "-o", tmp_path / "out", "--method", "sgbm", "--outputs", value)
    assert result.exit_code == 1
    assert result.output == (f"Error: --outputs {value!r}: not a set of per-pair files; give a comma-separated "
                             "list of all, survey, kitti, pictures, height (e.g. survey,pictures)\n")
    assert not (tmp_path / "out").exists()


def test_a_bad_config_value_is_one_error_line(tmp_path, pairs_root):
    result = invoke("run", pairs_root, "-o", tmp_path / "out", "--method", "sgbm", "--set", "run.outputs=survey,jpg")
    assert result.exit_code == 1
    assert result.output == ("Error: --set run.outputs=survey,jpg: run.outputs must be a comma-separated list of "
                             "all, survey, kitti, pictures, height (e.g. survey,pictures), got 'survey,jpg'; fix the "
                             "value of run.outputs\n")
