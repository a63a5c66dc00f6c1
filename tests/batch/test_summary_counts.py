"""summary.md, summary.json and report.html count the pairs as run.json does: pairs
kept complete from an earlier run are "skipped as complete", not silently "ok"."""

from __future__ import annotations

import json
import os

from click.testing import CliRunner

from d3cli.cli import main


def _run(pairs_root, out, *extra):
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(out), "--method", "sgbm", "--eval", *extra])
    assert result.exit_code == 0, result.output
    return json.loads((out / "run.json").read_text())


def _counts_line(out) -> str:
    (line,) = [text for text in (out / "summary.md").read_text().splitlines() if text.startswith("3 pairs:")]
    return line


def test_summary_counts_agree_with_run_json_on_a_rerun(tmp_path, pairs_root):
    out = tmp_path / "out"
    first = _run(pairs_root, out)
    assert (first["n_computed"], first["n_skipped"], first["n_failed"]) == (3, 0, 0)
    assert _counts_line(out) == "3 pairs: 3 ok (3 computed, 0 skipped as complete), 0 failed."

    # One input changes: that pair is computed again, the other two are kept.
    left = pairs_root / "b" / "left.png"
    stat = left.stat()
    os.utime(left, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    again = _run(pairs_root, out)
    assert [p["status"] for p in again["pairs"]] == ["skipped", "ok", "skipped"]
    assert _counts_line(out) == "3 pairs: 3 ok (1 computed, 2 skipped as complete), 0 failed."
    assert "<p>3 pairs: 3 ok (1 computed, 2 skipped as complete), 0 failed. " in (out / "report.html").read_text()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run"] == {"n_computed": again["n_computed"], "n_skipped": again["n_skipped"],
                              "n_failed": again["n_failed"]} == {"n_computed": 1, "n_skipped": 2, "n_failed": 0}
    assert summary["counts"]["ok"] == 3  # the means are over every pair with a map, as before


def test_a_failed_pair_is_counted_alike(tmp_path, pairs_root):
    (pairs_root / "c" / "right.png").write_bytes(b"not a png")
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(out), "--method", "sgbm", "--eval"])
    assert result.exit_code == 1
    run = json.loads((out / "run.json").read_text())
    assert (run["n_computed"], run["n_skipped"], run["n_failed"]) == (2, 0, 1)
    assert _counts_line(out) == "3 pairs: 2 ok (2 computed, 0 skipped as complete), 1 failed."


def test_report_title_names_the_command_then_the_method(tmp_path, pairs_root):
    # the title was f"d3stereo {method}: {out}", which read "d3stereo d3stereo: out" for the
    # default method; now the command, the output folder and the method in brackets
    out = tmp_path / "out"
    _run(pairs_root, out)
    assert f"<h1>d3stereo run: {out} (sgbm)</h1>" in (out / "report.html").read_text()
