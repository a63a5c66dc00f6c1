"""Ctrl-C inside a compiled kernel and SIGTERM stop the batch."""

import json
import os
import signal
import subprocess
import sys
import time

from click.testing import CliRunner

import d3cli.batch.runner
from d3cli.batch import LOCK_FILE
from d3cli.cli import main


def _default_sigint():
    """In the child before exec: SIGINT back to its default.  A shell starts background jobs
    with SIGINT ignored, children inherit that, and Python then installs no Ctrl-C handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupting(real, when):
    """``real`` wrapped: after it returns, when ``when(args, kwargs)``, a Ctrl-C arrives."""

    def wrapped(*args, **kwargs):
        value = real(*args, **kwargs)
        if when(args, kwargs):
            signal.raise_signal(signal.SIGINT)
            time.sleep(0.05)  # (a pending signal is handled at the next bytecode)
        return value

    return wrapped


def _run_with_ctrl_c_handler(args):
    """``d3stereo ARGS`` in this process with Python's Ctrl-C handler installed."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # even where a shell ignores SIGINT
    try:
        return CliRunner().invoke(main, args)
    finally:
        signal.signal(signal.SIGINT, previous)


def test_ctrl_c_inside_a_numba_kernel_stops_the_batch_and_fails_no_pair(tmp_path, pairs_root, monkeypatch):
    real = d3cli.batch.runner.compute_pair

    def kernel_interrupted(method, cfg, left, right, *, max_disparity, **kwargs):
        if (tmp_path / "second").exists():
            # what numba raises when SIGINT arrives inside a compiled function
            try:
                raise KeyboardInterrupt
            except KeyboardInterrupt:
                raise SystemError("<numba function> returned a result with an exception set")
        (tmp_path / "second").touch()
        return real(method, cfg, left, right, max_disparity=max_disparity, **kwargs)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", kernel_interrupted)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(out), "--method", "sgbm"])
    assert result.exit_code == 130, result.output
    assert "Interrupted: 1 of 3 pairs done" in result.output
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["n_failed"] == 0
    assert [p["status"] for p in run["pairs"]] == ["ok"]


def test_sigterm_stops_a_serial_batch_with_143_run_json_and_no_lock(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    for i in range(30):  # enough pairs that the signal lands while the batch runs
        make_pair_folder(root, f"p{i:02d}", shift=4 + i % 5, size=(240, 400), seed=i)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(os.getcwd()), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(root), "-o", str(out), "--method", "sgbm"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 90
        while not list(out.glob("*/result.json")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline
            time.sleep(0.005)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == 143, stderr
    assert stderr.strip().splitlines()[-1].startswith("Terminated (SIGTERM): ")
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["stop_reason"] == "terminated (SIGTERM)"
    assert not (out / LOCK_FILE).exists()


def test_ctrl_c_at_eight_moments_of_a_d3stereo_batch(tmp_path, make_pair_folder):
    """SIGINT at eight moments spread over a d3stereo batch (loading kernels,
    discovery, computing, writing) always exits 130 with the resume line, records no pair
    as failed, leaves no lock, and a rerun completes.  (The first tenth of a second, the
    interpreter's own start-up before d3cli runs, is left out: README "Failure behaviour".)"""
    root = tmp_path / "pairs"
    for i in range(6):
        make_pair_folder(root, f"p{i}", shift=3 + i, size=(96, 160), seed=i)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(os.getcwd()), os.environ.get("PYTHONPATH")]))}
    cmd = [sys.executable, "-m", "d3cli", "run", str(root), "--method", "d3stereo", "-q", "--max-disparity", "16"]
    warm = subprocess.run(cmd + ["-o", str(tmp_path / "warm")], capture_output=True, text=True, env=env, timeout=600)
    assert warm.returncode == 0, warm.stderr  # kernels compiled and cached: the batch below is short
    started = time.monotonic()
    subprocess.run(cmd + ["-o", str(tmp_path / "timed")], capture_output=True, text=True, env=env, timeout=300)
    span = time.monotonic() - started
    for k in range(8):
        out = tmp_path / f"out{k}"
        proc = subprocess.Popen(cmd + ["-o", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env, preexec_fn=_default_sigint)
        time.sleep(span * (0.35 + 0.6 * k / 7))
        if proc.poll() is not None:  # finished before the signal: nothing to interrupt
            assert proc.returncode == 0, proc.communicate()
            continue
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
        if proc.returncode == 0:  # the signal came after the batch had finished: a late Ctrl-C is ignored
            run = json.loads((out / "run.json").read_text())
            assert run["interrupted"] is False and run["n_failed"] == 0, (k, run)
            continue
        # Was -2 now and then (death by SIGINT after the line was printed): CPython's
        # "unhandled KeyboardInterrupt" flag, set by an interrupt inside exec()'d code
        # while importing (tests/test_cli_interrupts.py); d3stereo now clears it.
        assert proc.returncode == 130, (k, proc.returncode, stderr)
        assert "Traceback" not in stderr, (k, stderr)
        assert stderr.strip().splitlines()[-1].endswith("rerun the same command to resume"), (k, stderr)
        assert not (out / LOCK_FILE).exists()
        if (out / "run.json").exists():
            run = json.loads((out / "run.json").read_text())
            assert run["interrupted"] is True and run["n_failed"] == 0, (k, run)
        again = subprocess.run(cmd + ["-o", str(out)], capture_output=True, text=True, env=env, timeout=300)
        assert again.returncode == 0, (k, again.stderr)


def test_ctrl_c_while_the_lock_is_taken_leaves_no_lock(tmp_path, pairs_root, monkeypatch):
    """Seen once in 10 repetitions of the eight-moment test: a Ctrl-C in the middle of
    acquire_lock left OUT/.d3stereo.lock behind.  The lock is now taken whole, the
    interrupt raised once it is held, and the lock released."""
    # Ctrl-C lands before acquire_lock has returned
    monkeypatch.setattr(d3cli.batch.runner, "acquire_lock",
                        _interrupting(d3cli.batch.runner.acquire_lock, lambda args, kwargs: True))
    term_before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "out"
    result = _run_with_ctrl_c_handler(["run", str(pairs_root), "-o", str(out), "--method", "sgbm"])
    assert result.exit_code == 130, result.output
    assert result.output.strip().splitlines()[-1] == "Interrupted; rerun the same command to resume"
    assert not (out / LOCK_FILE).exists()
    assert signal.getsignal(signal.SIGTERM) == term_before  # the batch's SIGTERM handler is gone again


def test_ctrl_c_between_a_pairs_outputs_and_its_result_json_leaves_no_half_pair(tmp_path, pairs_root, monkeypatch):
    """A Ctrl-C after a pair's maps and panel are written, while its warnings are logged and
    before result.json: the pair folder goes (it held outputs without result.json before)."""
    real = d3cli.batch.runner.compute_pair
    real_log = d3cli.batch.runner.log

    def with_a_warning(method, cfg, left, right, *, max_disparity, **kwargs):
        result = real(method, cfg, left, right, max_disparity=max_disparity, **kwargs)
        result.warnings.append("a warning of this test")
        return result

    class InterruptedLog:
        def __getattr__(self, name):
            return getattr(real_log, name)

        def warning(self, message, *args):
            if "a warning of this test" in args:
                raise KeyboardInterrupt
            real_log.warning(message, *args)

    monkeypatch.setattr(d3cli.batch.runner, "compute_pair", with_a_warning)
    monkeypatch.setattr(d3cli.batch.runner, "log", InterruptedLog())
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(out), "--method", "sgbm"])
    assert result.exit_code == 130, result.output
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["pairs"] == []
    assert [p.name for p in out.iterdir() if p.is_dir()] == []


def test_ctrl_c_right_after_run_json_records_the_batch_complete_is_ignored(tmp_path, pairs_root, monkeypatch):
    """CI: a Ctrl-C between run.json's complete record and the batch's return gave exit 130
    and "rerun the same command to resume" beside ``interrupted: false``.  Now the batch
    returns complete and the command exits 0."""
    monkeypatch.setattr(d3cli.batch.runner, "write_run_json", _interrupting(
        d3cli.batch.runner.write_run_json, lambda args, kwargs: kwargs.get("interrupted") is False))
    out = tmp_path / "out"
    result = _run_with_ctrl_c_handler(["run", str(pairs_root), "-o", str(out), "--method", "sgbm"])
    assert result.exit_code == 0, result.output
    assert "rerun" not in result.output
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is False and run["n_failed"] == 0
    assert not (out / LOCK_FILE).exists()


def test_ctrl_c_while_the_report_is_written_is_recorded_and_a_rerun_finishes(tmp_path, pairs_root, monkeypatch):
    """A Ctrl-C after the last pair, before run.json's complete record (report.html being
    written): exit 130, run.json says interrupted with every pair done, and a rerun writes
    the rest without computing a pair again."""
    monkeypatch.setattr(d3cli.batch.runner, "write_report_html", _interrupting(
        d3cli.batch.runner.write_report_html, lambda args, kwargs: True))
    out = tmp_path / "out"
    args = ["run", str(pairs_root), "-o", str(out), "--method", "sgbm"]
    result = _run_with_ctrl_c_handler(args)
    assert result.exit_code == 130, result.output
    assert result.output.strip().splitlines()[-1].endswith("rerun the same command to resume")
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["n_failed"] == 0
    assert {p["status"] for p in run["pairs"]} == {"ok"}
    monkeypatch.undo()
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is False and {p["status"] for p in run["pairs"]} == {"skipped"}


def test_signals_deferred_delivers_a_held_ctrl_c_unless_the_block_set_its_own_handler():
    """A Ctrl-C inside the block comes out at its end; when the block itself set SIGINT's
    handler (the run command ignores Ctrl-C once run.json records the batch), that handler
    stays and the held Ctrl-C is dropped (the old end put the earlier handler back over it)."""
    from d3cli.batch.signals import signals_deferred

    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        try:
            with signals_deferred():
                signal.raise_signal(signal.SIGINT)
            raise AssertionError("the held Ctrl-C was not delivered")
        except KeyboardInterrupt:
            pass
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        with signals_deferred():
            signal.raise_signal(signal.SIGINT)
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
