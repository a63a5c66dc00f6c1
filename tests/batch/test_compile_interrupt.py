"""Ctrl-C during the first (cold) compile of the kernels is answered at once, and what was
compiled stays in the cache for the next run, which says it compiles the rest.

Every test here uses a numba cache folder of its own (``NUMBA_CACHE_DIR``): the package's
shared cache is never touched.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numba
import pytest

from d3cli.batch import warmup
from d3cli.config import Config
from d3cli.kernels import cache_location

REPO = Path(__file__).resolve().parents[2]
#: Seconds a signal may take to end the command, at any moment of the compile included.
ANSWER_S = 2.0
#: What a first run expects to compile where no compile was recorded (a fresh cache folder).
ESTIMATE = cache_location.COLD_ESTIMATE


@pytest.fixture
def empty_cache(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "numba-cache"
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(folder))
    monkeypatch.setattr(cache_location, "announced", False)
    return folder


# ----------------------------------------------------------------------------- the record
def test_an_interrupted_compile_is_recorded_and_the_next_notice_says_what_is_left(empty_cache, monkeypatch):
    cache_location.record_interrupted("d3stereo", 10.0, 46)  # 46 of the estimate's 251 functions in 10 s
    monkeypatch.setattr(cache_location, "is_cold", lambda *a, **k: False)  # their cache entries are there
    assert cache_location.resume_point("d3stereo") == {"seconds": 10.0, "kernels": 46}
    assert cache_location.compile_estimate("d3stereo") == {"seconds": 120.0, "kernels": 251}  # no slower than estimated
    assert cache_location.compile_notice("d3stereo", cache_location.resume_point("d3stereo")) == (
        "compiling the rest of the kernels for this machine, once (about 110 s; 46 of about 251 were "
        f"compiled by an interrupted run); cached in {empty_cache}")
    assert cache_location.resume_point("pt-sgm") is None  # per method

    cache_location.record_interrupted("d3stereo", 150.0, 60)  # a slow machine: the whole estimate grows
    assert cache_location.compile_estimate("d3stereo") == {"seconds": 241.3, "kernels": 251}
    cache_location.record_compile("d3stereo", 230.0, 251)  # the rest compiled: nothing is left
    assert cache_location.resume_point("d3stereo") is None


def test_a_cold_cache_again_forgets_the_interrupted_compile(empty_cache):
    cache_location.record_interrupted("d3stereo", 10.0, 46)
    assert cache_location.is_cold()  # its entries are gone (emptied, or every module edited)
    assert cache_location.resume_point("d3stereo") is None
    assert cache_location.compile_notice("d3stereo") == (
        f"compiling the kernels for this machine, once (about 120 s); cached in {empty_cache}")


def test_the_next_run_announces_the_rest_and_records_the_whole(empty_cache, monkeypatch, caplog):
    cache_location.record_interrupted("d3stereo", 10.0, 46)
    monkeypatch.setattr(cache_location, "is_cold", lambda *a, **k: False)
    monkeypatch.setattr(warmup.dispatch, "compute_pair", lambda *a, **k: None)
    with caplog.at_level(logging.INFO):
        warmup.warm_jit(Config(), "d3stereo")
    assert caplog.records[0].getMessage().startswith("compiling the rest of the kernels for this machine")
    # Nothing compiled (compute_pair is a stand-in): nothing was left, the estimate stands.
    assert cache_location.resume_point("d3stereo") is None
    assert cache_location.compile_estimate("d3stereo") == {"seconds": 120.0, "kernels": 251}


def test_the_rest_compiled_records_both_runs_seconds(empty_cache, monkeypatch, caplog):
    from numba.core import event as numba_event

    def compute(*args, **kwargs):  # compiles 230 functions (numba's own helpers again among them)
        for _ in range(230):
            with numba_event.trigger_event("numba:compile", data={}):
                pass

    cache_location.record_interrupted("d3stereo", 10.0, 46)
    monkeypatch.setattr(cache_location, "is_cold", lambda *a, **k: False)
    monkeypatch.setattr(warmup.dispatch, "compute_pair", compute)
    with caplog.at_level(logging.INFO):
        seconds = warmup.warm_jit(Config(), "d3stereo")
    assert [r.getMessage() for r in caplog.records if r.levelname == "NOTE"][1:] == [
        f"compiled 230 kernel functions in {seconds:.0f} s"]
    assert cache_location.resume_point("d3stereo") is None
    assert cache_location.compile_estimate("d3stereo") == {"seconds": round(10.0 + seconds, 1), "kernels": 251}


# ----------------------------------------------------------------------------- the wait
def test_a_signal_ends_the_wait_at_once_and_is_handed_back():
    """The compile goes on in its thread; the caller gets the signal and its handler."""
    release = threading.Event()
    seen = []

    def handler(signum, frame):
        seen.append(signum)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        timer = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
        timer.start()
        started = time.monotonic()
        finished, signals = warmup.call_interruptibly(release.wait, 60)
        waited = time.monotonic() - started
        assert finished is False and [s for s, _ in signals] == [signal.SIGINT]
        assert waited < 0.3 + ANSWER_S
        assert seen == []  # not delivered yet: the caller records first, then calls the handler
        assert warmup.compiling_in_background()
        assert signal.getsignal(signal.SIGINT) is handler  # put back
        signals[0][1](signal.SIGINT, None)
        assert seen == [signal.SIGINT]
    finally:
        release.set()
        signal.signal(signal.SIGINT, previous)
    deadline = time.monotonic() + 10
    while warmup.compiling_in_background() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not warmup.compiling_in_background()  # the thread ends with its function


def test_without_a_signal_the_result_and_errors_come_through():
    assert warmup.call_interruptibly(lambda: None) == (True, [])
    with pytest.raises(ZeroDivisionError):
        warmup.call_interruptibly(lambda: 1 / 0)


# ----------------------------------------------------------------------------- end to end
class _Lines:
    """The stderr lines of a child, read in a thread, with the second each arrived."""

    def __init__(self, proc: subprocess.Popen):
        self.queue: queue.Queue = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._read, args=(proc.stderr,), daemon=True).start()

    def _read(self, stream):
        for line in stream:
            self.queue.put(line.rstrip("\n"))
        self.queue.put(None)

    def until(self, predicate, timeout: float) -> str | None:
        """The first line (from now) for which ``predicate`` holds; None at the end or timeout."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.queue.get(timeout=max(deadline - time.monotonic(), 0.01))
            except queue.Empty:
                return None
            if line is None:
                return None
            self.seen.append(line)
            if predicate(line):
                return line

    def rest(self, timeout: float = 10.0) -> list[str]:
        self.until(lambda line: False, timeout)
        return self.seen


def _start(pairs: Path, out: Path, cache: Path, *options: str) -> tuple[subprocess.Popen, _Lines]:
    """``d3stereo run PAIRS -o OUT [options]`` with a numba cache of its own, in a session
    of its own (its worker processes can be found and ended by process group)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(REPO)}
    env.pop("NUMBA_DISABLE_JIT", None)
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(pairs), "-o", str(out), *options],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            env=env, text=True, start_new_session=True)
    return proc, _Lines(proc)


def _entries(cache: Path) -> dict[str, int]:
    """The compiled functions in ``cache``: numba's data files (one per function and
    signature; a function's index file also changes when it compiles another signature),
    with their modification times."""
    return {p.name: p.stat().st_mtime_ns for p in cache.rglob("*.nbc")}


@pytest.mark.slow
def test_ctrl_c_20_s_into_a_cold_compile_returns_within_2_s_and_the_next_run_goes_on(tmp_path, make_pair_folder):
    pairs = tmp_path / "pairs"
    make_pair_folder(pairs, "a", shift=4, seed=0)
    cache = tmp_path / "cache"
    proc, lines = _start(pairs, tmp_path / "out", cache)
    try:
        notice = lines.until(lambda line: line.startswith("NOTE: compiling"), 120)
        assert notice == (f"NOTE: compiling the kernels for this machine, once (about {ESTIMATE['seconds']:.0f} s); "
                          f"cached in {cache}")
        started = time.monotonic()
        # 20 s into the compile, and past its first progress line (a loaded machine is slower).
        progress = lines.until(lambda line: line.startswith("NOTE: compiled "), 180)
        assert progress is not None and f" of about {ESTIMATE['kernels']} kernel functions (" in progress, lines.seen
        time.sleep(max(20 - (time.monotonic() - started), 0))
        proc.send_signal(signal.SIGINT)
        sent = time.monotonic()
        status = proc.wait(timeout=60)
        answered = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    stderr = lines.rest()
    print(f"answered in {answered:.2f} s; stderr: {stderr}")
    assert answered < ANSWER_S, stderr
    assert status == 130, stderr
    assert not any("Traceback" in line for line in stderr), stderr
    assert stderr[-1] == "Interrupted: 0 of 1 pair done; rerun the same command to resume"
    kept = [line for line in stderr if "before the interrupt" in line]
    assert len(kept) == 1 and kept[0].endswith("; they are kept in the cache, the next run compiles the rest")
    compiled = int(kept[0].split()[2])  # "NOTE: compiled N kernel functions in T s before ..."
    assert compiled > 0
    record = json.loads((cache_location.cache_folder(cache_dir=str(cache)) / cache_location.COMPILE_RECORD).read_text())
    assert record["d3stereo"]["done"]["kernels"] == compiled
    first_run = _entries(cache)
    assert len(first_run) > 0  # what was compiled is in the cache

    # The next run says it compiles the rest, and loads what the first one compiled.
    proc, lines = _start(pairs, tmp_path / "out", cache)
    try:
        notice = lines.until(lambda line: line.startswith("NOTE: "), 120)
        assert notice is not None and notice.startswith(
            "NOTE: compiling the rest of the kernels for this machine, once (about ")
        assert notice.endswith(f" s; {compiled} of about {ESTIMATE['kernels']} were compiled by an interrupted run); "
                               f"cached in {cache}")
        # Wait until it compiles a function the first run did not: it has passed theirs.
        deadline = time.monotonic() + 180
        while not set(_entries(cache)) - set(first_run) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert set(_entries(cache)) - set(first_run), lines.rest(0.1)
    finally:
        proc.kill()  # our own child; the rest of its compile would take minutes
        proc.wait()
    now = _entries(cache)
    assert {name: now[name] for name in first_run} == first_run  # loaded, not compiled again


@pytest.mark.slow
def test_ctrl_c_during_a_cold_compile_in_the_worker_pool_returns_within_2_s(tmp_path, make_pair_folder):
    """With --workers the first worker compiles in its initializer, ignoring SIGINT; the
    parent answers the signal at once and ends its workers (none is left running)."""
    pairs = tmp_path / "pairs"
    for i, name in enumerate("abc"):
        make_pair_folder(pairs, name, shift=4, seed=i)
    proc, lines = _start(pairs, tmp_path / "out", tmp_path / "cache", "--workers", "2")
    try:
        assert lines.until(lambda line: line.startswith("NOTE: compiling"), 120) is not None, lines.seen
        time.sleep(8)  # the worker is compiling now
        assert proc.poll() is None, lines.rest(0.1)
        proc.send_signal(signal.SIGINT)
        sent = time.monotonic()
        status = proc.wait(timeout=60)
        answered = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    stderr = lines.rest()
    assert answered < ANSWER_S, stderr
    assert status == 130, stderr
    assert not any("Traceback" in line for line in stderr), stderr
    assert stderr[-1].startswith("Interrupted: 0 of 3 pairs done"), stderr
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        try:
            os.killpg(proc.pid, 0)  # a worker of the session still alive
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail("a worker process outlived the interrupted run")
