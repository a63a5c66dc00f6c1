"""Scaling out, part 2: the up-front checks of a Dask cluster (another d3stereo version on
a worker, OUT not writable from the workers), and how the local pool starts its workers
(forked where safe, spawned after numba's OpenMP threads have started) and orders pairs."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

import d3cli
from d3cli.batch.executors import AUTO_SERIAL_CORES, available_cores, largest_first, pair_cost, parse_workers
from d3cli.cli import main
from d3cli.data import layouts as datasets

ROOT = Path(__file__).resolve().parents[2]


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def env_with_package():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    env.pop("D3STEREO_POOL_START", None)
    return env


@pytest.fixture
def small_pairs(tmp_path, make_pair_folder):
    """Three pairs of three sizes: 40x64 (a), 64x128 (b), 48x96 (c)."""
    root = tmp_path / "pairs"
    for name, size, shift in (("a", (40, 64), 3), ("b", (64, 128), 5), ("c", (48, 96), 4)):
        make_pair_folder(root, name, shift=shift, size=size, seed=len(name + str(shift)))
    return root


def same_maps(first: Path, second: Path, names) -> None:
    for name in names:
        for file in ("disp.pfm", "valid.png"):
            assert (first / name / file).read_bytes() == (second / name / file).read_bytes(), (name, file)


# ----------------------------------------------------------------------------- local pool
def test_auto_workers_is_one_per_core(monkeypatch):
    for cores, expected in ((1, 1), (2, 2), (3, 3), (16, 16)):
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid, n=cores: set(range(n)))
        assert available_cores() == cores
        assert parse_workers("auto") == parse_workers("AUTO") == expected
    assert AUTO_SERIAL_CORES == 1


def test_largest_pairs_first(small_pairs):
    pairs = datasets.discover([small_pairs])
    # pixels x disparity range (width // 4 when the pair states none)
    assert [pair_cost(p) for p in pairs] == [64 * 40 * 16, 128 * 64 * 32, 96 * 48 * 24]
    assert [p.name for p in largest_first(pairs)] == ["b", "c", "a"]
    assert [p.name for p in largest_first(pairs, limit=2)] == ["a", "b", "c"]  # too many: input order
    broken = datasets.Pair(name="x", left=small_pairs / "missing.png", right=small_pairs / "missing.png")
    assert pair_cost(broken) == 0
    assert [p.name for p in largest_first([broken, *pairs])] == ["b", "c", "a", "x"]


def run_cli(pairs: Path, out: Path, *extra, env=None):
    done = subprocess.run([sys.executable, "-m", "d3cli", "run", str(pairs), "-o", str(out), "--method", "d3stereo",
                           "-q", *extra], env=env or env_with_package(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads((out / "run.json").read_text())


def test_forked_and_spawned_workers_match_serial(tmp_path, small_pairs):
    serial = tmp_path / "serial"
    run_cli(small_pairs, serial)
    forked = run_cli(small_pairs, tmp_path / "fork", "--workers", "2")
    assert forked["execution"] == {"mode": "local-pool", "workers": 2, "threads_per_worker": max(
        1, len(os.sched_getaffinity(0)) // 2), "start": "fork"}
    spawned = run_cli(small_pairs, tmp_path / "spawn", "--workers", "2",
                      env={**env_with_package(), "D3STEREO_POOL_START": "spawn"})
    assert spawned["execution"]["start"] == "spawn"
    for run, out in ((forked, tmp_path / "fork"), (spawned, tmp_path / "spawn")):
        same_maps(serial, out, "abc")
        assert [p["pair"] for p in run["pairs"]] == ["a", "b", "c"]
        assert {p["status"] for p in run["pairs"]} == {"ok"}
        assert run["compile_s"] > 0.0  # the first worker compiled or loaded the kernels


AFTER_OPENMP = """
import sys
from d3cli.batch import run_batch
from d3cli.batch.executors import pool_start_method
from d3cli.batch.warmup import warm_jit
from d3cli.config import load_config
from d3cli.data import layouts as datasets
cfg = load_config(None)
print(pool_start_method())
warm_jit(cfg, "d3stereo")  # runs the parallel kernels here: numba's OpenMP threads start
print(pool_start_method())
result = run_batch(datasets.discover([sys.argv[1]]), sys.argv[2], cfg=cfg, method="d3stereo", progress=False,
                   workers=2)
print(result.n_failed)
"""


def test_pool_spawns_once_this_process_has_run_parallel_kernels(tmp_path, small_pairs):
    """GNU OpenMP is not fork-safe (numba SIGTERMs such a forked child): the pool must spawn."""
    serial = tmp_path / "serial"
    run_cli(small_pairs, serial)
    done = subprocess.run([sys.executable, "-c", AFTER_OPENMP, str(small_pairs), str(tmp_path / "pool")],
                          env=env_with_package(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["fork", "spawn", "0"]
    assert json.loads((tmp_path / "pool" / "run.json").read_text())["execution"]["start"] == "spawn"
    same_maps(serial, tmp_path / "pool", "abc")


def test_bad_start_method_is_one_error_line(tmp_path, small_pairs, monkeypatch):
    monkeypatch.setenv("D3STEREO_POOL_START", "teleport")
    result = invoke("run", small_pairs, "-o", tmp_path / "o", "--method", "sgbm", "-q", "--workers", "2")
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1].startswith(
        "Error: $D3STEREO_POOL_START=teleport: use one of ")
    assert not list((tmp_path / "o").glob("*/disp.pfm"))


# ----------------------------------------------------------------------------- Dask checks
distributed = pytest.importorskip("distributed")


def on_workers(cluster, function) -> list[str]:
    """Run ``function`` in every worker process of ``cluster``; their addresses, sorted."""
    with distributed.Client(cluster, set_as_default=False) as client:
        client.run(function)
        return sorted(client.scheduler_info()["workers"])


def test_worker_with_another_version_is_one_error_line(tmp_path, small_pairs, local_cluster):
    cluster = local_cluster
    # As a worker with another install would answer: its d3cli says another version.
    workers = on_workers(cluster, lambda: setattr(importlib.import_module("d3cli"), "__version__", "0.0.1+other"))
    out = tmp_path / "o"
    address = cluster.scheduler_address
    result = invoke("run", small_pairs, "-o", out, "--method", "sgbm", "-q", "--scheduler", address)
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        f"Error: --scheduler {address}: worker {workers[0]} has d3stereo 0.0.1+other, this client "
        f"{d3cli.__version__}; install the same version on the workers and here")
    assert not list(out.glob("*/disp.pfm")) and not (out / "run.json").exists()


def read_only_under(folder: str):
    """A function making ``folder`` read-only for the process it runs in, as a read-only
    mount would: opening a file there for writing fails with EROFS (root ignores
    permission bits, so chmod cannot show it)."""

    def patch():
        import errno
        import os

        real_open = os.open

        def guarded(path, flags, *args, **kwargs):
            writing = flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT)
            if writing and os.path.abspath(os.fsdecode(path)).startswith(folder + os.sep):
                raise OSError(errno.EROFS, os.strerror(errno.EROFS), path)
            return real_open(path, flags, *args, **kwargs)

        os.open = guarded

    return patch


def test_workers_that_cannot_write_out_is_one_error_line(tmp_path, small_pairs, local_cluster):
    cluster = local_cluster
    out = (tmp_path / "o").resolve()
    workers = on_workers(cluster, read_only_under(str(out)))
    result = invoke("run", small_pairs, "-o", out, "--method", "sgbm", "-q", "--scheduler", cluster.scheduler_address)
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == (
        f"Error: {out}: worker {workers[0]} cannot write the output folder (Read-only file system); "
        "use -o on a filesystem shared by the client and every worker, writable by them")
    # The client could write (it made OUT and took its lock); no pair ran, no lock is left behind.
    assert out.is_dir() and not list(out.iterdir())
