"""Throughput of ``d3stereo run``: serial against ``--workers N``, ``--prefetch N`` (the
pipelined batch), a local Dask cluster and, on a GPU, ``--backend cuda``.

Runs the same batch with each way in turn, alternating (serial, workers, dask, serial,
workers, dask, ...) so that a change of the machine's load hits every way alike; each
run writes into a fresh output folder, and every map is compared byte for byte with the
first serial run.  Reports per run the wall time, the CPU seconds of the run's processes
(user + system, the client and its pool workers; not the Dask workers, which are not its
children) and the load average, then the medians and pairs per minute.

Example (the figures in README "Scaling out")::

    python -m d3cli synth /tmp/synth8 --n 8 --seed 0 --width 640 --height 360 -q
    python scripts/bench_scaling.py /tmp/synth8 --reps 3 --dask
    python scripts/bench_scaling.py DATA --reps 3 --dask

``--start spawn`` (or fork, forkserver) sets ``D3STEREO_POOL_START`` for the pool runs,
to compare how the workers start.

The pipelined batch (reading and writing in threads beside the pair computing) on the
CPU, and on a GPU machine CUDA serial / CUDA pipelined against the CPU pool::

    python scripts/bench_scaling.py /tmp/synth12 --reps 3 --workers 0 --prefetch 2
    python scripts/bench_scaling.py DATA --reps 1 --backend cpu --workers 16 --cuda

Every way runs with ``--backend`` (default: the configuration's) except the ``--cuda``
ways; serial is ``--prefetch 0`` (never pipelined, whatever the backend).
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(inputs, out: Path, method: str, extra: list[str], env: dict) -> tuple[float, float]:
    """(wall s, CPU s) of one ``d3stereo run`` into a fresh ``out``."""
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "d3cli", "run", *inputs, "-o", str(out), "--method", method, "-q", *extra]
    cpu0, t0 = child_cpu(), time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, child_cpu() - cpu0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr}")
    return wall, cpu


def same_maps(first: Path, second: Path) -> bool:
    names = [p.parent.name for p in first.glob("*/disp.pfm")]
    return bool(names) and all(
        filecmp.cmp(first / n / f, second / n / f, shallow=False) for n in names for f in ("disp.pfm", "valid.png"))


def start_dask(workers: int, env: dict, folder: Path):
    """A ``dask scheduler`` and ``workers`` x ``dask worker --nthreads 1`` on 127.0.0.1, each
    worker with cores // workers numba threads."""
    sched_file = folder / "scheduler.json"
    dask = str(Path(sys.executable).parent / "dask")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(sched_file)], env=env, cwd=folder,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    deadline = time.monotonic() + 60
    while not sched_file.exists():
        if time.monotonic() > deadline:
            raise SystemExit("dask scheduler did not start")
        time.sleep(0.1)
    address = json.loads(sched_file.read_text())["address"]
    threads = max(1, (os.cpu_count() or 1) // workers)
    worker_env = {**env, "NUMBA_NUM_THREADS": str(threads)}
    procs += [subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--nworkers", "1", "--host",
                                "127.0.0.1", "--no-dashboard", "--no-nanny"], env=worker_env, cwd=folder,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(workers)]
    return address, procs


def way_list(args, env: dict, pool_env: dict) -> list:
    """(name, extra ``d3stereo run`` arguments, environment) of every way to run, serial first."""
    backend = ["--backend", args.backend] if args.backend else []
    ways = [("serial", [*backend, "--prefetch", "0"], env)]
    if args.workers > 1:
        ways.append((f"--workers {args.workers}", [*backend, "--workers", str(args.workers)], pool_env))
    if args.prefetch > 0:
        ways.append((f"--prefetch {args.prefetch}", [*backend, "--prefetch", str(args.prefetch)], env))
    if args.cuda:
        ways.append(("cuda --prefetch 0", ["--backend", "cuda", "--prefetch", "0"], env))
        ways.append(("cuda --prefetch auto", ["--backend", "cuda", "--prefetch", "auto"], env))
    return ways


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("inputs", nargs="+", help="what `d3stereo run` takes (a folder of pairs, ...)")
    parser.add_argument("--method", default="d3stereo")
    parser.add_argument("--workers", type=int, default=2, help="pool processes (0: no pool run)")
    parser.add_argument("--prefetch", type=int, default=0,
                        help="also the pipelined batch reading this many pairs ahead (0: not run)")
    parser.add_argument("--backend", choices=["auto", "cpu", "cuda"], help="--backend of the runs")
    parser.add_argument("--cuda", action="store_true",
                        help="also --backend cuda serially (--prefetch 0) and pipelined (--prefetch auto)")
    parser.add_argument("--reps", type=int, default=3)
    parser.add_argument("--dask", action="store_true", help="also a local Dask cluster of --workers workers")
    parser.add_argument("--start", choices=["fork", "spawn", "forkserver"], help="pool start method")
    parser.add_argument("--json", type=Path, help="write every run's figures here")
    args = parser.parse_args(argv)

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    pool_env = {**env, "D3STEREO_POOL_START": args.start} if args.start else env
    n_pairs = None
    tmp = Path(tempfile.mkdtemp(prefix="d3-bench-scaling-"))
    procs = []
    try:
        ways = way_list(args, env, pool_env)
        if args.dask:
            address, procs = start_dask(args.workers, env, tmp)
            ways.append((f"--scheduler ({args.workers} workers)", ["--scheduler", address], env))
        # One untimed run: numba cache written, files in the page cache, Dask workers joined.
        run_once(args.inputs, tmp / "reference", args.method, ways[0][1], env)
        for name, extra, way_env in ways:
            if "cuda" in extra:  # the CUDA kernels compiled or loaded once too
                run_once(args.inputs, tmp / "cuda-warm", args.method, extra, way_env)
                break
        reference = tmp / "reference"
        n_pairs = len(list(reference.glob("*/result.json")))
        if args.dask:
            run_once(args.inputs, tmp / "dask-warm", args.method, ways[-1][1], env)
        runs = []
        for rep in range(args.reps):
            for name, extra, way_env in ways:
                load0 = os.getloadavg()[0]
                out = tmp / f"out-{len(runs)}"
                wall, cpu = run_once(args.inputs, out, args.method, extra, way_env)
                load1 = os.getloadavg()[0]
                identical = same_maps(reference, out)
                runs.append({"way": name, "rep": rep + 1, "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
                             "load": [round(load0, 2), round(load1, 2)], "identical": identical})
                print(f"{name:28s} rep {rep + 1}: {wall:6.2f} s wall, {cpu:6.2f} s CPU, load {load0:.1f}-{load1:.1f},"
                      f" maps identical: {identical}", flush=True)
                shutil.rmtree(out, ignore_errors=True)
    finally:
        for proc in reversed(procs):
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"\n{n_pairs} pairs, {args.reps} runs each, medians:")
    print("| way | wall s | pairs/min | CPU s | load avg | maps identical |")
    print("|---|---|---|---|---|---|")
    for name, _, _ in ways:
        mine = [r for r in runs if r["way"] == name]
        wall = statistics.median(r["wall_s"] for r in mine)
        cpu = statistics.median(r["cpu_s"] for r in mine)
        loads = [x for r in mine for x in r["load"]]
        cpu_text = f"{cpu:.1f}" if not name.startswith("--scheduler") else "-"
        print(f"| {name} | {wall:.1f} | {60 * n_pairs / wall:.1f} | {cpu_text} | {min(loads):.1f}-{max(loads):.1f} |"
              f" {all(r['identical'] for r in mine)} |")
    serial = [r["wall_s"] for r in runs if r["way"] == "serial"]
    for name, _, _ in ways[1:]:
        # Each run against the serial run just before it: the load changes less between neighbours.
        ratios = [r["wall_s"] / s for r, s in zip((r for r in runs if r["way"] == name), serial)]
        print(f"{name}: wall / serial wall of the same repetition, median {statistics.median(ratios):.2f} "
              f"(each: {', '.join(f'{x:.2f}' for x in ratios)})")
    pool = [r["wall_s"] for r in runs if r["way"] == f"--workers {args.workers}"]
    for name, _, _ in ways:
        mine = [r["wall_s"] for r in runs if r["way"] == name]
        if name.startswith("cuda") and pool:  # the claim to check: a GPU batch beats the machine's CPU pool
            print(f"{name}: median wall / --workers {args.workers} median wall "
                  f"{statistics.median(mine) / statistics.median(pool):.2f}")
    if args.json:
        args.json.write_text(json.dumps({"n_pairs": n_pairs, "runs": runs}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
