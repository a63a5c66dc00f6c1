"""A pair named like a file the batch writes into OUT (run.json, report.html, the summary
files, a shard's record...) fails up front, before it is computed: the other pairs run
and the batch is recorded.  An OUT where such a name is already a folder is refused
before anything runs.  CLI runs use ``--method sgbm`` on tiny pairs.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from d3cli.cli import main


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error:")]


def failed_lines(output):
    return [line for line in output.splitlines() if line.startswith("failed:")]


def reserved_message(name: str, out: Path, taken: str) -> str:
    return (f"{name}: the pair's name is taken by a file d3stereo writes into the output folder ({out / taken}); "
            "rename the pair (its folder, or its name in the manifest) and rerun")


@pytest.fixture
def with_pair_named(tmp_path, make_pair_folder):
    def _make(name):
        root = tmp_path / "pairs"
        make_pair_folder(root, "a", shift=4, seed=0)
        make_pair_folder(root, name, shift=5, seed=1)
        make_pair_folder(root, "b", shift=6, seed=2)
        return root
    return _make


@pytest.mark.parametrize("name", ["run.json", "report.html", "summary.md", "summary.json", "metrics.csv",
                                  "defects.csv", "run-1-of-2.json", "Run.JSON"])
def test_a_pair_named_like_a_batch_file_fails_alone_and_the_batch_is_recorded(tmp_path, with_pair_named, name):
    root = with_pair_named(name)
    out = tmp_path / "out"
    for _attempt in range(2):  # the rerun ends the same way, the good pairs skipped as complete
        result = invoke("run", root, "-o", out, "--method", "sgbm", "--eval")
        assert result.exit_code == 1, result.output
        assert "Traceback" not in result.output
        taken = name.lower() if name != "run-1-of-2.json" else name
        assert failed_lines(result.output) == [f"failed: {reserved_message(name, out, taken)}"]
        assert error_lines(result.output) == [f"Error: 1 of 3 pairs failed (see {out / 'run.json'})"]
        record = json.loads((out / "run.json").read_text())
        assert {p["pair"]: p["status"] for p in record["pairs"]}[name] == "failed"
        assert all((out / f).is_file() for f in ("run.json", "report.html", "metrics.csv", "summary.md"))
        assert not (out / name).is_dir()
        assert (out / "a" / "disp.pfm").is_file() and (out / "b" / "disp.pfm").is_file()
    assert [p["status"] for p in record["pairs"] if p["pair"] != name] == ["skipped", "skipped"]


def test_a_pair_named_like_its_shard_record_fails_alone(tmp_path, with_pair_named):
    root = with_pair_named("run-1-of-2.json")
    out = tmp_path / "out"
    result = invoke("run", root, "-o", out, "--method", "sgbm", "--shard", "1/2")
    assert result.exit_code == 1, result.output
    assert failed_lines(result.output) == [f"failed: {reserved_message('run-1-of-2.json', out, 'run-1-of-2.json')}"]
    assert (out / "run-1-of-2.json").is_file()


def test_an_output_folder_with_a_batch_file_name_taken_by_a_folder_is_refused(tmp_path, with_pair_named):
    """An OUT written by an earlier d3stereo, which put such a pair's folder there."""
    root = with_pair_named("x")
    out = tmp_path / "out"
    (out / "run.json").mkdir(parents=True)
    (out / "run.json" / "result.json").write_text("{}")
    result = invoke("run", root, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1
    assert error_lines(result.output) == [
        f"Error: {out / 'run.json'}: is a folder, where d3stereo writes a file of the batch; move it away "
        "(a pair's folder: rename the pair) or choose another -o folder"]
    assert not (out / "a").exists()
    assert (out / "run.json" / "result.json").read_text() == "{}"


def test_eval_fails_such_a_pair_alone(tmp_path, with_pair_named):
    root = with_pair_named("metrics.csv")
    preds = tmp_path / "preds"
    for name in ("a", "metrics.csv", "b"):  # predictions as flat files: nothing of the run's names
        folder = preds / name
        folder.mkdir(parents=True)
        (folder / "disp.pfm").write_bytes((root / name / "disp_gt.pfm").read_bytes())
    out = tmp_path / "report"
    result = invoke("eval", preds, "--gt", root, "-o", out)
    assert result.exit_code == 1, result.output
    message = reserved_message("metrics.csv", out, "metrics.csv")
    assert failed_lines(result.output) == [f"failed: preds/metrics.csv: {message}"]  # eval's method/pair prefix
    assert (out / "metrics.csv").is_file() and (out / "summary.md").is_file()
    assert not (out / "metrics.csv").is_dir()


def test_reserved_names():
    from d3cli.batch.outputs import reserved_name

    for name in ("run.json", "REPORT.html", "run-3-of-12.json", ".d3stereo.lock", ".d3stereo-shard-1-of-2.lock",
                 "road_survey.json", "defects.geojson", "Track.GeoJSON"):
        assert reserved_name(name) is not None, name
    for name in ("run", "run.json.d", "run-1-of-2.json.bak", "metrics", "a", "report.htm"):
        assert reserved_name(name) is None, name
