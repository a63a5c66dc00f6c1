"""Step 8 (the host-side finishing of D3Stereo) before and after its numba kernels.

Per case (the pairs and configs of ``scripts/bench_speed.py``) one process:

1. runs ``D3Stereo(cfg).compute`` once and records the real inputs of every finishing
   function (``occluded_by_uniqueness``, ``out_of_view``, ``fill_holes``,
   ``smooth_disparity``) as ``D3Stereo._finish`` calls them;
2. times each function on those inputs, the NumPy/OpenCV formulation it replaced
   ("before": the references of ``tests/kernels/test_finishing.py``) and the current one
   ("after") **alternately**, ``--reps`` times after a warm-up, and checks that both give
   the same bytes;
3. times the whole ``finish`` step of ``compute`` (``result.timings["finish"]``) with the
   old functions patched into the pipeline and with the current ones, alternately.

Medians of wall time (and of this process's CPU time for the functions).  Run from the
repository root (the references are imported from ``tests/``)::

    PYTHONPATH=. python scripts/bench_finishing.py --cases road road-full middlebury --reps 7
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

NAMES = ("occluded_by_uniqueness", "out_of_view", "fill_holes", "smooth_disparity")


def _references():
    from tests.kernels import test_finishing as t

    return {"occluded_by_uniqueness": t.ref_occluded_by_uniqueness, "out_of_view": t.ref_out_of_view,
            "fill_holes": t.ref_fill_holes, "smooth_disparity": t.ref_smooth_disparity}


def _capture(method, left, right, dmax):
    """One compute with the pipeline's finishing functions wrapped: their (args, kwargs)."""
    import numpy as np

    from d3cli.method import pipeline

    calls, original = [], {n: getattr(pipeline, n) for n in NAMES}

    def wrap(name):
        def call(*args, **kwargs):
            calls.append((name, [np.array(a) if isinstance(a, np.ndarray) else a for a in args],
                          {k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in kwargs.items()}))
            return original[name](*args, **kwargs)
        return call

    try:
        for n in NAMES:
            setattr(pipeline, n, wrap(n))
        method.compute(left, right, max_disparity=dmax)
    finally:
        for n in NAMES:
            setattr(pipeline, n, original[n])
    return calls


def _finish_step(method, left, right, dmax, functions) -> float:
    from d3cli.method import pipeline

    original = {n: getattr(pipeline, n) for n in NAMES}
    try:
        for n, f in functions.items():
            setattr(pipeline, n, f)
        return method.compute(left, right, max_disparity=dmax).timings["finish"]
    finally:
        for n in NAMES:
            setattr(pipeline, n, original[n])


def main(argv=None) -> int:
    import bench_speed
    import numba

    from d3cli import D3Stereo
    from d3cli.method import refinement

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    parser.add_argument("--cases", nargs="+", default=["road", "road-full", "middlebury"],
                        choices=sorted(bench_speed.CASES))
    parser.add_argument("--reps", type=int, default=7)
    parser.add_argument("--no-compute", action="store_true", help="skip the whole-step timing (3.)")
    args = parser.parse_args(argv)
    before = _references()
    after = {n: getattr(refinement, n) for n in NAMES}
    print(f"numba threads {numba.get_num_threads()}, {args.reps} alternating reps after a warm-up; ms, medians")
    for case in args.cases:
        spec = dict(bench_speed.CASES[case], case=case, data=args.data, seed=3, backend="cpu", overrides=[])
        if spec.get("pair") and not (Path(args.data) / spec["pair"]).is_dir():
            print(f"{case}: {Path(args.data) / spec['pair']} not found, skipped")
            continue
        left, right, dmax, name = bench_speed._load(spec)
        method = D3Stereo(bench_speed._config(spec))
        calls = _capture(method, left, right, dmax)
        print(f"\n{case} ({name}, config {spec['config'] or 'defaults'})")
        print("| function | before wall | after wall | before CPU | after CPU | same bytes |")
        print("|---|---|---|---|---|---|")
        sums = {"before": 0.0, "after": 0.0}
        for fname, fargs, fkwargs in calls:
            results = {k: f[fname](*fargs, **fkwargs) for k, f in (("before", before), ("after", after))}
            same = results["before"].tobytes() == results["after"].tobytes()
            wall, cpu = {"before": [], "after": []}, {"before": [], "after": []}
            for _ in range(args.reps):
                for key, funcs in (("before", before), ("after", after)):
                    w0, c0 = time.perf_counter(), time.process_time()
                    funcs[fname](*fargs, **fkwargs)
                    wall[key].append(time.perf_counter() - w0)
                    cpu[key].append(time.process_time() - c0)
            med = {k: (statistics.median(wall[k]) * 1e3, statistics.median(cpu[k]) * 1e3) for k in wall}
            sums["before"] += med["before"][0]
            sums["after"] += med["after"][0]
            print(f"| {fname} | {med['before'][0]:.1f} | {med['after'][0]:.1f} | {med['before'][1]:.1f} | "
                  f"{med['after'][1]:.1f} | {'yes' if same else 'NO'} |")
        print(f"| sum | {sums['before']:.1f} | {sums['after']:.1f} | | | |")
        if not args.no_compute:
            steps = {"before": [], "after": []}
            _finish_step(method, left, right, dmax, after)  # warm-up
            for _ in range(args.reps):
                for key, funcs in (("before", before), ("after", after)):
                    steps[key].append(_finish_step(method, left, right, dmax, funcs) * 1e3)
            before_ms, after_ms = statistics.median(steps["before"]), statistics.median(steps["after"])
            print(f"finish step of compute (incl. sub-pixel, PT restore, masks): "
                  f"before {before_ms:.1f} ms, after {after_ms:.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
