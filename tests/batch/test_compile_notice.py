"""A first run on a cold numba cache says what it is doing before the kernels compile,
and reports progress while they do (unless -q)."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from d3cli.batch import warmup
from d3cli.config import Config
from d3cli.kernels import cache_location

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def empty_cache(tmp_path, monkeypatch) -> Path:
    folder = tmp_path / "numba-cache"
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(folder))
    monkeypatch.setattr(cache_location, "announced", False)
    return folder


def test_cache_folders_are_where_numba_puts_them(tmp_path):
    from numba.core.caching import UserProvidedCacheLocator

    module = cache_location.HERE / "cost" / "cpu.py"
    assert cache_location.module_cache_folder(module, str(tmp_path)) == (
        tmp_path / UserProvidedCacheLocator.get_suitable_cache_subpath(str(module)))
    assert cache_location.module_cache_folder(module, "") == cache_location.HERE / "cost" / "__pycache__"


def test_an_empty_cache_is_cold_and_an_index_newer_than_its_source_warms_it(empty_cache):
    assert cache_location.is_cold() is True
    module = cache_location.HERE / "pixel.py"  # its cache folder is the one cache_folder() names
    index = cache_location.cache_folder() / "pixel.build.locals.box_sum-62.py{}{}.nbi".format(*sys.version_info[:2])
    index.parent.mkdir(parents=True)
    index.write_bytes(b"")
    os.utime(index, (module.stat().st_mtime - 10,) * 2)  # older than the source: numba drops it
    assert cache_location.is_cold() is True
    os.utime(index, (module.stat().st_mtime + 10,) * 2)
    assert cache_location.is_cold() is False
    other_python = index.with_name("pixel.build.locals.box_sum-62.py29.nbi")  # another Python's index does not count
    index.rename(other_python)
    assert cache_location.is_cold() is True


def test_the_notice_names_the_estimate_and_the_folder(empty_cache):
    assert cache_location.compile_notice("d3stereo") == (
        f"compiling the kernels for this machine, once (about 120 s); cached in {empty_cache}")
    cache_location.record_compile("d3stereo", 61.34, 88)  # this machine's last cold compile
    assert cache_location.compile_estimate("d3stereo") == {"seconds": 61.3, "kernels": 88}
    assert cache_location.compile_estimate("other") == cache_location.COLD_ESTIMATE
    assert cache_location.compile_notice("d3stereo") == (
        f"compiling the kernels for this machine, once (about 61 s); cached in {empty_cache}")


def test_progress_counts_compiles_and_logs_once_per_period(caplog):
    clock = iter([0.0, 4.0, 11.0, 15.0, 23.0])  # seconds at creation, then at each compile's end
    progress = warmup.CompileProgress(expected=3, every=10.0, clock=lambda: next(clock))
    with caplog.at_level(logging.INFO, logger="d3cli.batch.warmup"):
        for _ in range(4):
            progress.on_start(None)
            progress.on_end(None)
    assert progress.compiled == 4
    assert [(r.levelname, r.getMessage()) for r in caplog.records] == [
        ("NOTE", "compiled 2 of about 3 kernel functions (11 s)"),
        ("NOTE", "compiled 4 kernel functions (23 s)")]  # past the estimate: the count only


def test_warm_jit_on_a_cold_cache_says_so_first(empty_cache, monkeypatch, caplog):
    seen = []
    monkeypatch.setattr(warmup.dispatch, "compute_pair", lambda *a, **k: seen.append(a[0]))
    with caplog.at_level(logging.INFO):  # the root's level: the notice comes from d3cli.kernels.cache_location
        warmup.warm_jit(Config(), "d3stereo")
    assert seen == ["d3stereo"]
    assert caplog.records[0].levelname == "NOTE"
    assert caplog.records[0].getMessage() == (
        f"compiling the kernels for this machine, once (about 120 s); cached in {empty_cache}")
    assert caplog.records[1].getMessage() == "compiled 0 kernel functions in 0 s"
    assert cache_location.compile_estimate("d3stereo") == {"seconds": 0.0, "kernels": 0}  # recorded for next time


def test_warm_jit_on_a_warm_cache_is_silent(monkeypatch, caplog):
    monkeypatch.setattr(cache_location, "announced", False)
    monkeypatch.setattr(cache_location, "is_cold", lambda *a, **k: False)
    monkeypatch.setattr(warmup.dispatch, "compute_pair", lambda *a, **k: None)
    with caplog.at_level(logging.WARNING):
        warmup.warm_jit(Config(), "d3stereo")
    assert caplog.records == []


def test_a_cold_first_run_prints_the_notice_first(tmp_path, make_pair_folder):
    """End to end: the command's first stderr line, before anything compiles (the process
    is killed once it is read, so nothing compiles for long)."""
    make_pair_folder(tmp_path / "pairs", "a", shift=4, seed=0)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(REPO)}
    started = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(tmp_path / "pairs"), "-o", str(tmp_path / "out")],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, env=env, text=True)
    try:
        first = proc.stderr.readline()
        seconds = time.monotonic() - started
    finally:
        proc.kill()  # our own child; its compile would take minutes
        proc.wait()
    assert first == (f"NOTE: compiling the kernels for this machine, once (about 120 s); cached in "
                     f"{tmp_path / 'cache'}\n")
    print(f"first line after {seconds:.1f} s")
    assert seconds < 60  # the imports only (about 2 s on a quiet machine)


@pytest.fixture
def fake_compute(monkeypatch):
    """Every pair (and the warm-up pair) 'computed' at once: no kernel compiles."""
    import numpy as np

    from d3cli import DisparityResult

    def compute(method, cfg, left, right, **kwargs):
        shape = left.shape[:2]
        return DisparityResult(np.full(shape, 4.0, np.float32), np.ones(shape, bool), timings={"total": 0.0})

    monkeypatch.setattr(warmup.dispatch, "compute_pair", compute)
    monkeypatch.setattr("d3cli.batch.runner.compute_pair", compute)


@pytest.mark.parametrize("args, first", [
    ([], "NOTE: compiling the kernels for this machine, once (about 120 s); cached in {cache}"),
    (["-q"], None),  # -q: only errors
    (["--method", "sgbm"], None),  # compiles none of the kernels
])
def test_cli_says_it_compiles_unless_quiet(empty_cache, fake_compute, pairs_root, tmp_path, args, first):
    from click.testing import CliRunner

    from d3cli.cli import main

    result = CliRunner().invoke(main, ["run", str(pairs_root), "-o", str(tmp_path / "out"), *args])
    assert result.exit_code == 0, result.output
    notes = [line for line in result.output.splitlines() if line.startswith("NOTE: ")]
    if first is None:
        assert notes == []
    else:
        assert result.output.splitlines()[0] == first.format(cache=empty_cache)
        assert notes == [first.format(cache=empty_cache), "NOTE: compiled 0 kernel functions in 0 s"]  # one notice, not two
