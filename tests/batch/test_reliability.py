"""The batch runner against a hostile user: links where files should be, absurd worker
counts, schedulers that do not answer, outputs changed behind its back, kills in the
middle of a pair, and bugs in a pair's steps."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

import d3cli.batch.extras
import d3cli.batch.runner
from d3cli.batch import LOCK_FILE, OUTPUT_FILES, parse_workers
from d3cli.batch.executors.cluster import probe_scheduler
from d3cli.batch.executors import PoolExecutor, SerialExecutor, make_executor
from d3cli.cli import main
from d3cli.errors import ConfigError


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error:")]


def digest(root):
    return {p.relative_to(root): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(Path(root).rglob("*"))
            if p.is_file() and not p.is_symlink()}


def run_json(out):
    return json.loads((out / "run.json").read_text())


def python_module(code: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``code`` as a module (``python -m``), as the d3stereo command runs."""
    (cwd / "inject_d3.py").write_text(textwrap.dedent(code))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [os.getcwd(), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "inject_d3"], capture_output=True, text=True, env=env,
                          timeout=timeout, cwd=cwd)


@pytest.fixture
def two_pairs(tmp_path, make_pair_folder):
    root = tmp_path / "in"
    make_pair_folder(root, "a", seed=0)
    make_pair_folder(root, "b", shift=5, seed=1)
    return root


# ----------------------------------------------------------------------------- links into OUT
def test_lock_file_that_is_a_link_to_a_user_file_is_refused_and_the_file_untouched(tmp_path, two_pairs):
    out = tmp_path / "out"
    out.mkdir()
    mine = tmp_path / "thesis.txt"
    mine.write_text("chapter 1\n")
    (out / LOCK_FILE).symlink_to(mine)
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert error_lines(result.output) == [
        f"Error: {out / LOCK_FILE}: is a symbolic link (to {mine}), not a lock file of d3stereo; "
        "remove the link (what it points to is left alone) and rerun"]
    assert mine.read_text() == "chapter 1\n" and (out / LOCK_FILE).is_symlink()
    assert not (out / "a").exists()


def test_lock_file_that_is_a_hard_link_is_refused(tmp_path, two_pairs):
    out = tmp_path / "out"
    out.mkdir()
    mine = tmp_path / "thesis.txt"
    mine.write_text("chapter 1\n")
    os.link(mine, out / LOCK_FILE)
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert error_lines(result.output) == [
        f"Error: {out / LOCK_FILE}: has 2 names (a hard link to another file), not a lock file of d3stereo; "
        "remove it (nothing else is touched) and rerun"]
    assert mine.read_text() == "chapter 1\n"


def test_pair_folder_linked_into_the_inputs_is_refused_and_nothing_is_written(tmp_path, two_pairs):
    (two_pairs / "a" / "panel.png").write_bytes(b"my own panel")
    out = tmp_path / "out"
    out.mkdir()
    (out / "a").symlink_to(two_pairs / "a")
    before = digest(two_pairs)
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert error_lines(result.output) == [
        f"Error: {out / 'a'}: is a symbolic link leading outside the output folder (to {two_pairs / 'a'}); "
        "remove the link (what it points to is left alone) or choose another -o folder"]
    assert digest(two_pairs) == before


def test_a_link_inside_out_is_replaced_never_written_through(tmp_path, two_pairs):
    out = tmp_path / "out"
    (out / "elsewhere").mkdir(parents=True)
    (out / "elsewhere" / "keep.txt").write_text("mine")
    (out / "a").symlink_to(out / "elsewhere")
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    assert not (out / "a").is_symlink() and (out / "a" / "result.json").is_file()
    assert sorted(os.listdir(out / "elsewhere")) == ["keep.txt"]


def test_a_file_where_a_pair_folder_goes_is_refused_and_kept(tmp_path, two_pairs):
    out = tmp_path / "out"
    out.mkdir()
    (out / "b").write_text("my notes")
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert error_lines(result.output) == [
        f"Error: {out / 'b'}: is a file, where pair b writes its folder; move it away or choose another -o folder"]
    assert (out / "b").read_text() == "my notes"


def test_out_may_be_a_new_folder_in_the_images_own_folder(tmp_path, make_pair_folder, monkeypatch):
    folder = make_pair_folder(tmp_path, "shots", gt=False)
    monkeypatch.chdir(folder)
    before = digest(folder)
    result = invoke("run", "left.png", "right.png", "-o", "out", "--method", "sgbm")
    assert result.exit_code == 0, result.output
    assert (folder / "out" / "shots" / "result.json").is_file()
    assert {k: v for k, v in digest(folder).items() if k.parts[0] != "out"} == before


def test_out_that_is_an_input_folder_is_still_refused(tmp_path, make_pair_folder, monkeypatch):
    folder = make_pair_folder(tmp_path, "shots", gt=False)
    monkeypatch.chdir(folder)
    result = invoke("run", "left.png", "right.png", "-o", ".", "--method", "sgbm")
    assert error_lines(result.output) == [
        f"Error: .: the output folder holds input files of pair shots ({folder / 'left.png'}); choose an output "
        "folder outside the input data with -o (a new folder beside the inputs is fine)"]


# ----------------------------------------------------------------------------- workers
def test_workers_beyond_the_pairs_are_never_started():
    assert isinstance(make_executor(1000, n_pairs=1), SerialExecutor)
    pool = make_executor(1000, n_pairs=2)
    assert isinstance(pool, PoolExecutor) and pool.workers == 2
    assert make_executor(3, n_pairs=10).workers == 3


def test_a_thousand_workers_on_two_pairs_finish_promptly(tmp_path, two_pairs):
    out = tmp_path / "out"
    started = time.monotonic()
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm", "--workers", "1000")
    assert result.exit_code == 0, result.output
    assert time.monotonic() - started < 120
    assert run_json(out)["execution"]["workers"] == 2
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok", "ok"]


@pytest.mark.parametrize("value", ["99999999999999999999", "1025"])
def test_absurd_worker_counts_are_one_error_line(tmp_path, two_pairs, value):
    with pytest.raises(ConfigError, match="at most 1024 processes"):
        parse_workers(value)
    result = invoke("run", two_pairs, "-o", tmp_path / "out", "--workers", value)
    assert result.exit_code == 1 and "Traceback" not in result.output
    (line,) = error_lines(result.output)
    assert line.startswith(f"Error: --workers {value}: at most 1024 processes; use 'auto' for one per core (")
    assert parse_workers("1024") == 1024


# ----------------------------------------------------------------------------- schedulers
@pytest.fixture
def listener():
    """Factory: a 127.0.0.1 listener that accepts and then stays silent or sends random bytes."""
    sockets = []

    def _start(send_garbage: bool) -> str:
        server = socket.create_server(("127.0.0.1", 0))
        sockets.append(server)

        def serve():
            while True:
                try:
                    conn, _ = server.accept()
                except OSError:
                    return
                sockets.append(conn)
                if send_garbage:
                    conn.sendall(os.urandom(4096))

        threading.Thread(target=serve, daemon=True).start()
        return f"tcp://127.0.0.1:{server.getsockname()[1]}"

    yield _start
    for s in sockets:
        s.close()


def test_a_listener_that_never_answers_is_an_error_within_the_timeout(listener):
    pytest.importorskip("distributed")
    address = listener(send_garbage=False)
    started = time.monotonic()
    with pytest.raises(ConfigError) as caught:
        probe_scheduler(address, timeout=1)
    assert time.monotonic() - started < 3
    assert str(caught.value) == (f"--scheduler {address}: scheduler unreachable (no answer within 1 s); start one "
                                 "with `dask scheduler` or fix the address (also $DASK_SCHEDULER_ADDRESS)")


def test_a_listener_sending_garbage_is_one_clean_error(listener, capfd):
    pytest.importorskip("distributed")
    address = listener(send_garbage=True)
    with pytest.raises(ConfigError, match=rf"^--scheduler {address}: scheduler unreachable \("):
        probe_scheduler(address, timeout=3)
    assert capfd.readouterr().err == ""


@pytest.mark.parametrize("address", ["silent", "garbage", "notaurl", "tcp://:", "http://127.0.0.1:80"])
def test_bad_scheduler_is_one_error_line_and_nothing_after_it(tmp_path, two_pairs, listener, address):
    """The whole process: one Error line, exit 1, and no ``Exception ignored in:
    Client.__del__`` when the process ends (it came 10 s after the error)."""
    pytest.importorskip("distributed")
    if address in ("silent", "garbage"):
        address = listener(send_garbage=address == "garbage")
    started = time.monotonic()
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    done = subprocess.run([sys.executable, "-m", "d3cli", "run", str(two_pairs), "-o", str(tmp_path / "out"),
                           "--method", "sgbm", "--scheduler", address], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 1
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"Error: --scheduler {address}: scheduler unreachable (")
    assert time.monotonic() - started < 60


# ----------------------------------------------------------------------------- resume checks
@pytest.mark.parametrize("damage", ["truncate", "same-size", "delete"])
def test_resume_recomputes_an_output_changed_since_it_was_written(tmp_path, two_pairs, damage, caplog):
    out = tmp_path / "out"
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    stored = json.loads((out / "a" / "result.json").read_text())
    pfm = out / "a" / "disp.pfm"
    assert stored["files"]["disp.pfm"] == {"size": pfm.stat().st_size,
                                           "sha256": hashlib.sha256(pfm.read_bytes()).hexdigest()}
    assert set(stored["files"]) >= set(OUTPUT_FILES) | {"panel.png", "valid_overlay.png"}
    good = pfm.read_bytes()
    if damage == "truncate":
        os.truncate(pfm, 100)
        why = f"disp.pfm has 100 bytes, {len(good)} when written"
    elif damage == "same-size":
        pfm.write_bytes(good[:-4] + b"\0\0\0\0")
        why = "disp.pfm changed since it was written (SHA-256 differs)"
    else:
        pfm.unlink()
        why = None  # no longer a complete folder: computed again as before
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok", "skipped"]
    assert pfm.read_bytes() == good
    if why is not None:
        assert f"WARNING: a: {why}; computing the pair again" in result.output


def test_a_result_without_file_records_is_computed_again(tmp_path, two_pairs):
    out = tmp_path / "out"
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    stored = json.loads((out / "b" / "result.json").read_text())
    del stored["files"]
    (out / "b" / "result.json").write_text(json.dumps(stored))
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert ("WARNING: b: result.json records no file sizes and hashes (written by an earlier d3stereo); "
            "computing the pair again") in result.output
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok"]


# ----------------------------------------------------------------------------- whole pairs
def test_a_pair_folder_appears_only_once_complete(tmp_path, two_pairs, monkeypatch):
    out = tmp_path / "out"
    seen = []
    real = d3cli.batch.runner.write_panel

    def panel_watched(folder, name, *args, **kwargs):
        seen.append((name, (out / name).exists(), sorted(p.name for p in Path(folder).iterdir())))
        return real(folder, name, *args, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "write_panel", panel_watched)
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    assert [(name, exists) for name, exists, _ in seen] == [("a", False), ("b", False)]
    assert seen[0][2] == sorted([*OUTPUT_FILES, "valid_overlay.png"])
    assert sorted(os.listdir(out)) == ["a", "b", "report.html", "run.json"]


def test_a_kill_in_the_middle_of_a_pair_leaves_no_part_of_it_and_the_rerun_cleans_up(tmp_path, two_pairs):
    code = f"""
        import os, signal, sys
        import d3cli.batch.runner as runner

        panel = runner.write_panel

        def panel_then_kill(folder, name, *args, **kwargs):
            if name == "b":
                os.kill(os.getpid(), signal.SIGKILL)  # as kill -9, or a pool worker's SIGTERM
            return panel(folder, name, *args, **kwargs)

        runner.write_panel = panel_then_kill
        sys.argv = ["d3stereo", "run", {str(two_pairs)!r}, "-o", "out", "--method", "sgbm", "-q"]
        from d3cli.__main__ import entry
        entry()
        """
    done = python_module(code, tmp_path)
    assert done.returncode == -signal.SIGKILL
    out = tmp_path / "out"
    assert (out / "a" / "result.json").is_file() and not (out / "b").exists()
    (leftover,) = [p for p in out.iterdir() if p.name.startswith(".b.partial-")]
    assert sorted(p.name for p in leftover.iterdir()) == sorted([*OUTPUT_FILES, "valid_overlay.png"])
    foreign = out / ".zz.partial-1234"  # a pair of another run (a shard): not ours to remove
    foreign.mkdir()
    os.unlink(out / LOCK_FILE)  # the killed run's lock (it would be taken over with a warning)
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 0, result.output
    assert [p["status"] for p in run_json(out)["pairs"]] == ["skipped", "ok"]
    assert not leftover.exists() and foreign.is_dir()


def test_files_of_the_user_in_a_pair_folder_stay_when_it_is_computed_again(tmp_path, two_pairs):
    out = tmp_path / "out"
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    (out / "a" / "notes.txt").write_text("looks fine")
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm", "--overwrite").exit_code == 0
    assert (out / "a" / "notes.txt").read_text() == "looks fine"
    assert [p.name for p in out.iterdir() if ".partial-" in p.name] == []


# ----------------------------------------------------------------------------- internal errors
def _broken_road_report(*args, **kwargs):
    import cv2

    raise cv2.error("OpenCV(4.10) error: (-4:Insufficient memory) Failed to allocate\n3183098934643681 bytes")


def test_an_internal_error_names_the_pair_and_the_step_and_stores_no_pair(tmp_path, two_pairs, monkeypatch):
    monkeypatch.setattr(d3cli.batch.extras, "road_report", _broken_road_report)
    out = tmp_path / "out"
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm", "--road-report")
    assert result.exit_code == 1 and "Traceback" not in result.output
    failed = [line for line in result.output.splitlines() if line.startswith("failed:")]
    assert failed[0] == ("failed: a: internal error in road report (cv2.error: OpenCV(4.10) error: "
                         "(-4:Insufficient memory) Failed to allocate 3183098934643681 bytes); please report it")
    assert not (out / "a").exists() and not (out / "b").exists()
    monkeypatch.undo()
    again = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert again.exit_code == 0, again.output
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok", "ok"]  # computed, not "skipped as complete"


def test_an_extra_failing_on_a_complete_pair_leaves_it_incomplete(tmp_path, two_pairs, monkeypatch):
    out = tmp_path / "out"
    assert invoke("run", two_pairs, "-o", out, "--method", "sgbm").exit_code == 0
    monkeypatch.setattr(d3cli.batch.extras, "road_report", _broken_road_report)
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm", "--road-report")
    assert result.exit_code == 1
    assert not (out / "a" / "result.json").exists()
    monkeypatch.undo()
    again = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert [p["status"] for p in run_json(out)["pairs"]] == ["ok", "ok"]
    assert again.exit_code == 0


def test_an_internal_error_while_matching_names_the_method(tmp_path, two_pairs, monkeypatch):
    def broken(*args, **kwargs):
        import numpy as np

        np.empty((1 << 28, 1 << 28), np.float64)  # numpy's _ArrayMemoryError, a MemoryError

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", broken)
    result = invoke("run", two_pairs, "-o", tmp_path / "out", "--method", "sgbm")
    assert ("failed: a: internal error in matching (sgbm) (MemoryError: Unable to allocate 512. PiB for an array "
            "with shape (268435456, 268435456) and data type float64); please report it") in result.output


# ----------------------------------------------------------------------------- SIGTERM
def test_sigterm_while_the_pool_starts_is_an_interrupt_with_run_json(tmp_path, two_pairs):
    """The workers die by the same SIGTERM (process group): the pool "could not start",
    but what happened is the SIGTERM: 143, the Terminated line, run.json."""
    code = f"""
        import os, signal, sys
        from d3cli.batch.executors import PoolExecutor

        import d3cli.errors

        def warm_broken(self, cfg, method):
            os.kill(os.getpid(), signal.SIGTERM)  # held back while the workers start
            raise d3cli.errors.D3Error("the --workers processes could not start (fork); run with --workers 1")

        PoolExecutor.warm = warm_broken
        sys.argv = ["d3stereo", "run", {str(two_pairs)!r}, "-o", "out", "--method", "sgbm", "--workers", "2"]
        from d3cli.__main__ import entry
        entry()
        """
    done = python_module(code, tmp_path)
    assert done.returncode == 143, done.stderr
    assert done.stderr.strip().splitlines() == [
        "Terminated (SIGTERM): 0 of 2 pairs done; rerun the same command to resume"]
    run = run_json(tmp_path / "out")
    assert run["interrupted"] is True and run["stop_reason"] == "terminated (SIGTERM)"


def test_sigterm_after_the_summary_exits_143_and_says_so_in_run_json(tmp_path, two_pairs):
    code = f"""
        import os, signal, sys
        import click

        echo = click.echo

        def echo_then_sigterm(message=None, *args, **kwargs):
            result = echo(message, *args, **kwargs)
            if message is not None and str(message).startswith("report:"):  # the summary is out
                os.kill(os.getpid(), signal.SIGTERM)
            return result

        click.echo = echo_then_sigterm
        sys.argv = ["d3stereo", "run", {str(two_pairs)!r}, "-o", "out", "--method", "sgbm"]
        from d3cli.__main__ import entry
        entry()
        """
    done = python_module(code, tmp_path)
    assert done.returncode == 143, (done.returncode, done.stderr)
    assert done.stderr.strip().splitlines()[-1] == (
        "Terminated (SIGTERM): 2 of 2 pairs done; rerun the same command to resume")
    run = run_json(tmp_path / "out")
    assert run["interrupted"] is True
    assert run["stop_reason"] == "terminated (SIGTERM) after the batch had finished"
    assert [p["status"] for p in run["pairs"]] == ["ok", "ok"]


def test_a_full_disk_when_a_pair_folder_is_made_ends_the_batch_with_one_error(tmp_path, two_pairs, monkeypatch):
    import errno
    import pathlib

    real = pathlib.Path.mkdir

    def mkdir_full(self, *args, **kwargs):
        if ".partial-" in self.name and self.name.startswith(".b."):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "mkdir", mkdir_full)
    out = tmp_path / "out"
    result = invoke("run", two_pairs, "-o", out, "--method", "sgbm")
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert error_lines(result.output) == [
        f"Error: {out / 'b'}: cannot create the pair's folder ({os.strerror(errno.ENOSPC)}); free disk space or fix "
        "the permissions of the output folder, then rerun"]
    assert run_json(out)["stop_reason"].startswith(f"{out / 'b'}: cannot create")
    assert (out / "a" / "result.json").is_file()
