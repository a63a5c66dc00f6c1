"""The paper's ablation (Table I) on our pairs: PT, PRC, RBF, ARS switched on and off.

Prints a Markdown table: one row per switch combination, in the paper's order (Table
I(a): PT, PRC, RBF, ARS, 9 rows, on road pairs; Table I(b): PRC, RBF, ARS, 8 rows), then
the additions of this implementation, each turned on alone on top of the full method,
and all of them (= the bundled default.yaml's choices).  Columns: PEP 0.5 / 1 / 2 %, EPE,
mean seconds per pair, and the paper's figures for the same row.

What a switch means (README "Reproducing the paper"):

- PT  ``pt.enabled``: perspective transformation (road scenes);
- PRC ``inheritance.prc``: patch reliability + local-minimum constraints; off: DFM's PKRN
  test in the patch (``inheritance.dfm_pkrn_min``);
- RBF ``aggregation.rbf``: t_max passes of the 3x3 kernel; off: one plain bilateral pass
  of radius kappa_a (= t_max) with sigma_1 scaled with the radius (same receptive field);
- ARS ``pyramid.ars``: alternating inheritance / diffusion; off: DFM's linear structure
  (seeds at the coarsest level only, diffusion at the finest level only).

Usage::

    python scripts/ablation.py DATA --family middlebury --table b   # Table I(b)
    d3stereo synth /tmp/road6 --n 6 --seed 0 --width 640 --height 360
    python scripts/ablation.py /tmp/road6 --table a --set cost.window=25      # Table I(a)

``-c`` (default the bundled config ``paper``, the method as published) may be given more than once:
later files override earlier ones.  ``--every N`` keeps every N-th pair (sorted by name),
a deterministic subset for slow machines.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from benchmark import evaluate_pairs, family_means

from d3cli import load_config
from d3cli.config import read_yaml_lines, resolve_config
from d3cli.data.layouts import discover
from d3cli.errors import D3Error

PAPER_CONFIG = "paper"  # the bundled configs/paper.yaml

SWITCHES = {"PT": "pt.enabled", "PRC": "inheritance.prc", "RBF": "aggregation.rbf", "ARS": "pyramid.ars"}

#: Table I(a), UDTIRI-Stereo: (PT, PRC, RBF, ARS) -> (PEP0.5 %, PEP1 %, EPE px, runtime s)
PAPER_A = {
    (0, 0, 0, 0): (10.5, 3.57, 0.48, 0.79),
    (1, 0, 0, 0): (9.15, 3.27, 0.38, 0.62),
    (1, 1, 0, 0): (9.13, 3.22, 0.37, 0.64),
    (1, 0, 1, 0): (9.22, 2.51, 0.29, 0.91),
    (1, 0, 0, 1): (9.60, 3.64, 0.44, 0.59),
    (1, 1, 1, 0): (4.54, 2.23, 0.28, 0.94),
    (1, 0, 1, 1): (3.64, 1.37, 0.26, 0.90),
    (1, 1, 0, 1): (8.31, 2.75, 0.35, 0.61),
    (1, 1, 1, 1): (3.53, 1.20, 0.21, 0.84),
}
#: Table I(b), Middlebury: (PRC, RBF, ARS) -> (PEP1 %, PEP2 %, EPE px, runtime s)
PAPER_B = {
    (0, 0, 0): (34.3, 24.0, 4.07, 1.11),
    (1, 0, 0): (34.2, 23.8, 3.75, 1.03),
    (0, 1, 0): (25.2, 17.6, 3.41, 1.89),
    (0, 0, 1): (34.4, 23.8, 4.17, 0.94),
    (1, 1, 0): (25.2, 17.4, 3.15, 1.90),
    (0, 1, 1): (25.4, 17.8, 3.46, 1.77),
    (1, 0, 1): (33.1, 22.8, 3.39, 0.96),
    (1, 1, 1): (24.9, 17.1, 2.97, 1.58),
}
TABLES = {"a": (("PT", "PRC", "RBF", "ARS"), PAPER_A, ("pep_0.5", "pep_1")),
          "b": (("PRC", "RBF", "ARS"), PAPER_B, ("pep_1", "pep_2"))}

#: The additions of this implementation, each a config change on top of the full method.
ADDITIONS = (
    ("+ occlusion check", ["refine.occlusion_check=true"]),
    ("+ max_gap 0", ["diffusion.max_gap=0"]),
    ("+ seeds.every_level", ["seeds.every_level=true"]),
    ("+ band search", ["pyramid.band=true"]),
    ("+ symmetric candidates", ["inheritance.candidates=symmetric"]),
    # with the sub-pixel fit that follows it (auto: two lines of equal slope after the smoothing)
    ("+ semi-global smoothing", ["aggregation.sgm_p1=0.1", "aggregation.sgm_p2=1.2", "refine.subpixel_fit=auto"]),
    # the smoothing in place of the RBF passes at full resolution (the coarser levels keep them)
    ("+ no RBF at full resolution", ["aggregation.finest_t_max=0"]),
    ("+ finishing smoothing", ["refine.smooth_radius=3", "refine.smooth_sigma=2.0", "refine.smooth_kernel=box"]),
)
ALL_ADDITIONS = [s for _, sets in ADDITIONS for s in sets]


def file_overrides(path) -> list[str]:
    """A YAML config file as ``section.key=value`` overrides (to stack several files)."""
    data, _ = read_yaml_lines(resolve_config(path)[0])
    return [f"{section}.{key}={json.dumps(value)}" for section, keys in (data or {}).items()
            for key, value in (keys or {}).items()]


def switch_overrides(names, flags) -> list[str]:
    return [f"{SWITCHES[n]}={'true' if on else 'false'}" for n, on in zip(names, flags)]


def rows_of(table: str):
    """(label, switch flags or None, overrides, paper figures or None) in print order."""
    names, paper, _ = TABLES[table]
    full = (1,) * len(names)
    for flags, figures in paper.items():
        yield "", flags, switch_overrides(names, flags), figures
    for label, sets in ADDITIONS + (("+ all additions (defaults)", ALL_ADDITIONS),):
        yield label, full, switch_overrides(names, full) + sets, None


def measure(pairs, base: list[str], config: str, overrides: list[str], log):
    """Overall means (metrics and seconds per pair) of d3stereo with these overrides."""
    cfg = load_config(config, base + overrides)
    rows = evaluate_pairs(pairs, cfg, methods=("d3",), log=log)
    return family_means(rows, "d3")["overall"]


def markdown(table: str, results) -> str:
    """The Markdown table: switches, measured PEPs/EPE/time, the paper's figures."""
    names, _, paper_peps = TABLES[table]
    paper_head = " | ".join(f"paper PEP{k.split('_')[1]}" for k in paper_peps)
    head = ("| " + " | ".join(names) + " | PEP0.5 % | PEP1 % | PEP2 % | EPE px | time s/pair | "
            + paper_head + " | paper EPE | paper time s |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for label, flags, _, figures, m in results:
        marks = " | ".join("x" if on else "" for on in flags)
        if label:
            marks = label + " |" * (len(names) - 1)
        paper_cells = " | ".join(f"{f:g}" for f in figures) if figures else " | ".join("" for _ in range(4))
        lines.append(f"| {marks} | {m['pep_0.5']:.2f} | {m['pep_1']:.2f} | {m['pep_2']:.2f} | {m['epe']:.3f} | "
                     f"{m['time']:.2f} | {paper_cells} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="+", help="dataset folders, manifests or pair folders")
    parser.add_argument("--table", choices=("a", "b"), default="b", help="a: PT, PRC, RBF, ARS; b: PRC, RBF, ARS")
    parser.add_argument("-c", "--config", action="append", default=[],
                        help="YAML config or bundled name (default paper); repeat to stack files")
    parser.add_argument("--set", action="append", default=[], help="section.key=value applied to every row")
    parser.add_argument("--family", action="append", default=[], help="keep families starting with this")
    parser.add_argument("--every", type=int, default=1, help="keep every N-th pair (sorted by name)")
    parser.add_argument("--no-additions", action="store_true", help="only the switch combinations")
    parser.add_argument("-v", "--verbose", action="store_true", help="one line per pair")
    args = parser.parse_args(argv)
    configs = args.config or [str(PAPER_CONFIG)]
    base = [s for path in configs[1:] for s in file_overrides(path)] + args.set
    try:
        load_config(configs[0], base)  # a bad file or value stops here, before any pair runs
    except D3Error as exc:
        print(f"Error: {exc}", file=sys.stderr)
        return 2
    pairs = discover(args.inputs)
    if args.family:
        pairs = [p for p in pairs if any(p.family.startswith(f) for f in args.family)]
    pairs = sorted(pairs, key=lambda p: p.name)[:: max(1, args.every)]
    if not pairs:
        print("Error: no pairs found; give dataset folders with ground truth", file=sys.stderr)
        return 1
    log = print if args.verbose else (lambda *_: None)
    print(f"{len(pairs)} pairs: {', '.join(p.name for p in pairs)}", file=sys.stderr)
    results = []
    for label, flags, overrides, figures in rows_of(args.table):
        if args.no_additions and label:
            continue
        t0 = time.perf_counter()
        m = measure(pairs, base, configs[0], overrides, log)
        results.append((label, flags, overrides, figures, m))
        print(f"{label or ' '.join(map(str, flags)):28s} EPE {m['epe']:.3f} PEP1 {m['pep_1']:5.2f} "
              f"PEP2 {m['pep_2']:5.2f} t {m['time']:.2f}s/pair ({time.perf_counter() - t0:.0f}s)",
              file=sys.stderr, flush=True)
    print(markdown(args.table, results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
