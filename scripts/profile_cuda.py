"""Where a CUDA run spends its launches, copies and time: per kernel and per pipeline step.

For every case (the pairs and configs of ``scripts/bench_speed.py``, plus ``tiny``, a 64x32
uint8 textured pair made here that needs no data and suits the CUDA simulator, with the
default settings, ``tiny-kitti`` and ``tiny-paper`` with those configs, and ``tiny-road``, a
64x32 synthetic road with road.yaml)::

    1. one warm-up call (compiles or loads the kernels);
    2. one call inside ``count_cuda_calls()``: kernel launches, device-to-host and
       host-to-device copies and their bytes (per call site), launches per kernel (the
       budget of a GPU program), and per pipeline step its wall time split into time inside
       launches and copies and host time outside them (under the simulator the kernels run
       as Python inside the launches, so the host figure holds there too);
    3. ``--reps`` calls, untimed inside: the median wall time of a whole pair, host images in,
       host disparity out, and the median of every step of ``result.timings``;
    4. on a GPU, one call inside ``count_cuda_calls(timing=True)``: every launch synchronised
       and timed, the kernels by time (a timed call is slower than an untimed one).

Usage::

    python scripts/profile_cuda.py --data DATA --cases road kitti --reps 5
    NUMBA_ENABLE_CUDASIM=1 python scripts/profile_cuda.py --cases tiny tiny-road tiny-kitti tiny-paper --reps 0

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

CASES = {**bench_speed.CASES, "tiny": {"tiny": [64, 32], "config": None},
         **{f"tiny-{name}": {"tiny": [64, 32], "config": name} for name in ("road", "kitti", "paper")}}

#: Pipeline step -> (where, attribute) of the function that runs it; a step's time is that
#: of its calls, less the steps called inside it.
STEPS = {
    "pyramid": ("backend", "pyramid"),
    "band": ("backend", "band_indexes"),
    "cost": ("pipeline", "level_cost"),
    "decide": ("D3Stereo", "_decide"),
    "diffusion": ("pipeline", "diffuse"),
    "road fit": ("pipeline", "fit_road_model"),
    "counts": ("D3Stereo", "_read_counts"),
    "finish": ("D3Stereo", "_finish"),
}


class _StepSpans:
    """Records ``(step, start, end)`` of every call of the :data:`STEPS` functions while active."""

    def __init__(self):
        self.spans: list[tuple[str, float, float]] = []
        self._saved = []

    def __enter__(self):
        from d3cli.kernels import cuda as backend
        from d3cli.method import pipeline

        owners = {"backend": backend, "pipeline": pipeline, "D3Stereo": pipeline.D3Stereo}
        for step, (where, name) in STEPS.items():
            owner = owners[where]
            original = getattr(owner, name)

            def timed(*a, _step=step, _f=original, **k):
                start = time.perf_counter()
                try:
                    return _f(*a, **k)
                finally:
                    self.spans.append((_step, start, time.perf_counter()))

            self._saved.append((owner, name, original))
            setattr(owner, name, timed)
        return self

    def __exit__(self, *exc):
        for owner, name, original in reversed(self._saved):
            setattr(owner, name, original)


def split_steps(spans, calls, start: float, end: float) -> dict:
    """Per step ``{wall_ms, calls_ms, host_ms}``: each instant of ``[start, end]`` belongs to
    the innermost step running then ("other" outside every step); ``calls_ms`` is the time
    inside launches and copies (:meth:`CudaCalls.seconds_in_calls`), ``host_ms`` the rest."""
    cuts = sorted({start, end, *(t for _, s0, s1 in spans for t in (s0, s1) if start <= t <= end)})
    out: dict[str, dict[str, float]] = {}
    for t0, t1 in zip(cuts, cuts[1:]):
        mid = 0.5 * (t0 + t1)
        inside = [(s0, step) for step, s0, s1 in spans if s0 <= mid <= s1]
        step = max(inside)[1] if inside else "other"
        row = out.setdefault(step, {"wall_ms": 0.0, "calls_ms": 0.0, "host_ms": 0.0})
        wall, in_calls = t1 - t0, calls.seconds_in_calls(t0, t1)
        row["wall_ms"] += 1e3 * wall
        row["calls_ms"] += 1e3 * in_calls
        row["host_ms"] += 1e3 * (wall - in_calls)
    return out


def _tiny_pair(road: bool = False):
    """A 64x32 uint8 textured pair, true disparity 5 everywhere, range 16, or with ``road``
    a 64x32 synthetic road (the pairs of ``tests/kernels/test_cuda_budget.py``)."""
    import cv2
    import numpy as np

    if road:
        from d3cli.data.synth import render_pair

        pair = render_pair(seed=1, width=64, height=32, variant="sun", flat=True, noise=False, supersample=1)
        return pair.left, pair.right, 16, "tiny synthetic road 64x32"

    rng = np.random.default_rng(0)
    wide = cv2.GaussianBlur(rng.uniform(0, 255, (32, 80)).astype(np.float32), (3, 3), 0.8)
    wide = np.round(wide).astype(np.uint8)
    return np.ascontiguousarray(wide[:, 0:64]), np.ascontiguousarray(wide[:, 5:69]), 16, "tiny textured 64x32"


def profile_case(name: str, spec: dict, reps: int) -> dict:
    """Counts, times and per-kernel times of one case (see the module docstring)."""
    from d3cli.batch import compute_pair
    from d3cli.kernels import cuda_status
    from d3cli.kernels.cuda_calls import count_cuda_calls

    if spec.get("tiny"):
        left, right, dmax, label = _tiny_pair(road=spec["config"] == "road")
    else:
        left, right, dmax, label = bench_speed._load(spec)
    cfg = bench_speed._config(spec)
    t0 = time.perf_counter()
    compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
    cold = time.perf_counter() - t0
    with count_cuda_calls() as calls, _StepSpans() as step_spans:
        t_start = time.perf_counter()
        res = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
        t_end = time.perf_counter()
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
        "device_to_host_bytes": calls.device_to_host_bytes, "host_to_device_bytes": calls.host_to_device_bytes,
        "copies_by_site": {f"{d} {site}": {"copies": n, "bytes": b} for (d, site), (n, b) in calls.by_site.items()},
        "host_by_step": split_steps(step_spans.spans, calls, t_start, t_end),
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
    print(f"launches {row['launches']}, device-to-host copies {row['device_to_host']} "
          f"({row['device_to_host_bytes']} bytes), host-to-device copies {row['host_to_device']} "
          f"({row['host_to_device_bytes']} bytes); wall per pair {wall} (median); "
          f"first call {row['cold_s']:.1f} s")
    for site, c in row["copies_by_site"].items():
        print(f"  copy {site}: {c['copies']} x, {c['bytes']} bytes")
    print("per step of the counted call (ms): wall = inside launches and copies + host")
    for step, t in sorted(row["host_by_step"].items(), key=lambda kv: -kv[1]["host_ms"]):
        print(f"  {step:10s} {t['wall_ms']:9.2f} = {t['calls_ms']:9.2f} + {t['host_ms']:8.2f}")
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
