"""One lock covers every writer of an output folder: plain runs, shards and ``eval -o``.

Shards of one batch (``--shard I/N``, the same N) write into one OUT at the same time;
anything else that writes OUT (a plain run, an eval report, a shard of another split)
is refused while one of them writes, with one ``Error:`` line naming the writer.

The writer holding the folder is a real ``d3stereo`` process, paused inside its first
pair (``compute_pair`` / ``evaluate_pair`` wait for a file) so that the lock is held for
as long as the test needs; CLI runs use ``--method sgbm`` on tiny pairs.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from d3cli.batch import LOCK_FILE, acquire_lock, release_lock
from d3cli.batch.lock import shard_lock_name
from d3cli.cli import main
from d3cli.errors import OutputError

#: A d3stereo command whose first pair waits until ``GO`` exists (``READY`` says it got there).
HELD = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    import d3cli.batch.scoring, d3cli.batch.runner

    ready, go = Path(os.environ["READY"]), Path(os.environ["GO"])

    def paused(real):
        def wait_then(*args, **kwargs):
            ready.touch()
            while not go.exists():
                time.sleep(0.01)
            return real(*args, **kwargs)
        return wait_then

    d3cli.batch.runner.compute_pair = paused(d3cli.batch.runner.compute_pair)
    d3cli.batch.scoring.evaluate_pair = paused(d3cli.batch.scoring.evaluate_pair)
    from d3cli.cli import main
    main(sys.argv[1:], prog_name="d3stereo")
""")

HOLD_HINT = "wait for it or use another -o folder"
BREAK_HINT = ("if no d3stereo run is writing there (e.g. it was killed on another machine), "
              "rerun with --break-lock; else wait for it or use another -o folder")


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error:")]


def lock_files(out):
    return sorted(p.name for p in Path(out).glob(".d3stereo*.lock"))


@pytest.fixture
def four_pairs(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    for i, name in enumerate("abcd"):
        make_pair_folder(root, name, shift=4 + i, seed=i)
    return root


class Held:
    """A ``d3stereo`` command paused in its first pair, holding its output folder."""

    def __init__(self, tmp_path, *args):
        script = tmp_path / "held.py"
        script.write_text(HELD)
        self.ready, self.go = tmp_path / f"ready-{time.monotonic_ns()}", tmp_path / f"go-{time.monotonic_ns()}"
        env = {**os.environ, "READY": str(self.ready), "GO": str(self.go)}
        self.proc = subprocess.Popen([sys.executable, str(script), *map(str, args)], cwd=tmp_path, env=env,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.pid = self.proc.pid

    def __enter__(self):
        deadline = time.monotonic() + 120
        while not self.ready.exists():
            assert self.proc.poll() is None, self.proc.communicate()
            assert time.monotonic() < deadline, "the held command never reached its first pair"
            time.sleep(0.02)
        return self

    def finish(self):
        self.go.touch()
        stdout, stderr = self.proc.communicate(timeout=120)
        return self.proc.returncode, stdout, stderr

    def __exit__(self, *exc):
        if self.proc.poll() is None:
            self.go.touch()
            try:
                self.proc.communicate(timeout=120)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.communicate()


@pytest.fixture
def predictions(tmp_path, four_pairs):
    """The -o folder of a complete run over four_pairs, to be scored by eval."""
    preds = tmp_path / "preds"
    result = invoke("run", four_pairs, "-o", preds, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    return preds


# ----------------------------------------------------------------------------- eval and run
def test_eval_into_a_folder_a_run_writes_is_refused(tmp_path, four_pairs, predictions):
    out = tmp_path / "out"
    with Held(tmp_path, "run", four_pairs, "-o", out, "--method", "sgbm", "--eval", "-q") as run:
        result = invoke("eval", predictions, "--gt", four_pairs, "-o", out, "-q")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out}: another d3stereo run (pid {run.pid}) is writing here; {HOLD_HINT}"]
        assert not (out / "metrics.csv").exists() and not (out / "report.html").exists()
        status, _, stderr = run.finish()
    assert status == 0, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "sgbm"  # the run's own report, not the eval's
    assert lock_files(out) == []


def test_run_into_a_folder_eval_writes_is_refused(tmp_path, four_pairs, predictions):
    out = tmp_path / "report"
    with Held(tmp_path, "eval", predictions, "--gt", four_pairs, "-o", out, "-q") as evaluation:
        result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out}: another d3stereo eval (pid {evaluation.pid}) is writing here; {HOLD_HINT}"]
        again = invoke("eval", predictions, "--gt", four_pairs, "-o", out, "-q")
        assert error_lines(again.output) == [
            f"Error: {out}: another d3stereo eval (pid {evaluation.pid}) is writing here; {HOLD_HINT}"]
        status, _, stderr = evaluation.finish()
    assert status == 0, stderr
    assert not (out / "run.json").exists() and not (out / "a" / "disp.pfm").exists()
    assert lock_files(out) == []


def test_eval_takes_a_lock_left_behind_only_as_a_run_does(tmp_path, four_pairs, predictions):
    from d3cli.batch import evaluate_folders
    from d3cli.data.layouts import discover

    out = tmp_path / "report"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "elsewhere.example", "command": "d3stereo run"}))
    pairs = discover([four_pairs])
    with pytest.raises(OutputError) as refused:
        evaluate_folders([predictions], pairs, out_dir=out, progress=False)
    assert str(refused.value) == (f"{out}: the folder is locked by a d3stereo run (pid 1 on elsewhere.example) "
                                  f"that may still be running; {BREAK_HINT}")
    assert not (out / "metrics.csv").exists()
    outcome = evaluate_folders([predictions], pairs, out_dir=out, progress=False, break_lock=True)
    assert outcome["n_failed"] == 0 and (out / "metrics.csv").is_file()
    assert lock_files(out) == []


def test_eval_of_several_folders_locks_each_report_folder(tmp_path, four_pairs, predictions):
    """Several prediction folders: the reports go to OUT/<name>/, each locked like OUT."""
    import shutil

    second = tmp_path / "more" / "preds"
    shutil.copytree(predictions, second)
    out = tmp_path / "report"
    (out / "more-preds").mkdir(parents=True)
    held = acquire_lock(out / "more-preds", command="d3stereo run")
    try:
        result = invoke("eval", predictions, second, "--gt", four_pairs, "-o", out, "-q")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out / 'more-preds'}: another d3stereo run (pid {os.getpid()}) is writing here; {HOLD_HINT}"]
        assert not (out / "comparison.md").exists()
    finally:
        release_lock(held)
    result = invoke("eval", predictions, second, "--gt", four_pairs, "-o", out, "-q")
    assert result.exit_code == 0, result.output
    assert (out / "more-preds" / "metrics.csv").is_file() and (out / "comparison.md").is_file()
    assert [p for p in out.rglob(".d3stereo*")] == []


# ----------------------------------------------------------------------------- shards
def test_a_plain_run_while_a_shard_writes_is_refused(tmp_path, four_pairs):
    out = tmp_path / "out"
    with Held(tmp_path, "run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2", "-q") as shard:
        result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out}: another d3stereo run --shard 1/2 (pid {shard.pid}) is writing here; {HOLD_HINT}"]
        status, _, stderr = shard.finish()
    assert status == 0, stderr
    assert not (out / "run.json").exists()
    assert [p["status"] for p in json.loads((out / "run-1-of-2.json").read_text())["pairs"]] == ["ok", "ok"]
    assert lock_files(out) == []


def test_a_shard_while_a_plain_run_writes_is_refused(tmp_path, four_pairs):
    out = tmp_path / "out"
    with Held(tmp_path, "run", four_pairs, "-o", out, "--method", "sgbm", "-q") as run:
        result = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "2/2")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out}: another d3stereo run (pid {run.pid}) is writing here; {HOLD_HINT}"]
        status, _, stderr = run.finish()
    assert status == 0, stderr
    assert not (out / "run-2-of-2.json").exists()
    assert [p["status"] for p in json.loads((out / "run.json").read_text())["pairs"]] == ["ok"] * 4
    assert lock_files(out) == []


def test_shards_of_one_batch_write_together(tmp_path, four_pairs):
    out = tmp_path / "out"
    with Held(tmp_path, "run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2", "-q") as shard:
        other = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "2/2")
        assert other.exit_code == 0, other.output
        again = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2")  # the same shard
        assert error_lines(again.output) == [
            f"Error: {out}: another d3stereo run --shard 1/2 (pid {shard.pid}) is writing here; {HOLD_HINT}"]
        status, _, stderr = shard.finish()
    assert status == 0, stderr
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["a", "b", "c", "d"]
    assert lock_files(out) == []


def test_a_shard_of_another_split_is_refused(tmp_path, four_pairs):
    """--shard 1/3 takes other pairs than 1/2 and 2/2: not a shard of the batch writing."""
    out = tmp_path / "out"
    with Held(tmp_path, "run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2", "-q") as shard:
        result = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/3")
        assert result.exit_code == 1, result.output
        assert error_lines(result.output) == [
            f"Error: {out}: another d3stereo run --shard 1/2 (pid {shard.pid}) is writing here; {HOLD_HINT}"]
        status, _, stderr = shard.finish()
    assert status == 0, stderr
    assert not (out / "run-1-of-3.json").exists()
    assert lock_files(out) == []


# ----------------------------------------------------------------------------- records left behind
def test_a_shard_lock_of_another_host_stops_a_plain_run_unless_broken(tmp_path, four_pairs):
    """A shard killed on another machine leaves its record; a plain run cannot tell whether
    it still writes (a file system without working flock across hosts)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / shard_lock_name(2, 2)).write_text(json.dumps({"pid": 1, "host": "elsewhere.example",
                                                         "command": "d3stereo run --shard 2/2"}))
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1
    assert error_lines(result.output) == [
        f"Error: {out}: the folder is locked by a d3stereo run --shard 2/2 (pid 1 on elsewhere.example) "
        f"that may still be running; {BREAK_HINT}"]
    assert not (out / "a").exists()
    broken = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--break-lock")
    assert broken.exit_code == 0, broken.output
    assert lock_files(out) == []


def test_a_plain_lock_of_another_host_stops_a_shard_unless_broken(tmp_path, four_pairs):
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "elsewhere.example", "command": "d3stereo eval"}))
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2")
    assert error_lines(result.output) == [
        f"Error: {out}: the folder is locked by a d3stereo eval (pid 1 on elsewhere.example) "
        f"that may still be running; {BREAK_HINT}"]
    broken = invoke("run", four_pairs, "-o", out, "--method", "sgbm", "--shard", "1/2", "--break-lock")
    assert broken.exit_code == 0, broken.output
    assert lock_files(out) == []


def test_stale_shard_locks_of_this_host_are_taken_over(tmp_path, four_pairs):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    out = tmp_path / "out"
    out.mkdir()
    (out / shard_lock_name(1, 2)).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname()}))
    result = invoke("run", four_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    assert lock_files(out) == []


# ----------------------------------------------------------------------------- the lock itself
def test_folder_lock_modes_in_one_process(tmp_path):
    """flock locks belong to open files: two in one process exclude each other as two
    processes would."""
    shard1 = acquire_lock(tmp_path, shard=(1, 2), command="d3stereo run --shard 1/2")
    shard2 = acquire_lock(tmp_path, shard=(2, 2), command="d3stereo run --shard 2/2")
    try:
        both = (f"{tmp_path}: d3stereo run --shard 1/2 (pid {os.getpid()}) and d3stereo run --shard 2/2 "
                f"(pid {os.getpid()}) are writing here; wait for them or use another -o folder")
        other_split = f"{tmp_path}: another d3stereo run --shard 1/2 (pid {os.getpid()}) is writing here; {HOLD_HINT}"
        for shard, command, message in ((None, "d3stereo run", both), (None, "d3stereo eval", both),
                                        ((1, 3), "d3stereo run --shard 1/3", other_split)):
            with pytest.raises(OutputError) as refused:
                acquire_lock(tmp_path, shard=shard, command=command)
            assert str(refused.value) == message
        with pytest.raises(OutputError, match=rf"another d3stereo run --shard 1/2 \(pid {os.getpid()}\) is writing"):
            acquire_lock(tmp_path, shard=(1, 2), command="d3stereo run --shard 1/2")
    finally:
        release_lock(shard1)
    assert lock_files(tmp_path) == sorted([LOCK_FILE, shard_lock_name(2, 2)])  # shard 2 still writes
    release_lock(shard2)
    assert lock_files(tmp_path) == []
    plain = acquire_lock(tmp_path, command="d3stereo eval")
    try:
        with pytest.raises(OutputError, match=rf"another d3stereo eval \(pid {os.getpid()}\) is writing here"):
            acquire_lock(tmp_path, shard=(1, 2), command="d3stereo run --shard 1/2")
    finally:
        release_lock(plain)
    assert lock_files(tmp_path) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_record_with_a_strange_command_names_a_run(tmp_path):
    """A record is read back from a file anyone could have written: only a d3stereo
    command, printable and short, is quoted."""
    (tmp_path / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "elsewhere.example",
                                                  "command": "rm -rf /\n" + "x" * 1000}))
    with pytest.raises(OutputError) as refused:
        acquire_lock(tmp_path)
    assert str(refused.value) == (f"{tmp_path}: the folder is locked by a d3stereo run (pid 1 on elsewhere.example) "
                                  f"that may still be running; {BREAK_HINT}")


def test_eval_break_lock_on_the_command_line(tmp_path, four_pairs, predictions):
    out = tmp_path / "report"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": 1, "host": "elsewhere.example", "command": "d3stereo run"}))
    result = invoke("eval", predictions, "--gt", four_pairs, "-o", out, "-q")
    assert result.exit_code == 1
    assert error_lines(result.output) == [f"Error: {out}: the folder is locked by a d3stereo run (pid 1 on "
                                          f"elsewhere.example) that may still be running; {BREAK_HINT}"]
    result = invoke("eval", predictions, "--gt", four_pairs, "-o", out, "-q", "--break-lock")
    assert result.exit_code == 0, result.output
    assert (out / "metrics.csv").is_file() and lock_files(out) == []
