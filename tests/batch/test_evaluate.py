"""`eval` of other tools' outputs: formats, common pairs, prediction folders only read."""

import json
import logging
import os
import shutil

import numpy as np
import pytest

from click.testing import CliRunner

from d3cli.batch import evaluate_folders
from d3cli.cli import main
from d3cli.batch.scoring import find_prediction, read_prediction
from d3cli.data import formats as io, layouts as datasets
from d3cli.errors import InputError


def snapshot(folder):
    """Bytes and mtimes of every file under a folder."""
    return {
        str(p.relative_to(folder)): (p.read_bytes(), os.stat(p).st_mtime_ns)
        for p in sorted(folder.rglob("*")) if p.is_file()
    }


def gt_of(pair):
    return io.read_disparity(pair.gt, scale=pair.gt_scale, invalid=pair.gt_invalid)


def test_flat_kitti_pngs_scored_without_touching_them(tmp_path, pairs_root):
    pairs = datasets.discover([pairs_root])
    flat = tmp_path / "other_tool"
    flat.mkdir()
    for pair in pairs:
        gt = gt_of(pair)
        io.write_kitti_png(flat / f"{pair.name}.png", gt + 1.0)  # every pixel off by exactly 1 px
    before = snapshot(flat)
    outcome = evaluate_folders([flat], pairs, out_dir=tmp_path / "rep", progress=False)
    assert snapshot(flat) == before  # byte-identical, same mtimes, no new file
    rows = outcome["results"]["other_tool"]
    assert [r["status"] for r in rows] == ["ok"] * 3
    for row in rows:
        assert row["avgerr_all"] == pytest.approx(1.0, abs=1 / 256)
        assert row["bad_0.5_all"] == pytest.approx(100.0)
        assert row["d1_all"] == 0.0
    assert (tmp_path / "rep" / "a" / "error.png").is_file()


def test_formats_are_equivalent(tmp_path, pairs_root):
    (pair, *_) = datasets.discover([pairs_root])
    gt = gt_of(pair).astype(np.float32)
    (tmp_path / "x" / pair.name).mkdir(parents=True)
    io.write_pfm(tmp_path / "x" / pair.name / "disp.pfm", gt)
    np.save(tmp_path / f"{pair.name}.npy", gt)
    assert find_prediction(tmp_path / "x", pair.name).name == "disp.pfm"
    a = read_prediction(find_prediction(tmp_path / "x", pair.name))
    b = read_prediction(find_prediction(tmp_path, pair.name))
    np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
    np.testing.assert_allclose(a[np.isfinite(a)], b[np.isfinite(b)])


def test_only_pairs_in_every_set_are_compared(tmp_path, pairs_root, caplog):
    pairs = datasets.discover([pairs_root])
    one, two = tmp_path / "one", tmp_path / "two"
    for folder in (one, two):
        folder.mkdir()
        for pair in pairs:
            io.write_kitti_png(folder / f"{pair.name}.png", gt_of(pair))
    (two / "b.png").unlink()
    with caplog.at_level(logging.WARNING):
        outcome = evaluate_folders([one, two], pairs, out_dir=tmp_path / "rep", progress=False)
    assert outcome["not_compared"] == ["b"]
    assert "b" in caplog.text and "not compared" in caplog.text
    assert [r["pair"] for r in outcome["results"]["one"]] == ["a", "c"]
    assert json.loads((tmp_path / "rep" / "two" / "summary.json").read_text())["extra"]["not_compared"] == ["b"]
    assert (tmp_path / "rep" / "comparison.md").is_file()


def test_report_folder_inside_predictions_is_refused(tmp_path, pairs_root):
    pairs = datasets.discover([pairs_root])
    flat = tmp_path / "flat"
    flat.mkdir()
    io.write_kitti_png(flat / "a.png", gt_of(pairs[0]))
    with pytest.raises(InputError, match="the report folder is inside the prediction folder"):
        evaluate_folders([flat], pairs, out_dir=flat / "rep", progress=False)


def two_folders_named_out(tmp_path, pairs):
    """exp1/out and exp2/out: two prediction folders with the same basename."""
    folders = [tmp_path / "exp1" / "out", tmp_path / "exp2" / "out"]
    for folder in folders:
        folder.mkdir(parents=True)
        for pair in pairs:
            io.write_kitti_png(folder / f"{pair.name}.png", gt_of(pair))
    return folders


def test_same_basename_folders_get_distinct_relative_names(tmp_path, pairs_root):
    pairs = datasets.discover([pairs_root])
    folders = two_folders_named_out(tmp_path, pairs)
    before = [snapshot(folder) for folder in folders]
    outcome = evaluate_folders([str(f.resolve()) for f in folders], pairs, out_dir=tmp_path / "rep", progress=False)
    assert sorted(outcome["results"]) == ["exp1-out", "exp2-out"]
    assert [snapshot(folder) for folder in folders] == before  # nothing written into the predictions
    for name in ("exp1-out", "exp2-out"):
        assert (tmp_path / "rep" / name / "summary.json").is_file()
        assert (tmp_path / "rep" / name / "report.html").is_file()


def test_same_folder_twice_gets_numbered_names(tmp_path, pairs_root):
    pairs = datasets.discover([pairs_root])
    folder = two_folders_named_out(tmp_path, pairs)[0]
    outcome = evaluate_folders([folder, folder], pairs, out_dir=tmp_path / "rep", progress=False)
    assert sorted(outcome["results"]) == ["out", "out-2"]
    assert snapshot(tmp_path / "rep").keys() >= {"out/summary.json", "out-2/summary.json"}


def test_method_names_are_single_safe_folder_names(tmp_path):
    from d3cli.batch.scoring import method_names

    folders = []
    for i, method in enumerate(["../../escape", "/abs/path", "../../escape"]):
        folder = tmp_path / f"m{i}" / "pred"
        folder.mkdir(parents=True)
        (folder / "run.json").write_text(json.dumps({"method": method}))
        folders.append(folder)
    # Only d3stereo's own methods name a folder; any other run.json value is not trusted.
    assert method_names(folders) == ["m0-pred", "m1-pred", "m2-pred"]
    (folders[1] / "run.json").write_text(json.dumps({"method": "sgbm"}))
    assert method_names(folders) == ["m0-pred", "sgbm", "m2-pred"]


def test_a_long_method_name_in_run_json_is_not_blamed_on_the_report_folder(tmp_path, pairs_root):
    """A 300-character method in run.json: the report goes to a folder named after the
    prediction folder, and the command succeeds (the name was never the user's -o)."""
    pairs = datasets.discover([pairs_root])
    pred = tmp_path / "preds"
    pred.mkdir()
    for pair in pairs:
        io.write_kitti_png(pred / f"{pair.name}.png", gt_of(pair))
    (pred / "run.json").write_text(json.dumps({"method": "m" * 300}))
    other = tmp_path / "sgbm-preds"
    shutil.copytree(pred, other)
    (other / "run.json").write_text(json.dumps({"method": "sgbm"}))
    result = CliRunner().invoke(main, ["eval", str(pred), str(other), "--gt", str(pairs_root),
                                       "-o", str(tmp_path / "rep"), "-q"])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "rep").iterdir() if p.is_dir()) == ["preds", "sgbm"]
    assert (tmp_path / "rep" / "preds" / "metrics.csv").is_file()


def test_report_folder_names_are_at_most_100_characters(tmp_path):
    from d3cli.batch.scoring import method_names

    deep = tmp_path / ("a" * 120) / "out"
    other = tmp_path / ("b" * 120) / "out"
    for folder in (deep, other):
        folder.mkdir(parents=True)
    names = method_names([deep, other])
    assert [len(n) for n in names] == [100, 100] and names[0].endswith("a-out") and names[1].endswith("b-out")


@pytest.mark.parametrize("where", ["gt_root", "gt_pair", "inside_gt_pair", "pred", "parent_of_pred"])
def test_report_folder_overlapping_the_inputs_is_refused(tmp_path, pairs_root, where):
    pairs = datasets.discover([pairs_root])
    flat = tmp_path / "preds" / "flat"
    flat.mkdir(parents=True)
    for pair in pairs:
        io.write_kitti_png(flat / f"{pair.name}.png", gt_of(pair))
    out = {"gt_root": pairs_root, "gt_pair": pairs_root / "a", "inside_gt_pair": pairs_root / "a" / "rep",
           "pred": flat, "parent_of_pred": tmp_path / "preds"}[where]
    before = snapshot(tmp_path)
    with pytest.raises(InputError) as info:
        evaluate_folders([flat], pairs, out_dir=out, progress=False)
    assert snapshot(tmp_path) == before
    message = str(info.value)
    assert message.startswith(f"{out}: ")
    assert message.endswith("; give -o a new folder that holds no input and lies inside none "
                            "(predictions and ground truth are only read)")


def test_report_folder_beside_the_pairs_is_accepted(tmp_path, pairs_root):
    (pairs_root / "broken").mkdir()
    (pairs_root / "broken" / "right.png").write_bytes((pairs_root / "a" / "right.png").read_bytes())
    pairs = datasets.discover([pairs_root])
    assert [pair.name for pair in pairs if pair.error] == ["broken"]  # its folder is not pairs_root
    flat = tmp_path / "flat"
    flat.mkdir()
    for pair in (pair for pair in pairs if pair.error is None):
        io.write_kitti_png(flat / f"{pair.name}.png", gt_of(pair))
    outcome = evaluate_folders([flat], pairs, out_dir=pairs_root / "report", progress=False)
    assert outcome["n_failed"] == 0 and outcome["not_compared"] == ["broken"]


def test_fifos_in_a_prediction_folder_are_named_never_opened(tmp_path, pairs_root):
    pairs = datasets.discover([pairs_root])
    pred = tmp_path / "pred"
    for pair in pairs:
        (pred / pair.name).mkdir(parents=True)
        io.write_pfm(pred / pair.name / "disp.pfm", gt_of(pair))
        os.mkfifo(pred / pair.name / "result.json")
    os.mkfifo(pred / "run.json")
    (pred / "a" / "disp.pfm").unlink()
    os.mkfifo(pred / "a" / "disp.pfm")
    outcome = evaluate_folders([pred], pairs, out_dir=tmp_path / "rep", progress=False)
    rows = outcome["results"]["pred"]
    assert [r["status"] for r in rows] == ["failed", "ok", "ok"]
    assert rows[0]["error"] == f"{pred / 'a' / 'disp.pfm'}: not a regular file (a FIFO); give the file itself"
    assert rows[1]["time_s"] is None
