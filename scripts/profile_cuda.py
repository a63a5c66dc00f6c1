"""Where a CUDA run spends its launches, copies and time: per kernel and per pipeline step.

For every case (the pairs and configs of ``scripts/bench_speed.py``, plus ``tiny``, a 64x32
textured pair made here that needs no data and suits the CUDA simulator)::

    1. one warm-up call (compiles or loads the kernels);
    2. one call inside ``count_cuda_calls()``: kernel launches, device-to-host and
       host-to-device copies, launches per kernel (the budget of a GPU program);
    3. ``--reps`` calls, untimed inside: the median wall time of a whole pair, host images in,
       host disparity out, and the median of every step of ``result.timings``;
    4. on a GPU, one call inside ``count_cuda_calls(timing=True)``: every launch synchronised
       and timed, the kernels by time (a timed call is slower than an untimed one).

Usage::

    python scripts/profile_cuda.py --data DATA --cases road kitti --reps 5
    NUMBA_ENABLE_CUDASIM=1 python scripts/profile_cuda.py --cases tiny --reps 0   # no GPU

DATA is the folder holding the benchmark pairs (``middlebury2014-adirondack-Q``,
``kitti2015-000000_10``); the road cases are synthetic and need none.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_speed  # noqa: E402  (the same cases, loaders and configs as the speed benchmark)

CASES = {**bench_speed.CASES, "tiny": {"tiny": [64, 32], "config": None}}


def _tiny_pair():
    """A 64x32 textured pair, true disparity 5 everywhere, range 16."""
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    wide = cv2.GaussianBlur(rng.uniform(0, 255, (32, 80)).astype(np.float32), (3, 3), 0.8)
    return np.ascontiguousarray(wide[:, 0:64]), np.ascontiguousarray(wide[:, 5:69]), 16, "tiny textured 64x32"


def profile_case(name: str, spec: dict, reps: int) -> dict:
    """Counts, times and per-kernel times of one case (see the module docstring)."""
    from d3cli.batch import compute_pair
    from d3cli.kernels import cuda_status
    from d3cli.kernels.cuda_calls import count_cuda_calls

    if spec.get("tiny"):
        left, right, dmax, label = _tiny_pair()
    else:
        left, right, dmax, label = bench_speed._load(spec)
    cfg = bench_speed._config(spec)
    t0 = time.perf_counter()
    compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
    cold = time.perf_counter() - t0
    with count_cuda_calls() as calls:
        res = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
    walls, steps = [], {}
    for _ in range(reps):
        t0 = time.perf_counter()
        res = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
        walls.append(time.perf_counter() - t0)
        for key, value in res.timings.items():
            steps.setdefault(key, []).append(value)
    row = {
        "case": name, "pair": label, "size": f"{left.shape[1]}x{left.shape[0]}", "max_disparity": dmax,
        "backend": res.info.get("backend"), "cold_s": cold,
        "launches": calls.launches, "device_to_host": calls.device_to_host, "host_to_device": calls.host_to_device,
        "launches_by_kernel": dict(calls.by_kernel.most_common()),
        "wall_ms": 1e3 * statistics.median(walls) if walls else None,
        "steps_ms": {k: 1e3 * statistics.median(v) for k, v in steps.items()},
    }
    if cuda_status()[1].startswith("CUDA device"):
        with count_cuda_calls(timing=True) as timed:
            compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
        row["kernel_ms"] = {k: 1e3 * v for k, v in sorted(timed.seconds.items(), key=lambda kv: -kv[1])}
        row["kernel_ms_total"] = 1e3 * sum(timed.seconds.values())
    return row


def _print(row: dict) -> None:
    wall = "-" if row["wall_ms"] is None else f"{row['wall_ms']:.1f} ms"
    print(f"\n## {row['case']}: {row['pair']} ({row['size']}, range {row['max_disparity']}), "
          f"backend {row['backend']}")
    print(f"launches {row['launches']}, device-to-host copies {row['device_to_host']}, "
          f"host-to-device copies {row['host_to_device']}; wall per pair {wall} (median); "
          f"first call {row['cold_s']:.1f} s")
    if row["steps_ms"]:
        print("steps (ms): " + ", ".join(f"{k} {v:.1f}" for k, v in row["steps_ms"].items()))
    timed = row.get("kernel_ms", {})
    for kernel, n in row["launches_by_kernel"].items():
        extra = f"  {timed[kernel]:8.3f} ms" if kernel in timed else ""
        print(f"  {n:5d} x {kernel}{extra}")
    if timed:
        print(f"  kernel time, each launch synchronised: {row['kernel_ms_total']:.2f} ms")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.environ.get("D3STEREO_DATA", ""),
                        help="data folder with the benchmark pairs (default: $D3STEREO_DATA)")
    parser.add_argument("--cases", nargs="+", default=["road", "kitti"], choices=sorted(CASES))
    parser.add_argument("--reps", type=int, default=5, help="untimed-inside calls for the median wall time")
    parser.add_argument("--seed", type=int, default=3, help="seed of the synthetic road pairs")
    parser.add_argument("--json", dest="json_out", help="also write the rows to this JSON file")
    args = parser.parse_args(argv)
    rows = []
    for name in args.cases:
        spec = {**CASES[name], "data": args.data, "seed": args.seed, "backend": "cuda", "reps": args.reps}
        rows.append(profile_case(name, spec, args.reps))
        _print(rows[-1])
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
