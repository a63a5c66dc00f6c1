"""Step 8 (the host-side finishing of D3Stereo) before and after its numba kernels.

Per case (the pairs and configs of ``scripts/bench_speed.py``) one process:

1. runs ``D3Stereo(cfg).compute`` once and records the real inputs of every finishing
   function (``occluded_by_uniqueness``, ``out_of_view``, ``fill_holes``,
   ``smooth_disparity``) as ``D3Stereo._finish`` calls them;
2. times each function on those inputs, its NumPy/OpenCV reference formulation
   ("before": the references of ``tests/reference/finishing.py``) and the current one
   ("after") **alternately**, ``--reps`` times after a warm-up, and checks that both give
   the same bytes;
3. times the whole ``finish`` step of ``compute`` (``result.timings["finish"]``) with the
   old functions patched into the pipeline and with the current ones, alternately.

With ``--against REV`` "before" is instead the code of a git revision:
``d3cli/kernels/finishing.py``, ``d3cli/method/refinement.py`` and
``d3cli/method/perspective.py`` as they were at REV, loaded side by side with the current
ones (so A/B of a kernel change in one process); the speckle filter and the road fit
(``fit_road_model``, step 6, timed outside ``finish``) are timed too.

Medians of wall time (and of this process's CPU time for the functions).  Run from the
repository root (the references are imported from ``tests/``)::

    PYTHONPATH=. python scripts/bench_finishing.py --cases road road-full middlebury --reps 7
    PYTHONPATH=. python scripts/bench_finishing.py --cases road kitti --against 814ec9c --reps 9
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

NAMES = ("occluded_by_uniqueness", "out_of_view", "fill_holes", "smooth_disparity")
# with --against: every host function of the finishing, and the road fit
ALL_NAMES = ("fit_road_model", "occluded_by_uniqueness", "out_of_view", "speckles", "fill_holes", "smooth_disparity")


def _references():
    from tests.reference import finishing as t

    return {"occluded_by_uniqueness": t.ref_occluded_by_uniqueness, "out_of_view": t.ref_out_of_view,
            "fill_holes": t.ref_fill_holes, "smooth_disparity": t.ref_smooth_disparity}


def _at_revision(rev: str) -> dict:
    """The finishing functions and the road fit as they were at git revision ``rev``.

    The three modules are loaded from ``git show REV:path`` under private names inside the
    ``d3cli`` package (their relative imports resolve there); the old refinement module is
    executed while ``d3cli.kernels.finishing`` names the old kernels, so it calls those.
    """
    import importlib.util
    import subprocess
    import tempfile

    import d3cli.kernels

    folder = Path(tempfile.mkdtemp(prefix=f"d3old-{rev[:12]}-"))

    def load(path, name):
        source = subprocess.run(["git", "show", f"{rev}:{path}"], cwd=ROOT, check=True, capture_output=True,
                                text=True).stdout
        file = folder / Path(path).name
        file.write_text(source)
        spec = importlib.util.spec_from_file_location(name, file)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module

    finishing = load("d3cli/kernels/finishing.py", "d3cli.kernels._old_finishing")
    current = d3cli.kernels.finishing
    try:
        d3cli.kernels.finishing = sys.modules["d3cli.kernels.finishing"] = finishing
        refinement = load("d3cli/method/refinement.py", "d3cli.method._old_refinement")
    finally:
        d3cli.kernels.finishing = sys.modules["d3cli.kernels.finishing"] = current
    perspective = load("d3cli/method/perspective.py", "d3cli.method._old_perspective")
    funcs = {n: getattr(refinement, n) for n in ALL_NAMES if n != "fit_road_model"}
    funcs["fit_road_model"] = perspective.fit_road_model
    return funcs


def _same(a, b) -> bool:
    """Equal bytes of two maps; equal fields of two road models (their classes differ)."""
    import dataclasses

    if dataclasses.is_dataclass(a):
        return dataclasses.astuple(a) == dataclasses.astuple(b)
    return a.tobytes() == b.tobytes()


def _capture(method, left, right, dmax, names=NAMES):
    """One compute with the pipeline's finishing functions wrapped: their (args, kwargs)."""
    import numpy as np

    from d3cli.method import pipeline

    calls, original = [], {n: getattr(pipeline, n) for n in names}

    def wrap(name):
        def call(*args, **kwargs):
            calls.append((name, [np.array(a) if isinstance(a, np.ndarray) else a for a in args],
                          {k: np.array(v) if isinstance(v, np.ndarray) else v for k, v in kwargs.items()}))
            return original[name](*args, **kwargs)
        return call

    try:
        for n in names:
            setattr(pipeline, n, wrap(n))
        method.compute(left, right, max_disparity=dmax)
    finally:
        for n in names:
            setattr(pipeline, n, original[n])
    return calls


def _finish_step(method, left, right, dmax, functions) -> float:
    from d3cli.method import pipeline

    original = {n: getattr(pipeline, n) for n in functions}
    try:
        for n, f in functions.items():
            setattr(pipeline, n, f)
        return method.compute(left, right, max_disparity=dmax).timings["finish"]
    finally:
        for n in functions:
            setattr(pipeline, n, original[n])


def main(argv=None) -> int:
    import bench_speed
    import numba

    from d3cli import D3Stereo
    from d3cli.method import refinement

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.environ.get("D3STEREO_DATA", ""),
                        help="data folder holding the real pairs (default: $D3STEREO_DATA)")
    parser.add_argument("--cases", nargs="+", default=["road", "road-full", "middlebury"],
                        choices=sorted(bench_speed.CASES))
    parser.add_argument("--reps", type=int, default=7)
    parser.add_argument("--no-compute", action="store_true", help="skip the whole-step timing (3.)")
    parser.add_argument("--against", metavar="REV",
                        help="'before' is the code of this git revision, not the NumPy references")
    args = parser.parse_args(argv)
    from d3cli.method import perspective

    if args.against:
        names = ALL_NAMES
        before = _at_revision(args.against)
    else:
        names = NAMES
        before = _references()
    after = {n: getattr(refinement, n) for n in names if n != "fit_road_model"}
    after["fit_road_model"] = perspective.fit_road_model
    print(f"numba threads {numba.get_num_threads()}, {args.reps} alternating reps after a warm-up; ms, medians; "
          f"before: {args.against or 'NumPy references'}")
    for case in args.cases:
        spec = dict(bench_speed.CASES[case], case=case, data=args.data, seed=3, backend="cpu", overrides=[])
        if spec.get("pair") and not (Path(args.data) / spec["pair"]).is_dir():
            print(f"{case}: {Path(args.data) / spec['pair']} not found, skipped")
            continue
        left, right, dmax, name = bench_speed._load(spec)
        method = D3Stereo(bench_speed._config(spec))
        calls = _capture(method, left, right, dmax, names)
        print(f"\n{case} ({name}, config {spec['config'] or 'defaults'})")
        print("| function | before wall | after wall | before CPU | after CPU | same bytes |")
        print("|---|---|---|---|---|---|")
        sums = {"before": 0.0, "after": 0.0}
        for fname, fargs, fkwargs in calls:
            results = {k: f[fname](*fargs, **fkwargs) for k, f in (("before", before), ("after", after))}
            same = _same(results["before"], results["after"])
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
        print(f"| sum{' (road fit included)' if 'fit_road_model' in names else ''} | {sums['before']:.1f} | "
              f"{sums['after']:.1f} | | | |")
        if not args.no_compute:
            steps = {"before": [], "after": []}
            # the road fit is not part of the finish step
            in_step = {k: {n: f for n, f in funcs.items() if n != "fit_road_model"}
                       for k, funcs in (("before", before), ("after", after))}
            _finish_step(method, left, right, dmax, in_step["after"])  # warm-up
            for _ in range(args.reps):
                for key, funcs in in_step.items():
                    steps[key].append(_finish_step(method, left, right, dmax, funcs) * 1e3)
            before_ms, after_ms = statistics.median(steps["before"]), statistics.median(steps["after"])
            print(f"finish step of compute (incl. sub-pixel, PT restore, masks): "
                  f"before {before_ms:.1f} ms, after {after_ms:.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
