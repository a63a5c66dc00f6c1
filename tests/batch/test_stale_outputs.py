"""What a rerun leaves in OUT.

* a ground truth that cannot be scored fails the pair's evaluation, never its maps;
* a run without ``--eval`` leaves no summary of an earlier ``--eval`` run (another method)
  behind, and the console counts say "skipped" where run.json does;
* disp.png cannot hold disparities >= 256 px: said once per pair in result.json.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import d3cli.batch.runner
from d3cli.batch import OUTPUT_FILES
from d3cli.cli import main
from d3cli.data.formats import read_image, read_pfm, write_pfm


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def run_json(out):
    return json.loads((out / "run.json").read_text())


def stored(out, name):
    return json.loads((out / name / "result.json").read_text())


# ----------------------------------------------------------------------------- item 6
@pytest.mark.parametrize("how", ["overwrite", "settings change"])
def test_bad_ground_truth_fails_the_evaluation_and_keeps_the_maps(tmp_path, pairs_root, how):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    gt = read_pfm(pairs_root / "b" / "disp_gt.pfm")
    write_pfm(pairs_root / "b" / "disp_gt.pfm", gt[:, :80].copy())  # ground truth of another size
    extra = ["--overwrite"] if how == "overwrite" else ["--set", "sgbm.block_size=7"]
    keep = [] if how == "overwrite" else extra  # the settings of the later reruns
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", *extra)
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    assert [line for line in result.output.splitlines() if line.startswith("Error:")] == [
        f"Error: 1 of 3 pairs failed (see {out / 'run.json'})"]
    for name in OUTPUT_FILES:  # the map just computed is kept ...
        assert (out / "b" / name).is_file(), name
    result_b = stored(out, "b")
    assert result_b["metrics"] is None and "ground truth disp_gt.pfm is 48x80" in result_b["evaluation_error"]
    assert not (out / "b" / "error.png").exists()
    assert np.isfinite(read_pfm(out / "b" / "disp.pfm")).mean() > 0.9
    info = run_json(out)
    assert [p["status"] for p in info["pairs"]] == ["ok", "failed", "ok"]
    assert info["pairs"][1]["stage"] == "evaluation"
    assert info["failed"][0]["error"].startswith("b: evaluation failed, maps kept: ")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"ok": 2, "failed": 1, "skipped": 0, "total": 3}
    # ... and kept as complete: a rerun without --eval skips it, a rerun with --eval fails its
    # evaluation again without computing it.
    stamp = (out / "b" / "disp.pfm").stat().st_mtime_ns
    again = invoke("run", pairs_root, "-o", out, "--method", "sgbm", *keep)
    assert again.exit_code == 0, again.output
    assert [p["status"] for p in run_json(out)["pairs"]][1] == "skipped"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", *keep).exit_code == 1
    assert (out / "b" / "disp.pfm").stat().st_mtime_ns == stamp
    # A fixed ground truth is a changed input: the pair is computed and scored.
    write_pfm(pairs_root / "b" / "disp_gt.pfm", gt)
    fixed = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval", *keep)
    assert fixed.exit_code == 0, fixed.output
    assert stored(out, "b")["metrics"]["epe"] < 1.0 and stored(out, "b")["evaluation_error"] is None


def test_unreadable_ground_truth_still_gives_maps(tmp_path, pairs_root):
    out = tmp_path / "out"
    (pairs_root / "a" / "disp_gt.pfm").write_bytes(b"PF\ngarbage")
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 1 and "Traceback" not in result.output
    for name in OUTPUT_FILES:
        assert (out / "a" / name).is_file(), name
    result_a = stored(out, "a")
    assert result_a["max_disparity"] == 96 // 4  # no range from the ground truth
    assert any(w.startswith("disparity range 24 px (image width / 4): the ground truth gives none")
               for w in result_a["warnings"])
    assert result_a["evaluation_error"] and result_a["metrics"] is None
    assert [p["status"] for p in run_json(out)["pairs"]] == ["failed", "ok", "ok"]


# ----------------------------------------------------------------------------- item 7
def test_run_without_eval_removes_the_summary_of_an_earlier_eval_run(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "pt-sgm", "--eval").exit_code == 0
    assert json.loads((out / "summary.json").read_text())["method"] == "pt-sgm"
    (out / "notes.md").write_text("mine")
    (out / "summary.txt").write_text("mine too")
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    for name in ("summary.md", "metrics.csv", "summary.json"):
        assert not (out / name).exists(), name  # they described pt-sgm
    assert (out / "notes.md").read_text() == "mine" and (out / "summary.txt").read_text() == "mine too"
    assert "sgbm" in (out / "report.html").read_text()
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok"] * 3
    assert "sgbm: 3 ok (3 computed, 0 skipped as complete), 0 failed of 3 pairs" in result.output
    # --eval brings them back, scored from the stored maps without computing them again.
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm", "--eval")
    assert result.exit_code == 0, result.output
    assert json.loads((out / "summary.json").read_text())["method"] == "sgbm"
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped"] * 3
    assert (run_json(out)["n_computed"], run_json(out)["n_skipped"]) == (0, 3)
    assert "sgbm: 3 ok (0 computed, 3 skipped as complete), 0 failed of 3 pairs" in result.output
    assert "3 ok, 0 failed, 0 skipped" not in result.output  # the old line contradicting run.json
    assert "[1/3]  a  skipped" in result.output  # the per-pair lines say it too (no terminal)


def test_summary_files_not_written_by_d3stereo_are_kept(tmp_path, pairs_root):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metrics.csv").write_text("name,value\nx,1\n")
    (out / "summary.md").write_text("# My notes\n")
    (out / "summary.json").write_text('{"mine": true}\n')
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    assert (out / "metrics.csv").read_text() == "name,value\nx,1\n"
    assert (out / "summary.md").read_text() == "# My notes\n"
    assert (out / "summary.json").read_text() == '{"mine": true}\n'


# ----------------------------------------------------------------------------- item 18
def test_disparities_beyond_the_png_range_are_warned_once(tmp_path, pairs_root, monkeypatch):
    real = d3cli.batch.runner.compute_pair

    def far(*args, **kwargs):  # the right half of the map 260 px further: beyond 255.996 px
        result = real(*args, **kwargs)
        result.disparity = result.disparity.copy()
        result.disparity[:, 48:] += np.float32(260.0)
        return result

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", far)
    out = tmp_path / "out"
    result = invoke("run", pairs_root, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    disp = read_pfm(out / "a" / "disp.pfm")
    n_far = int((disp * 256 >= 65535.5).sum())
    assert 0 < n_far < disp.size
    assert disp.max() > 256  # the reference keeps them
    png = read_image(out / "a" / "disp.png")
    assert png.max() == 65535 and (png == 65535).sum() >= n_far
    text = (f"disp.png: {n_far} pixels have a disparity >= 256 px and are clipped to 255.996 px "
            "(KITTI uint16 format); disp.pfm holds the exact values")
    assert stored(out, "a")["warnings"].count(text) == 1
    assert result.output.count(f"a: {text}") == 1
    assert text in [w for p in run_json(out)["pairs"] if p["pair"] == "a" for w in p["warnings"]]
    again = invoke("run", pairs_root, "-o", out, "--method", "sgbm")  # skipped: still said once
    assert again.exit_code == 0 and stored(out, "a")["warnings"].count(text) == 1


def test_no_clipping_warning_below_256(tmp_path, pairs_root):
    out = tmp_path / "out"
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    assert not any("disp.png" in w for w in stored(out, "a")["warnings"])


def test_defects_csv_follows_the_pairs_road_outputs(tmp_path):
    data = tmp_path / "synth"
    assert invoke("synth", data, "--n", "1", "--seed", "2", "--width", "320", "--height", "192", "-q").exit_code == 0
    out = tmp_path / "out"
    assert invoke("run", data, "-o", out, "--method", "sgbm", "--road-report", "-q").exit_code == 0
    assert (out / "defects.csv").read_text().startswith("pair,id,kind")
    # Same maps, no --road-report: the pair's road outputs stay, and so does defects.csv.
    assert invoke("run", data, "-o", out, "--method", "sgbm", "-q").exit_code == 0
    assert (out / "defects.csv").is_file()
    # Another method: the map and its road outputs are replaced; defects.csv described them.
    assert invoke("run", data, "-o", out, "--method", "pt-sgm", "-q").exit_code == 0
    assert not list(out.glob("*/defects.json")) and not (out / "defects.csv").exists()


def test_a_defects_csv_of_the_user_is_never_touched(tmp_path, pairs_root):
    out = tmp_path / "out"
    out.mkdir()
    (out / "defects.csv").write_text("my,own\n")
    assert invoke("run", pairs_root, "-o", out, "--method", "sgbm").exit_code == 0
    assert (out / "defects.csv").read_text() == "my,own\n"
