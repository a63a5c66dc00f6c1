"""Parameter sweep used to choose the defaults in configs/ (docs/design.md: defaults are measured).

Each ``--grid section.key=v1,v2,...`` adds an axis; every combination is run with
d3stereo on the pairs with ground truth and ranked by mean EPE and mean PEP2.

Usage (the sweep behind configs/default.yaml)::

    python scripts/tune.py DATA --family middlebury \\
        --grid seeds.pkrn_min=1.2,1.5,2.0 --grid diffusion.max_gap=-1,0.02,0.05,0.1 \\
        --grid seeds.every_level=false,true

It ranks on the same pairs it tunes on; whether a chosen value holds on pairs it was not
tuned on is checked leave-one-out by ``scripts/loo.py`` (from ``d3stereo run --eval`` grid
folders, docs/results.md "Leave-one-out of the tuned parameters").
"""

from __future__ import annotations

import argparse
import itertools
import sys

from benchmark import evaluate_pairs, family_means

from d3cli import load_config
from d3cli.data.layouts import discover


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="+")
    parser.add_argument("--grid", action="append", default=[], help="section.key=v1,v2,...")
    parser.add_argument("--set", action="append", default=[], help="fixed section.key=value")
    parser.add_argument("--family", action="append", default=[])
    args = parser.parse_args(argv)
    axes = []
    for spec in args.grid:
        key, values = spec.split("=", 1)
        axes.append([f"{key}={v}" for v in values.split(",")])
    pairs = discover(args.inputs)
    if args.family:
        pairs = [p for p in pairs if any(p.family.startswith(f) for f in args.family)]
    results = []
    for combo in itertools.product(*axes) if axes else [()]:
        cfg = load_config(None, list(args.set) + list(combo))
        rows = evaluate_pairs(pairs, cfg, with_sgbm=False, log=lambda *_: None)
        m = family_means(rows, "d3")["overall"]
        results.append((m["epe"], m["pep_2"], m["time"], combo))
        print(f"EPE {m['epe']:.3f} PEP2 {m['pep_2']:.2f} t {m['time']:.2f}s  {' '.join(combo)}", flush=True)
    print("\nbest by EPE:")
    for epe, pep2, t, combo in sorted(results)[:5]:
        print(f"  EPE {epe:.3f} PEP2 {pep2:.2f} t {t:.2f}s  {' '.join(combo)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
