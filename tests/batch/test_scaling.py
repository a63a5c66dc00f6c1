"""--workers, --scheduler (Dask) and --shard give the same per-pair files as a serial run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from d3cli.batch import parse_shard, parse_workers, run_batch, select_shard
from d3cli.cli import main
from d3cli.config import load_config
from d3cli.data import layouts as datasets
from d3cli.errors import ConfigError
from d3cli.kernels import compile_cache

ROOT = Path(__file__).resolve().parents[2]
PAIRS = "abcd"
BIN = Path(sys.executable).parent


def invoke(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


@pytest.fixture
def pair_root(tmp_path, make_pair_set):
    return make_pair_set(tmp_path / "pairs", PAIRS)


@pytest.fixture
def serial_sgbm(tmp_path, pair_root):
    out = tmp_path / "serial"
    assert invoke("run", pair_root, "-o", out, "--method", "sgbm", "-q").exit_code == 0
    return out


def assert_same_maps(first, second, names=PAIRS):
    for name in names:
        assert (first / name / "disp.pfm").read_bytes() == (second / name / "disp.pfm").read_bytes(), name
        assert (first / name / "valid.png").read_bytes() == (second / name / "valid.png").read_bytes(), name


def env_with_package():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    return env


# ----------------------------------------------------------------------------- options
def test_parse_workers_and_shard():
    assert parse_workers("3") == 3
    assert parse_workers("auto") >= 1
    assert parse_shard("2/5") == (2, 5)
    for bad in ("0", "-1", "many"):
        with pytest.raises(ConfigError, match="--workers"):
            parse_workers(bad)
    for bad in ("0/3", "4/3", "1", "a/b"):
        with pytest.raises(ConfigError, match="--shard"):
            parse_shard(bad)


def test_shards_partition_the_pairs_whatever_the_order(pair_root):
    pairs = datasets.discover([pair_root])
    shards = [[p.name for p in select_shard(pairs, i, 3)] for i in (1, 2, 3)]
    assert shards == [["a", "d"], ["b"], ["c"]]
    assert [[p.name for p in select_shard(pairs[::-1], i, 3)] for i in (1, 2, 3)] == shards


def test_bad_workers_value_is_one_error_line(tmp_path, pair_root):
    result = invoke("run", pair_root, "-o", tmp_path / "o", "--workers", "zero")
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1].startswith("Error: --workers zero")


# ----------------------------------------------------------------------------- local pool
@pytest.mark.parametrize("method", ["sgbm", "d3stereo"])
def test_workers_2_is_byte_identical_to_serial(tmp_path, pair_root, method):
    serial, pool = tmp_path / "s", tmp_path / "p"
    assert invoke("run", pair_root, "-o", serial, "--method", method, "-q").exit_code == 0
    assert invoke("run", pair_root, "-o", pool, "--method", method, "-q", "--workers", "2").exit_code == 0
    assert_same_maps(serial, pool)
    run = json.loads((pool / "run.json").read_text())
    assert run["execution"]["mode"] == "local-pool" and run["execution"]["workers"] == 2
    assert [p["pair"] for p in run["pairs"]] == list(PAIRS)  # input order, whatever finished first
    assert all(p["status"] == "ok" for p in run["pairs"])
    assert run["compile_s"] >= 0.0


def test_warm_up_keeps_compile_time_out_of_the_first_pair(tmp_path, pair_root):
    out = tmp_path / "o"
    assert invoke("run", pair_root, "-o", out, "--method", "d3stereo", "-q").exit_code == 0
    run = json.loads((out / "run.json").read_text())
    walls = [p["wall_s"] for p in run["pairs"]]
    assert run["compile_s"] > 0.0
    # Same-size pairs: the first no longer carries the JIT (a compile or cache load is > 0.3 s).
    assert walls[0] < 3 * max(walls[1:]) + 0.3


def test_shards_fill_one_out_and_eval_covers_all(tmp_path, pair_root, serial_sgbm):
    out = tmp_path / "sharded"
    for i in (1, 2):
        assert invoke("run", pair_root, "-o", out, "--method", "sgbm", "-q", "--shard", f"{i}/2").exit_code == 0
    assert_same_maps(serial_sgbm, out)
    names = {i: [p["pair"] for p in json.loads((out / f"run-{i}-of-2.json").read_text())["pairs"]] for i in (1, 2)}
    assert names == {1: ["a", "c"], 2: ["b", "d"]}
    assert not (out / "run.json").exists()
    report = out.parent / (out.name + "-report")  # eval writes only under its own -o
    result = invoke("eval", out, "--gt", pair_root, "-o", report, "-q")
    assert result.exit_code == 0, result.output
    summary = json.loads((report / "summary.json").read_text())
    assert summary["overall"]["pairs"] == summary["overall"]["ok"] == summary["overall"]["with_gt"] == len(PAIRS)
    assert summary["overall"]["means"]["pep_1"] == 0.0  # integer shifts: every pair exact to 1 px


# ----------------------------------------------------------------------------- Dask
distributed = pytest.importorskip("distributed")


def test_local_cluster_is_byte_identical_and_records_a_bad_pair_once(tmp_path, pair_root, serial_sgbm,
                                                                      local_cluster):
    cfg = load_config(None)
    pairs = datasets.discover([pair_root])
    out = tmp_path / "dask"
    result = run_batch(pairs, out, cfg=cfg, method="sgbm", progress=False, scheduler=local_cluster.scheduler_address)
    assert result.n_failed == 0
    assert_same_maps(serial_sgbm, out)
    run = json.loads((out / "run.json").read_text())
    assert run["execution"] == {"mode": "dask", "scheduler": local_cluster.scheduler_address, "workers": 2,
                                "threads": 2, "gpus": 0}

    # Deterministic failure: recorded once as failed, the other pairs unaffected, no retry.
    (pair_root / "b" / "right.png").write_bytes(b"not a png")
    again = run_batch(datasets.discover([pair_root]), tmp_path / "dask-bad", cfg=cfg, method="sgbm", progress=False,
                      scheduler=local_cluster.scheduler_address)
    assert [r["pair"] for r in again.rows if r["status"] == "failed"] == ["b"]
    assert "right.png" in again.failures[0][1]
    assert_same_maps(serial_sgbm, tmp_path / "dask-bad", "acd")


def test_dask_d3stereo_is_byte_identical(tmp_path, pair_root, local_cluster):
    serial, out = tmp_path / "s", tmp_path / "d"
    assert invoke("run", pair_root, "-o", serial, "--method", "d3stereo", "-q").exit_code == 0
    env_before = os.environ.get("DASK_SCHEDULER_ADDRESS")
    os.environ["DASK_SCHEDULER_ADDRESS"] = local_cluster.scheduler_address
    try:
        assert invoke("run", pair_root, "-o", out, "--method", "d3stereo", "-q").exit_code == 0
    finally:
        if env_before is None:
            del os.environ["DASK_SCHEDULER_ADDRESS"]
        else:
            os.environ["DASK_SCHEDULER_ADDRESS"] = env_before
    assert_same_maps(serial, out)
    assert json.loads((out / "run.json").read_text())["execution"]["mode"] == "dask"


def test_scheduler_without_workers_is_a_clear_error(tmp_path):
    from d3cli.batch.executors import DaskExecutor

    cluster = distributed.LocalCluster(n_workers=0, processes=True, host="127.0.0.1", dashboard_address=None)
    try:
        with pytest.raises(ConfigError, match="no worker joined within 1 s; start workers with `dask worker"):
            with DaskExecutor(cluster.scheduler_address, tmp_path, worker_timeout=1):
                pass
    finally:
        cluster.close()


def test_unreachable_scheduler_is_one_error_line(tmp_path, pair_root):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    result = invoke("run", pair_root, "-o", tmp_path / "o", "--method", "sgbm", "-q",
                    "--scheduler", f"tcp://127.0.0.1:{port}")
    assert result.exit_code == 1
    last = result.output.strip().splitlines()[-1]
    assert last.startswith(f"Error: --scheduler tcp://127.0.0.1:{port}: scheduler unreachable")
    assert time.monotonic() - t0 < 30
    assert not list((tmp_path / "o").glob("*/disp.pfm"))


BIG = "abcdefgh"


def eight_pairs(root: Path, shape, *, first_seed: int) -> Path:
    """Pair folders ``BIG`` under ``root``: textured pairs of ``shape``, shifts 3..10."""
    from tests.helpers import textured_pair, write_png

    for i, name in enumerate(BIG):
        folder = root / name
        folder.mkdir()
        left, right, _ = textured_pair(3 + i, shape, seed=first_seed + i)
        write_png(folder / "left.png", left)
        write_png(folder / "right.png", right)
    return root


@pytest.fixture(scope="module")
def big_pairs(tmp_path_factory):
    """Eight 720x1280 pairs: about 0.1 s of SGBM each, so a batch is still running after its first pair."""
    return eight_pairs(tmp_path_factory.mktemp("big"), (720, 1280), first_seed=0)


@pytest.fixture(scope="module")
def big_serial(big_pairs, tmp_path_factory):
    """The serial SGBM outputs of :func:`big_pairs`, the reference of every parallel run."""
    out = tmp_path_factory.mktemp("big-serial")
    assert invoke("run", big_pairs, "-o", out, "--method", "sgbm", "-q").exit_code == 0
    return out


@pytest.fixture(scope="module")
def d3_pairs(tmp_path_factory):
    """Eight 360x640 pairs for the default method (d3stereo): a few tenths of a second each."""
    return eight_pairs(tmp_path_factory.mktemp("d3-eight"), (360, 640), first_seed=10)


@pytest.fixture(scope="module")
def d3_serial(d3_pairs, tmp_path_factory):
    out = tmp_path_factory.mktemp("d3-eight-serial")
    assert invoke("run", d3_pairs, "-o", out, "-q").exit_code == 0
    return out


@pytest.mark.parametrize("method", ["d3stereo", "sgbm"])
def test_dask_subprocess_cluster_survives_a_worker_killed_mid_batch(tmp_path, request, method):
    """The Dask acceptance run: `dask scheduler` + two `dask worker --no-nanny` on 127.0.0.1,
    `python -m d3cli run --scheduler` on 8 pairs; one worker is SIGKILLed after the first
    pair finishes: exit 0, every map as serial.  The default method (d3stereo) on 360x640
    pairs, SGBM on 720x1280 ones."""
    pairs_fixture, serial_fixture = ("d3_pairs", "d3_serial") if method == "d3stereo" else ("big_pairs", "big_serial")
    big_pairs, serial = request.getfixturevalue(pairs_fixture), request.getfixturevalue(serial_fixture)
    env = env_with_package()
    sched_file = tmp_path / "scheduler.json"
    procs = []
    try:
        procs.append(subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                       "--no-dashboard", "--scheduler-file", str(sched_file)],
                                      env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        deadline = time.monotonic() + 30
        while not sched_file.exists():
            assert time.monotonic() < deadline, "scheduler did not start"
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        workers = [subprocess.Popen([str(BIN / "dask"), "worker", address, "--no-nanny", "--nthreads", "1",
                                     "--host", "127.0.0.1", "--no-dashboard"],
                                    env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                   for _ in range(2)]
        procs += workers
        out = tmp_path / "cluster-out"
        client = subprocess.Popen([sys.executable, "-m", "d3cli", "run", str(big_pairs), "-o", str(out),
                                   "--method", method, "-q", "--scheduler", address],
                                  env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        procs.append(client)
        deadline = time.monotonic() + 90
        while not list(out.glob("*/result.json")):
            assert client.poll() is None, client.communicate()
            assert time.monotonic() < deadline, "no pair finished"
            time.sleep(0.005)
        workers[0].send_signal(signal.SIGKILL)
        done_at_kill = len(list(out.glob("*/result.json")))
        _, stderr = client.communicate(timeout=120)
        assert client.returncode == 0, stderr
        assert done_at_kill < len(BIG)  # the kill happened while pairs were still to do
        assert workers[0].wait(timeout=10) == -signal.SIGKILL
        assert_same_maps(serial, out, BIG)
        run = json.loads((out / "run.json").read_text())
        # A pair the killed worker had written but not reported is found complete by its rerun: "skipped".
        assert [p["pair"] for p in run["pairs"]] == list(BIG)
        assert {p["status"] for p in run["pairs"]} <= {"ok", "skipped"} and run["n_failed"] == 0
    finally:
        for proc in reversed(procs):
            if proc.poll() is None:
                proc.kill()
            proc.wait(timeout=10)


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_with_workers_exits_130_or_143_and_rerun_resumes(tmp_path, big_pairs, big_serial, signum):
    serial, out = big_serial, tmp_path / "pool"
    cmd = [sys.executable, "-m", "d3cli", "run", str(big_pairs), "-o", str(out), "--method", "sgbm", "-q",
           "--workers", "2"]
    # SIGINT back to its default in the child: a shell starts background jobs with it
    # ignored, and an ignored SIGINT would never reach the batch
    proc = subprocess.Popen(cmd, env=env_with_package(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 90
        while not list(out.glob("*/result.json")):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no pair finished"
            time.sleep(0.005)
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    assert proc.returncode == (143 if signum == signal.SIGTERM else 130), stderr
    assert "rerun the same command to resume" in stderr.strip().splitlines()[-1]
    run = json.loads((out / "run.json").read_text())
    assert run["interrupted"] is True and run["n_pairs"] < len(BIG)
    again = subprocess.run(cmd, env=env_with_package(), capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr
    assert_same_maps(serial, out, BIG)
    statuses = [p["status"] for p in json.loads((out / "run.json").read_text())["pairs"]]
    assert "skipped" in statuses and "ok" in statuses  # resumed: kept the finished pairs, computed the rest


# ----------------------------------------------------------------------------- numba cache
READ_ONLY_PACKAGE = """
import os, sys
real_access = os.access
kernels = os.path.join(sys.argv[1], "d3cli", "kernels")
# A read-only install, as the OS would answer it (root ignores permission bits, so chmod cannot show it).
os.access = lambda path, mode, **kw: (False if str(path).startswith(kernels) and mode & os.W_OK
                                      else real_access(path, mode, **kw))
import numpy as np
import numba
from d3cli.kernels.cost.cpu import integral_image
print(numba.config.CACHE_DIR, os.environ.get("NUMBA_CACHE_DIR"))
print(integral_image(np.ones((2, 3), np.float32), 1)[-1, -1])
"""


def test_read_only_package_caches_kernels_in_the_user_cache(tmp_path):
    env = env_with_package()
    env.pop("NUMBA_CACHE_DIR", None)
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    done = subprocess.run([sys.executable, "-c", READ_ONLY_PACKAGE, str(ROOT)], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    where, again, total = done.stdout.split()
    expected = tmp_path / "xdg" / "d3stereo" / "numba"
    assert where == again == str(expected)
    assert float(total) == 6.0  # sum of a 2x3 block of ones
    assert list(expected.rglob("cpu.integral_image-*.nbi")), list(expected.rglob("*"))
    assert list(expected.rglob(compile_cache.STAMP))  # the hashes of the kernels modules, beside their caches
