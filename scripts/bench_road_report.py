"""The road report's time against the stereo time of the same 720p road pairs, in one process.

For each synthetic 1280x720 road pair (``d3stereo synth``: calibration and potholes; rendered
once into a cache folder per seed), one process warms up (kernels loaded or compiled), then
``--reps`` times, pair after pair, *alternately*:

* the stereo compute, ``compute_pair("d3stereo", road config)``, as ``d3stereo run -c road``
  matches a pair;
* the road report of that map (:func:`d3cli.road.outputs.road_report`, the re-match with the
  right image included), writing the default files (``run.outputs: all``: height.pfm,
  height_color.png, defects.json, defects.png);
* the road report writing the ``survey`` set (defects.json only).

It prints, per pair and over all pairs, the medians and the ratio road report / stereo (the
median of the per-pair ratios of medians): alternating in one process keeps the ratio
meaningful on a shared, noisy machine, where absolute seconds drift between runs.  Then one
``run_batch`` per output set on the first pair gives the bytes a pair's folder holds with
``--road-report`` and ``--outputs all`` / ``survey`` / ``survey,height``.

``--memory`` then runs ``d3stereo run -c road --outputs survey`` over the pairs (``run_batch``)
in a fresh process, once without and once with the road report, and prints each process's
peak resident set size (``VmHWM`` of ``/proc/self/status``, as ``scripts/bench_speed.py``
reads it): what ``--road-report`` adds to a survey's memory.

``--stages`` then runs the ``survey`` report of every pair once more with one thread
(numba's and OpenCV's), prints its median time a pair (against the medians above: what the
second thread gains), and again under :mod:`cProfile`, printing each stage's share: the plane
fit, the first pass over the stored map (:func:`d3cli.road.defects.candidate_regions`, and
its per-map preparation), the re-match, the second pass (:func:`d3cli.road.defects.remeasure`),
the splitting of both passes and the match margin.

Usage::

    PYTHONPATH=. python scripts/bench_road_report.py            # 4 pairs of seed 0, 3 reps
    PYTHONPATH=. python scripts/bench_road_report.py --pairs 12 --reps 5
    PYTHONPATH=. python scripts/bench_road_report.py --pairs 12 --reps 3 --stages
    PYTHONPATH=. python scripts/bench_road_report.py --pairs 12 --reps 1 --no-bytes --memory
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

OUTPUT_SETS = ("all", "survey", "survey,height")


def _pairs(seed: int, n: int):
    """The first ``n`` pairs of ``d3stereo synth --seed SEED`` (rendered once, then cached)."""
    from d3cli.data import layouts as datasets
    from d3cli.data.synth import generate_dataset

    cache = Path(tempfile.gettempdir()) / f"d3stereo-bench-road-report-{seed}-{n}"
    if not (cache / "synth.json").is_file():
        generate_dataset(cache, n=n, seed=seed, width=1280, height=720)
    return datasets.discover([str(cache)])[:n]


def _folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.iterdir() if p.is_file())


def _child_run(seed: int, n: int, report: bool) -> None:
    """``d3stereo run -c road --outputs survey [--road-report]`` over the pairs, in this
    (fresh) process; prints its VmHWM."""
    from d3cli import load_config
    from d3cli.batch import run_batch

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_speed import _vmhwm_mb  # the speed benchmark's reading of VmHWM

    cfg = load_config("road", ["run.backend=cpu", f"road.report={str(report).lower()}", "run.outputs=survey"])
    with tempfile.TemporaryDirectory() as out:
        run_batch(_pairs(seed, n), Path(out), cfg=cfg, method="d3stereo", progress=False)
    print(f"{_vmhwm_mb():.1f}")


def _memory(seed: int, n: int) -> None:
    """Peak MB of a fresh process running the batch without and with the road report."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    peaks = {}
    for report in (False, True):
        proc = subprocess.run([sys.executable, __file__, "--pairs", str(n), "--seed", str(seed), "--child-run",
                               "report" if report else "stereo"], capture_output=True, text=True, check=True, env=env)
        peaks[report] = float(proc.stdout.strip().splitlines()[-1])
    print(f"\npeak memory of a fresh `run -c road --outputs survey` process over the {n} pairs (VmHWM): "
          f"{peaks[False]:.0f} MB without the road report, {peaks[True]:.0f} MB with it "
          f"({peaks[True] - peaks[False]:+.0f} MB)")


#: (label, module, function) of the stages --stages reports: each one's cumulative time
#: (its callees included) as a share of the whole; an indented one is a part of the one
#: above, the splitting a part of both passes.
STAGES = (
    ("the grid's cells", "d3cli/road/grid.py", "disparities"),
    ("plane fit", "d3cli/road/plane.py", "fit_road_plane"),
    ("first pass", "d3cli/road/defects.py", "candidate_regions"),
    ("  of which the per-map preparation", "d3cli/road/defects.py", "prepare_scene"),
    ("re-match", "d3cli/road/outputs.py", "_rematched"),
    ("second pass", "d3cli/road/defects.py", "remeasure"),
    ("the splitting, in both passes", "d3cli/road/splitting.py", "split_component"),
    ("match margin", "d3cli/road/rematch.py", "match_margin"),
)


def _stages(run, names, threaded_ms: float) -> None:
    """Print the one-thread time of ``run(name)`` over ``names`` against ``threaded_ms`` (the
    median of the pairs' medians with the threads of the run) and each stage's share of it
    under cProfile."""
    import cProfile
    import pstats

    import cv2
    import numba

    threads = numba.get_num_threads(), cv2.getNumThreads()
    numba.set_num_threads(1)
    cv2.setNumThreads(1)
    try:
        plain = []  # the same reports without the profiler: the one-thread time
        for name in names:
            t0 = time.perf_counter()
            run(name)
            plain.append(time.perf_counter() - t0)
        profile = cProfile.Profile()
        t0 = time.perf_counter()
        profile.enable()
        for name in names:
            run(name)
        profile.disable()
        total = time.perf_counter() - t0
    finally:
        numba.set_num_threads(threads[0])
        cv2.setNumThreads(threads[1])
    stats = pstats.Stats(profile).stats  # {(file, line, function): (cc, nc, tt, ct, callers)}
    print(f"\nthe survey report with one thread: median {1e3 * statistics.median(plain):.0f} ms a pair "
          f"({threaded_ms:.0f} ms with {os.cpu_count()} CPUs above); its stages ({len(names)} pairs under cProfile, "
          f"{1e3 * total / len(names):.0f} ms a pair):")
    for label, path, function in STAGES:
        spent = sum(v[3] for (file, _, func), v in stats.items() if func == function and file.endswith(path))
        print(f"  {label:<36} {100 * spent / total:5.1f} %")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pairs", type=int, default=4, help="synthetic 720p road pairs (default 4)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the synthetic pairs (default 0)")
    parser.add_argument("--reps", type=int, default=3, help="alternating repetitions after the warm-up")
    parser.add_argument("--no-bytes", action="store_true", help="skip the bytes per output set")
    parser.add_argument("--stages", action="store_true",
                        help="each stage's share of the survey report, one thread, under cProfile")
    parser.add_argument("--memory", action="store_true",
                        help="peak memory of a fresh batch process without and with the road report")
    parser.add_argument("--child-run", choices=("stereo", "report"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child_run:
        _child_run(args.seed, args.pairs, args.child_run == "report")
        return 0

    from d3cli import load_config
    from d3cli.batch import compute_pair, run_batch
    from d3cli.config import output_groups
    from d3cli.data import formats as io, layouts as datasets
    from d3cli.road.pointcloud import camera_from
    from d3cli.road.outputs import road_report

    cfg = load_config("road", ["run.backend=cpu", "road.report=true"])
    pairs = _pairs(args.seed, args.pairs)
    loaded = []
    for pair in pairs:
        left, right = datasets.load_pair_images(pair)
        camera = camera_from(io.read_calib(pair.calib), cfg, left.shape[:2])
        dmax = datasets.resolve_max_disparity(pair, left.shape[1])
        loaded.append((pair.name, left, right, camera, dmax))
    work = Path(tempfile.mkdtemp(prefix="d3stereo-bench-road-report-"))
    groups = {"all": output_groups("all"), "survey": output_groups("survey")}

    def report(name, left, right, camera, result, which):
        folder = work / which / name
        folder.mkdir(parents=True, exist_ok=True)
        road_report(folder, left, result.disparity, result.valid, camera, result.info, cfg.road, right=right,
                    groups=groups[which])

    t0 = time.perf_counter()
    for name, left, right, camera, dmax in loaded[:1]:  # warm-up: kernels loaded or compiled
        result = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
        report(name, left, right, camera, result, "all")
    print(f"warm-up {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    times = {name: {"stereo": [], "all": [], "survey": []} for name, *_ in loaded}
    last = []  # each pair's map of the last repetition, for --stages
    for rep in range(args.reps):
        for name, left, right, camera, dmax in loaded:
            t0 = time.perf_counter()
            result = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
            times[name]["stereo"].append(time.perf_counter() - t0)
            if rep == args.reps - 1:
                last.append((name, left, right, camera, result))
            for which in ("all", "survey"):
                t0 = time.perf_counter()
                report(name, left, right, camera, result, which)
                times[name][which].append(time.perf_counter() - t0)
        print(f"rep {rep + 1}/{args.reps} done", file=sys.stderr, flush=True)

    print(f"{len(loaded)} synthetic 1280x720 road pairs (seed {args.seed}), -c road, CPU, {os.cpu_count()} CPUs, "
          f"{args.reps} alternating reps after a warm-up; medians in ms")
    print(f"{'pair':<26} {'stereo':>8} {'report':>8} {'survey':>8} {'ratio':>6} {'survey':>7}")
    ratios, survey_ratios = [], []
    for name, t in times.items():
        stereo, full, survey = (statistics.median(t[k]) for k in ("stereo", "all", "survey"))
        ratios.append(full / stereo)
        survey_ratios.append(survey / stereo)
        print(f"{name:<26} {stereo * 1e3:8.0f} {full * 1e3:8.0f} {survey * 1e3:8.0f} {full / stereo:6.2f} "
              f"{survey / stereo:7.2f}")
    print(f"road report / stereo (median over pairs): {statistics.median(ratios):.2f} with the default files, "
          f"{statistics.median(survey_ratios):.2f} with --outputs survey; most {max(ratios):.2f} / "
          f"{max(survey_ratios):.2f}")

    if args.stages:
        kept = {name: (left, right, camera, result) for name, left, right, camera, result in last}
        _stages(lambda name: report(name, *kept[name][:3], kept[name][3], "survey"), list(kept),
                1e3 * statistics.median(statistics.median(t["survey"]) for t in times.values()))

    if not args.no_bytes:
        print("\nbytes per pair folder with --road-report (first pair):")
        for outputs in OUTPUT_SETS:
            out = work / f"run-{outputs.replace(',', '-')}"
            run_batch(pairs[:1], out, cfg=replace(cfg, run=replace(cfg.run, outputs=outputs)), method="d3stereo",
                      progress=False)
            folder = out / pairs[0].name
            names = sorted(p.name for p in folder.iterdir() if p.is_file())
            print(f"  {outputs:<14} {_folder_bytes(folder) / 1e6:6.2f} MB  ({', '.join(names)})")
    if args.memory:
        _memory(args.seed, args.pairs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
