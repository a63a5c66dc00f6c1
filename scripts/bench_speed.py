"""d3stereo against OpenCV SGBM: time ratio in one process, peak memory per fresh process.

For every case (a stereo pair + a config):

* **time**: one process loads the pair, runs d3stereo and SGBM once each as a warm-up
  (kernels loaded from numba's cache or compiled; the machine's caches warmed), then
  ``--reps`` times d3stereo and SGBM *alternately*; the medians and their ratio are
  reported. Alternating in one process keeps the ratio meaningful on a shared, noisy
  machine, where absolute seconds drift between runs. The median of every step of
  ``result.timings`` (pyramid, cost per level, seeds, diffusion, sgm, finish, ...) is printed,
  the semi-global smoothing's share of the time (median of the reps' shares, where it runs),
  and the md5 of the d3stereo disparity map (a speed-up that should change no output
  must leave it as it was).  Each rep's own ratio (the d3stereo call against the SGBM call
  right after it) is printed too, least / median / most: on a shared host the machine
  runs in spells of seconds at about half or full speed, which move the two methods
  differently (docs/performance.md, 'Current figures'; ``scripts/bench_spells.py``), and their spread
  shows how far one run's ratio can be trusted.
* **memory**: one fresh process per method does a single call and reads its peak
  resident set size, ``VmHWM`` of ``/proc/self/status`` (``ru_maxrss`` would carry the
  parent's peak across ``exec``); this is the whole process, interpreter and libraries
  included, as a user sees it.

``--against KEY=VALUE`` (repeatable) times a second d3stereo, the case's config with those
overrides too, in the same process and alternation (d3stereo, the variant, SGBM): the
speed of a setting against the shipped one on a noisy machine, where two separate runs
drift apart more than the setting changes.

SGBM is ``d3cli.batch.compute_pair("sgbm", ...)`` with the case's config and the same
disparity range: OpenCV StereoSGBM, 3-way, block ``sgbm.block_size`` (5 by default,
forced to 5 on every case with ``--sgbm-block 5``, the reference of the speed figures in
docs/performance.md).

Cases (``--cases``, default all that exist)::

    road          1280x720 synthetic road pair (d3cli.data.synth.render_pair), config road
    road-full     the same pair, default config (PT off: full range)
    middlebury    middlebury2014-adirondack-Q, config middlebury
    kitti         kitti2015-000000_10, config kitti
    road-1440     2560x1440 synthetic road pair, config road
    road-2160     3840x2160 synthetic road pair, config road (memory bound: PT within 4 GB)

Usage::

    PYTHONPATH=. python scripts/bench_speed.py --data DATA --markdown
    PYTHONPATH=. python scripts/bench_speed.py --cases road road-full --reps 7
    PYTHONPATH=. python scripts/bench_speed.py --cases middlebury --reps 11 --no-memory \
        --against pyramid.finest_band_tile=32
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CASES = {
    "road": {"synth": [1280, 720], "config": "road"},
    "road-full": {"synth": [1280, 720], "config": None},
    "middlebury": {"pair": "middlebury2014-adirondack-Q", "config": "middlebury"},
    "kitti": {"pair": "kitti2015-000000_10", "config": "kitti"},
    "road-1440": {"synth": [2560, 1440], "config": "road"},
    "road-2160": {"synth": [3840, 2160], "config": "road"},
}
DEFAULT_CASES = ("road", "road-full", "middlebury", "kitti")


def _vmhwm_mb() -> float:
    """Peak resident set size of this process (VmHWM), MB."""
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _load(spec: dict):
    """Left, right, max disparity and a display name of the case's pair."""
    import numpy as np

    if spec.get("pair"):
        from d3cli.data.layouts import discover, load_pair_images, resolve_max_disparity

        pair = discover([str(Path(spec["data"]) / spec["pair"])])[0]
        left, right = load_pair_images(pair)
        return left, right, resolve_max_disparity(pair, left.shape[1]), pair.name
    width, height = spec["synth"]
    cache = Path(tempfile.gettempdir()) / f"d3stereo-bench-{width}x{height}-{spec['seed']}"
    if not (cache / "left.npy").exists():
        from d3cli.data.synth import render_pair

        synth = render_pair(seed=spec["seed"], width=width, height=height)
        gt = np.where(np.isfinite(synth.disparity), synth.disparity, 0)
        cache.mkdir(parents=True, exist_ok=True)
        np.save(cache / "left.npy", synth.left)
        np.save(cache / "right.npy", synth.right)
        np.save(cache / "dmax.npy", np.array(int(np.ceil(np.nanmax(gt)))))
    dmax = int(np.load(cache / "dmax.npy")) + 8  # a little headroom above the true maximum
    return np.load(cache / "left.npy"), np.load(cache / "right.npy"), dmax, f"synth road {width}x{height}"


def case_spec(case: str, data: str, **options) -> dict | None:
    """The spec of a case (its pair or synthetic size and config, ``data``, ``options``),
    or None, said on stderr, when its real pair is not in ``data``."""
    spec = dict(CASES[case], case=case, data=data, **options)
    if spec.get("pair") and not (Path(data) / spec["pair"]).is_dir():
        print(f"{case}: {Path(data) / spec['pair']} not found, skipped", file=sys.stderr)
        return None
    return spec


def _config(spec: dict, extra=()):
    from d3cli import load_config

    overrides = [f"run.backend={spec['backend']}"]
    if spec.get("sgbm_block"):
        overrides.append(f"sgbm.block_size={spec['sgbm_block']}")
    overrides += spec.get("overrides", [])
    overrides += list(extra)
    cfg_path = spec["config"]  # a bundled config's name, or None
    return load_config(cfg_path, overrides)


def _child_time(spec: dict) -> dict:
    """Warm-up, then d3stereo and SGBM alternately; medians of time and of every step."""
    import hashlib

    import numpy as np

    from d3cli.batch import compute_pair

    left, right, dmax, name = _load(spec)
    cfg = _config(spec)
    against = _config(spec, spec["against"]) if spec.get("against") else None
    t0 = time.perf_counter()
    compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
    cold = time.perf_counter() - t0
    if against is not None:
        res_b = compute_pair("d3stereo", against, left, right, max_disparity=dmax)
    compute_pair("sgbm", cfg, left, right, max_disparity=dmax)
    d3, d3_b, sg, steps, sgm_share = [], [], [], {}, []
    for _ in range(spec["reps"]):
        t0 = time.perf_counter()
        res = compute_pair("d3stereo", cfg, left, right, max_disparity=dmax)
        d3.append(time.perf_counter() - t0)
        if against is not None:
            t0 = time.perf_counter()
            res_b = compute_pair("d3stereo", against, left, right, max_disparity=dmax)
            d3_b.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        compute_pair("sgbm", cfg, left, right, max_disparity=dmax)
        sg.append(time.perf_counter() - t0)
        for key, value in res.timings.items():
            steps.setdefault(key, []).append(value)
        if "sgm" in res.timings:  # the semi-global smoothing's share of this call (limit: 15 % on KITTI)
            sgm_share.append(res.timings["sgm"] / res.timings["total"])
    return {
        "pair": name, "size": f"{left.shape[1]}x{left.shape[0]}", "max_disparity": dmax,
        "backend": res.info.get("backend", "?"), "pt": res.info.get("pt", {}).get("applied")
        if isinstance(res.info.get("pt"), dict) else None,
        "cold_s": cold, "d3_s": statistics.median(d3), "sgbm_s": statistics.median(sg),
        # each rep's own ratio (d3stereo against the SGBM call right after it): their spread
        # shows how much the machine moved during the run (a shared host's slow and fast spells)
        "paired_ratios": sorted(a / b for a, b in zip(d3, sg)),
        "steps": {k: statistics.median(v) for k, v in steps.items()},
        "sgm_share": statistics.median(sgm_share) if sgm_share else None,
        # bit-identity check of a speed-up: the same md5 before and after the change
        "disparity_md5": hashlib.md5(np.ascontiguousarray(res.disparity, dtype=np.float32).tobytes()).hexdigest(),
        "against_s": statistics.median(d3_b) if d3_b else None,
        "against_md5": hashlib.md5(np.ascontiguousarray(res_b.disparity, dtype=np.float32).tobytes()).hexdigest()
        if d3_b else None,
    }


def _child_memory(spec: dict) -> dict:
    """One call of one method in this fresh process; its VmHWM."""
    from d3cli.batch import compute_pair

    left, right, dmax, _ = _load(spec)
    cfg = _config(spec)
    compute_pair(spec["method"], cfg, left, right, max_disparity=dmax)
    return {"vmhwm_mb": _vmhwm_mb()}


def _spawn(spec: dict) -> dict | None:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, __file__, "--child", json.dumps(spec)],
                          capture_output=True, text=True, check=False, env=env)
    if proc.returncode != 0:
        print(f"{spec['case']} {spec['mode']}: failed\n{proc.stderr[-2000:]}", file=sys.stderr)
        return None
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=os.environ.get("D3STEREO_DATA", ""),
                        help="data folder holding the real pairs (default: $D3STEREO_DATA; cases "
                             "whose pair is not there are skipped)")
    parser.add_argument("--cases", nargs="+", default=None, choices=sorted(CASES),
                        help=f"cases to run (default: {' '.join(DEFAULT_CASES)})")
    parser.add_argument("--reps", type=int, default=5, help="alternating repetitions after the warm-up")
    parser.add_argument("--seed", type=int, default=3, help="seed of the synthetic road pairs")
    parser.add_argument("--backend", default="cpu", choices=("cpu", "cuda", "auto"))
    parser.add_argument("--sgbm-block", type=int, default=5,
                        help="SGBM block size for the reference (default 5, the speed figures' baseline; 0: the config's)")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        help="config override for every case, e.g. --set pyramid.band=false")
    parser.add_argument("--against", action="append", default=[], metavar="KEY=VALUE",
                        help="also time d3stereo with this override (repeatable: one variant with all of them), "
                             "alternating with the shipped config and SGBM in the same process")
    parser.add_argument("--no-memory", action="store_true", help="skip the fresh-process memory runs")
    parser.add_argument("--markdown", action="store_true", help="print a markdown table")
    parser.add_argument("--json", dest="json_out", help="also write the rows to this JSON file")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        spec = json.loads(args.child)
        out = _child_time(spec) if spec["mode"] == "time" else _child_memory(spec)
        print(json.dumps(out))
        return 0

    rows = []
    for case in args.cases or DEFAULT_CASES:
        spec = case_spec(case, args.data, seed=args.seed, reps=args.reps, backend=args.backend,
                         sgbm_block=args.sgbm_block or None, overrides=args.overrides, against=args.against)
        if spec is None:
            continue
        row = _spawn(dict(spec, mode="time"))
        if row is None:
            continue
        row.update(case=case, config=spec["config"] or "defaults")
        for method in ("d3stereo", "sgbm"):
            mem = None if args.no_memory else _spawn(dict(spec, mode="memory", method=method))
            row[f"{method}_mb"] = mem["vmhwm_mb"] if mem else float("nan")
        rows.append(row)
        print(f"{case}: d3stereo {row['d3_s']:.3f} s, SGBM {row['sgbm_s']:.3f} s, "
              f"ratio {row['d3_s'] / row['sgbm_s']:.2f}; " +
              ", ".join(f"{k} {v:.3f}" for k, v in row["steps"].items()), file=sys.stderr, flush=True)
    if not rows:
        return 1
    print(f"{os.cpu_count()} CPUs, backend {args.backend}, {args.reps} alternating reps after a warm-up, "
          f"SGBM block {args.sgbm_block or 'from config'}" + (f", overrides {args.overrides}" if args.overrides else ""))
    if args.markdown:
        print("\n| case | pair | config | range | d3stereo s | SGBM s | ratio | peak MB d3stereo / SGBM | first call s |")
        print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        ratio = r["d3_s"] / r["sgbm_s"]
        mem = f"{r['d3stereo_mb']:.0f} / {r['sgbm_mb']:.0f}"
        if args.markdown:
            print(f"| {r['case']} | {r['pair']} ({r['size']}) | {r['config']} | {r['max_disparity']} | "
                  f"{r['d3_s']:.3f} | {r['sgbm_s']:.3f} | {ratio:.2f}x | {mem} | {r['cold_s']:.2f} |")
        else:
            print(f"{r['case']:<11} {r['d3_s']:7.3f} s  SGBM {r['sgbm_s']:6.3f} s  {ratio:5.2f}x  MB {mem}")
    print("\nper-rep ratios, each d3stereo call against the SGBM call after it (min / median / max):")
    for r in rows:
        paired = r["paired_ratios"]
        print(f"  {r['case']}: {paired[0]:.2f} / {statistics.median(paired):.2f} / {paired[-1]:.2f}")
    timed = [r for r in rows if r.get("against_s") is not None]
    if timed:
        print(f"\nagainst {args.against} (the same process, alternating):")
        for r in timed:
            print(f"  {r['case']}: {r['against_s']:.3f} s, {r['against_s'] / r['sgbm_s']:.2f}x SGBM's time; "
                  f"the shipped config's time {100 * (r['d3_s'] / r['against_s'] - 1):+.1f} % against it "
                  f"(md5 {r['against_md5'][:8]})")
    print("\nper-step medians (s):")
    for r in rows:
        print(f"  {r['case']}: " + ", ".join(f"{k} {v:.3f}" for k, v in r["steps"].items()))
    shares = [r for r in rows if r.get("sgm_share") is not None]
    if shares:
        print("\nsemi-global smoothing, share of d3stereo's time (median over the reps):")
        for r in shares:
            print(f"  {r['case']}: {100 * r['sgm_share']:.1f} %")
    print("\ndisparity md5 (equal before and after a bit-identical speed-up):")
    for r in rows:
        print(f"  {r['case']}: {r['disparity_md5']}")
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
