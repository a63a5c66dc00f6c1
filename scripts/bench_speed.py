"""Wall time and peak memory of d3stereo beside OpenCV SGBM on the same pair.

Every method runs in a fresh Python process, so its peak resident memory is its own:

* ``cold``: the first call in the process (kernels loaded from numba's cache, or compiled
  when there is none), measured from before ``D3Stereo(cfg)``;
* ``warm``: the median of ``--repeats`` further calls on the same pair;
* ``peak MB``: the process's peak resident set size minus its size just before the
  first call (``ru_maxrss`` after, ``/proc/self/statm`` before), i.e. what the method
  allocated at most;
* ``x SGBM``: warm time and peak memory divided by SGBM's from the same run.

Usage::

    python scripts/bench_speed.py                          # synthetic 1280x720 road pair
    python scripts/bench_speed.py --size 2560x1440 --max-disparity 256
    python scripts/bench_speed.py --pair ../shared/data/middlebury2014-teddy-Q
    python scripts/bench_speed.py --methods sgbm d3stereo d3stereo+pt --backend cuda
    python scripts/bench_speed.py -c configs/road.yaml --methods sgbm pt-sgm d3stereo d3stereo+pt

Method names: ``sgbm``, ``pt-sgm``, ``d3stereo``, ``d3stereo+pt`` (``pt.enabled=true``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

METHODS = ("sgbm", "pt-sgm", "d3stereo", "d3stereo+pt")


def _rss_mb() -> float:
    """Current resident set size of this process, MB."""
    with open("/proc/self/statm") as fh:
        pages = int(fh.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def _load_pair(spec: dict):
    import numpy as np

    if spec["pair"]:
        from d3cli.data.datasets import discover, load_pair_images, resolve_max_disparity

        pair = discover([spec["pair"]])[0]
        left, right = load_pair_images(pair)
        dmax = spec["max_disparity"] or resolve_max_disparity(pair, left.shape[1])
        return left, right, dmax, pair.name
    cache = Path(spec["cache"])
    if not (cache / "left.npy").exists():
        from d3cli.data.synth import render_pair

        width, height = spec["size"]
        synth = render_pair(seed=spec["seed"], width=width, height=height)
        cache.mkdir(parents=True, exist_ok=True)
        np.save(cache / "left.npy", synth.left)
        np.save(cache / "right.npy", synth.right)
        np.save(cache / "dmax.npy", np.array(int(np.ceil(np.nanmax(np.where(np.isfinite(synth.disparity), synth.disparity, 0))))))
    left = np.load(cache / "left.npy")
    right = np.load(cache / "right.npy")
    dmax = spec["max_disparity"] or int(np.load(cache / "dmax.npy")) + 8
    return left, right, dmax, f"synth-road-{left.shape[1]}x{left.shape[0]}"


def _child(spec: dict) -> dict:
    """Time and measure one method in this (fresh) process."""
    from d3cli import load_config
    from d3cli.batch import compute_pair

    left, right, dmax, name = _load_pair(spec)
    method = spec["method"]
    overrides = [f"run.backend={spec['backend']}"]
    if method == "d3stereo+pt":
        overrides.append("pt.enabled=true")
    cfg = load_config(spec["config"], overrides)
    base_method = "d3stereo" if method.startswith("d3stereo") else method
    rss0 = _rss_mb()
    t0 = time.perf_counter()
    result = compute_pair(base_method, cfg, left, right, max_disparity=dmax)
    cold = time.perf_counter() - t0
    warm = []
    for _ in range(spec["repeats"]):
        t0 = time.perf_counter()
        compute_pair(base_method, cfg, left, right, max_disparity=dmax)
        warm.append(time.perf_counter() - t0)
    warm.sort()
    return {
        "pair": name,
        "size": f"{left.shape[1]}x{left.shape[0]}",
        "max_disparity": dmax,
        "method": method,
        "backend": result.info.get("backend", "opencv"),
        "cold_s": cold,
        "warm_s": warm[len(warm) // 2] if warm else cold,
        "peak_mb": max(0.0, _peak_rss_mb() - rss0),
        "steps": {k: round(v, 4) for k, v in result.timings.items()},
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--pair", help="a pair folder (any layout d3stereo reads); default: a synthetic road pair")
    parser.add_argument("--size", default="1280x720", help="WxH of the synthetic pair (default 1280x720)")
    parser.add_argument("--seed", type=int, default=3, help="seed of the synthetic pair")
    parser.add_argument("--max-disparity", type=int, default=None)
    parser.add_argument("--methods", nargs="+", default=["sgbm", "d3stereo", "d3stereo+pt"], choices=METHODS)
    parser.add_argument("-c", "--config", default=None, help="YAML config for every method (e.g. configs/road.yaml)")
    parser.add_argument("--backend", default="cpu", choices=("cpu", "cuda", "auto"))
    parser.add_argument("--repeats", type=int, default=3, help="warm calls per method (median reported)")
    parser.add_argument("--json", dest="json_out", help="also write the rows to this JSON file")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_child(json.loads(args.child))))
        return 0

    width, height = (int(x) for x in args.size.lower().split("x"))
    cache = Path(tempfile.gettempdir()) / f"d3stereo-bench-{width}x{height}-{args.seed}"
    rows = []
    for method in args.methods:
        spec = {
            "pair": args.pair, "size": [width, height], "seed": args.seed, "cache": str(cache),
            "max_disparity": args.max_disparity, "method": method, "backend": args.backend, "repeats": args.repeats,
            "config": args.config,
        }
        proc = subprocess.run(
            [sys.executable, __file__, "--child", json.dumps(spec)], capture_output=True, text=True, check=False
        )
        if proc.returncode != 0:
            print(f"{method}: failed\n{proc.stderr[-2000:]}", file=sys.stderr)
            continue
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    if not rows:
        return 1
    ref = next((r for r in rows if r["method"] == "sgbm"), None)
    print(f"pair {rows[0]['pair']} ({rows[0]['size']}, max disparity {rows[0]['max_disparity']}), "
          f"{os.cpu_count()} CPUs, backend {args.backend}, config {args.config or 'defaults'}")
    print(f"{'method':<13} {'backend':>8} {'cold s':>8} {'warm s':>8} {'x SGBM':>7} {'peak MB':>8} {'x SGBM':>7}")
    for r in rows:
        t_ratio = r["warm_s"] / ref["warm_s"] if ref else float("nan")
        m_ratio = r["peak_mb"] / ref["peak_mb"] if ref and ref["peak_mb"] > 0 else float("nan")
        print(f"{r['method']:<13} {r['backend']:>8} {r['cold_s']:8.3f} {r['warm_s']:8.3f} {t_ratio:7.1f} "
              f"{r['peak_mb']:8.0f} {m_ratio:7.1f}")
    for r in rows:
        if r["steps"]:
            print(f"  {r['method']}: " + ", ".join(f"{k} {v:.3f}" for k, v in r["steps"].items()))
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
