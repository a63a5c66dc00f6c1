"""Accuracy and speed of d3stereo beside OpenCV SGBM on the same pairs, in one process.

For every pair: EPE, PEP 0.5/1/2/3 and density of d3stereo and of SGBM (hole-filled,
same disparity range, block 5, 3-way: the ``sgbm`` section of the config), and the
ratio of their wall times.  Then means per dataset family and overall.

Usage::

    python scripts/benchmark.py ../shared/data                     # every pair with gt
    python scripts/benchmark.py ../shared/data --family middlebury  # families by prefix
    python scripts/benchmark.py ../shared/data --set diffusion.max_gap=0.1 --markdown

The first d3stereo call compiles (or loads cached) kernels; a warm-up call on a tiny
pair keeps that out of the timings.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict

import numpy as np

from d3cli import D3Stereo, load_config
from d3cli.baselines import sgbm_disparity
from d3cli.datasets import discover, load_ground_truth, load_pair_images, resolve_max_disparity
from d3cli.metrics import disparity_errors

KEYS = ("epe", "pep_0.5", "pep_1", "pep_2", "pep_3", "density")


def evaluate_pairs(pairs, cfg, *, with_sgbm=True, log=print):
    """Run d3stereo (and SGBM) on ``pairs``; return a list of per-pair result dicts."""
    matcher = D3Stereo(cfg)
    rng = np.random.default_rng(0)
    warm = (rng.random((48, 64)) * 255).astype(np.uint8)
    matcher.compute(warm, np.roll(warm, -2, axis=1), max_disparity=8)  # compile outside timings
    rows = []
    for pair in pairs:
        left, right = load_pair_images(pair)
        gt, mask = load_ground_truth(pair, left.shape[:2])
        if gt is None:
            continue
        dmax = resolve_max_disparity(pair, left.shape[1])
        t0 = time.perf_counter()
        ours = matcher.compute(left, right, max_disparity=dmax)
        t_ours = time.perf_counter() - t0
        row = {"pair": pair.name, "family": pair.family, "size": f"{left.shape[1]}x{left.shape[0]}", "dmax": dmax}
        row["d3"] = disparity_errors(ours.disparity, gt, mask=mask)
        row["d3"]["time"] = t_ours
        row["d3"]["decided"] = 100.0 * float(ours.valid.mean())
        if with_sgbm:
            t0 = time.perf_counter()
            base = sgbm_disparity(left, right, max_disparity=dmax, cfg=cfg.sgbm)
            t_sgbm = time.perf_counter() - t0
            row["sgbm"] = disparity_errors(base.disparity, gt, mask=mask)
            row["sgbm"]["time"] = t_sgbm
        rows.append(row)
        line = f"{pair.name:36s} {row['size']:>9s} d3 EPE {row['d3']['epe']:6.3f} PEP2 {row['d3']['pep_2']:6.2f} t {t_ours:6.2f}s"
        if with_sgbm:
            line += (
                f" | sgbm EPE {row['sgbm']['epe']:6.3f} PEP2 {row['sgbm']['pep_2']:6.2f} t {row['sgbm']['time']:6.3f}s"
                f" | time ratio {t_ours / max(row['sgbm']['time'], 1e-9):6.1f}x"
            )
        log(line)
    return rows


def family_means(rows, method):
    """Mean of every metric per family and overall for ``method`` ("d3" or "sgbm")."""
    groups = defaultdict(list)
    for row in rows:
        groups[row["family"]].append(row[method])
        groups["overall"].append(row[method])
    return {
        fam: {k: float(np.mean([r[k] for r in items])) for k in KEYS + ("time",)} | {"n": len(items)}
        for fam, items in groups.items()
    }


def markdown_table(rows) -> str:
    """Per-family table of both methods, d3stereo first."""
    ours, base = family_means(rows, "d3"), family_means(rows, "sgbm")
    lines = [
        "| family | pairs | method | EPE | PEP0.5 % | PEP1 % | PEP2 % | PEP3 % | density % | time s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for fam in sorted(ours, key=lambda f: (f == "overall", f)):
        for name, table in (("d3stereo", ours), ("SGBM", base)):
            m = table[fam]
            lines.append(
                f"| {fam} | {m['n']} | {name} | {m['epe']:.3f} | {m['pep_0.5']:.2f} | {m['pep_1']:.2f} | "
                f"{m['pep_2']:.2f} | {m['pep_3']:.2f} | {m['density']:.1f} | {m['time']:.3f} |"
            )
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="+", help="dataset folders, manifests or pair folders")
    parser.add_argument("-c", "--config", help="YAML config (default: built-in defaults)")
    parser.add_argument("--set", action="append", default=[], help="section.key=value override")
    parser.add_argument("--family", action="append", default=[], help="keep families starting with this")
    parser.add_argument("--markdown", action="store_true", help="print the per-family Markdown table")
    args = parser.parse_args(argv)
    cfg = load_config(args.config, args.set)
    pairs = discover(args.inputs)
    if args.family:
        pairs = [p for p in pairs if any(p.family.startswith(f) for f in args.family)]
    rows = evaluate_pairs(pairs, cfg)
    if not rows:
        print("no pairs with ground truth", file=sys.stderr)
        return 1
    ours, base = family_means(rows, "d3"), family_means(rows, "sgbm")
    print()
    for fam in sorted(ours, key=lambda f: (f == "overall", f)):
        o, b = ours[fam], base[fam]
        print(
            f"{fam:16s} n={o['n']:2d}  d3stereo EPE {o['epe']:.3f} PEP1 {o['pep_1']:.2f} PEP2 {o['pep_2']:.2f} "
            f"dens {o['density']:.1f} t {o['time']:.3f}s | SGBM EPE {b['epe']:.3f} PEP1 {b['pep_1']:.2f} "
            f"PEP2 {b['pep_2']:.2f} dens {b['density']:.1f} t {b['time']:.3f}s | time ratio {o['time'] / b['time']:.1f}x"
        )
    if args.markdown:
        print()
        print(markdown_table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
