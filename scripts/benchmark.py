"""Accuracy and speed of d3stereo and the baselines on the same pairs, in one process.

For every pair and every method variant: EPE, PEP 0.5/1/2/3, density and wall time
(pairs with ground truth), or with ``--photometric`` the photometric scores (MSE, PSNR,
SSIM, coverage) of pairs without ground truth.  Then means per dataset family and
overall, the variants side by side.

Method variants (``--methods``, comma-separated, in the order printed):

- ``d3``: d3stereo with the configuration exactly as given (``-c``/``--set``),
- ``d3stereo``: d3stereo with the perspective transformation off (``pt.enabled=false``),
- ``d3stereo+pt``: PT-D3Stereo (``pt.enabled=true``),
- ``sgbm``: OpenCV SGBM (the ``sgbm`` section: block 5, 3-way, hole-filled),
- ``pt-sgm``: SGBM after the same perspective transformation (``pt`` section),
- ``elas``, ``pandora-sgm``: the optional peers (extra ``peers``; ``peers`` section:
  holes filled row-wise like SGBM's unless ``--set peers.fill=false``).

Usage::

    python scripts/benchmark.py DATA                      # d3 and sgbm, pairs with gt
    python scripts/benchmark.py DATA --family middlebury   # families by prefix
    python scripts/benchmark.py /tmp/synth12 -c road \\
        --methods d3stereo+pt,d3stereo,sgbm,pt-sgm --markdown          # the road table
    python scripts/benchmark.py DATA --family road --photometric \\
        -c road --methods d3stereo+pt,d3stereo,sgbm,pt-sgm
    python scripts/benchmark.py DATA --methods d3,sgbm,elas,pandora-sgm --markdown  # peers
    python scripts/benchmark.py DATA --family kitti -c kitti \\
        --methods d3,sgbm,elas,pandora-sgm --markdown --per-pair                # + per pair

With ``--markdown`` (ground truth) the per-family table is followed by the per-pair win
count: for EPE, PEP0.5, PEP1 and PEP2, on how many pairs the first d3stereo variant has a
lower value than each other variant and than the best of them on that pair (ties are no
win).  ``--per-pair`` adds one table per metric and time, a row per pair.

The first d3stereo call compiles (or loads cached) kernels; a warm-up call on a tiny
pair keeps that out of the timings.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from dataclasses import replace

import numpy as np

from d3cli import D3Stereo, load_config
from d3cli.baselines import elas_disparity, pandora_sgm_disparity, pt_sgm_disparity, sgbm_disparity
from d3cli.config import method_spec
from d3cli.data.layouts import discover, load_ground_truth, load_pair_images, resolve_max_disparity
from d3cli.data.formats import to_grey
from d3cli.evaluation.metrics import disparity_errors, photometric_scores

KEYS = ("epe", "pep_0.5", "pep_1", "pep_2", "pep_3", "density")
PHOTO_KEYS = ("mse", "psnr", "ssim", "coverage")
VARIANTS = ("d3", "d3stereo", "d3stereo+pt", "sgbm", "pt-sgm", "elas", "pandora-sgm")
D3_VARIANTS = ("d3", "d3stereo", "d3stereo+pt")
#: Metrics of the per-pair win count and the per-pair tables (lower is better).
WIN_KEYS = ("epe", "pep_0.5", "pep_1", "pep_2")
#: Column name of the best peer on each pair in :func:`win_counts`.
BEST = "best peer"
KEY_LABELS = {"epe": "EPE", "pep_0.5": "PEP0.5 %", "pep_1": "PEP1 %", "pep_2": "PEP2 %", "time": "time s"}
LABELS = {"d3": "d3stereo", "d3stereo": "d3stereo (PT off)", "d3stereo+pt": "d3stereo (PT on)",
          "sgbm": "SGBM", "pt-sgm": "PT-SGM", "elas": "ELAS", "pandora-sgm": "pandora census+SGM"}


def make_runners(cfg, methods):
    """``{variant: compute(left, right, dmax) -> DisparityResult}`` for ``methods``."""
    runners = {}
    for name in methods:
        if name not in VARIANTS:
            raise SystemExit(f"--methods: unknown variant {name!r}; use {', '.join(VARIANTS)}")
        if name in ("d3", "d3stereo", "d3stereo+pt"):
            vcfg = cfg if name == "d3" else replace(cfg, pt=replace(cfg.pt, enabled=name == "d3stereo+pt"))
            matcher = D3Stereo(vcfg)
            rng = np.random.default_rng(0)
            warm = (rng.random((48, 64)) * 255).astype(np.uint8)
            matcher.compute(warm, np.roll(warm, -2, axis=1), max_disparity=8)  # compile outside timings
            runners[name] = lambda left, right, dmax, m=matcher: m.compute(left, right, max_disparity=dmax)
        elif name == "sgbm":
            runners[name] = lambda left, right, dmax: sgbm_disparity(left, right, max_disparity=dmax, cfg=cfg.sgbm)
        elif name in ("elas", "pandora-sgm"):
            method_spec(name).require()
            peer = elas_disparity if name == "elas" else pandora_sgm_disparity
            runners[name] = lambda left, right, dmax, run=peer: run(left, right, max_disparity=dmax, cfg=cfg.peers)
        else:
            runners[name] = lambda left, right, dmax: pt_sgm_disparity(left, right, max_disparity=dmax, cfg=cfg)
    return runners


def evaluate_pairs(pairs, cfg, *, with_sgbm=True, methods=None, photometric=False, log=print):
    """Run the method variants on ``pairs``; return a list of per-pair result dicts.

    Each row holds ``pair``, ``family``, ``size``, ``dmax`` and, per variant, a dict of
    metrics plus ``time`` (seconds) and ``pt`` (the fitted road model, when any).
    ``methods`` defaults to ``("d3", "sgbm")`` (``("d3",)`` without ``with_sgbm``).
    Pairs without ground truth are skipped unless ``photometric``; with it, they are
    scored by :func:`d3cli.evaluation.metrics.photometric_scores` instead (and pairs with ground
    truth are skipped).
    """
    if methods is None:
        methods = ("d3", "sgbm") if with_sgbm else ("d3",)
    runners = make_runners(cfg, methods)
    rows = []
    for pair in pairs:
        left, right = load_pair_images(pair)
        gt, mask = load_ground_truth(pair, left.shape[:2])
        if (gt is None) != bool(photometric):
            continue
        dmax = resolve_max_disparity(pair, left.shape[1])
        row = {"pair": pair.name, "family": pair.family, "size": f"{left.shape[1]}x{left.shape[0]}", "dmax": dmax}
        parts = []
        for name, run in runners.items():
            t0 = time.perf_counter()
            result = run(left, right, dmax)
            elapsed = time.perf_counter() - t0
            if photometric:
                scores = photometric_scores(to_grey(left), to_grey(right), result.disparity)
                parts.append(f"{name} PSNR {scores['psnr']:6.2f} SSIM {scores['ssim']:.3f} t {elapsed:6.2f}s")
            else:
                scores = disparity_errors(result.disparity, gt, mask=mask)
                parts.append(f"{name} EPE {scores['epe']:6.3f} PEP1 {scores['pep_1']:6.2f} t {elapsed:6.2f}s")
            scores["time"] = elapsed
            scores["decided"] = 100.0 * float(result.valid.mean())
            if "pt" in result.info:
                scores["pt"] = result.info["pt"]
            row[name] = scores
        rows.append(row)
        log(f"{pair.name:36s} {row['size']:>9s} | " + " | ".join(parts))
    return rows


def family_means(rows, method, keys=KEYS):
    """Mean of every metric per family and overall for ``method`` (a variant name)."""
    groups = defaultdict(list)
    for row in rows:
        groups[row["family"]].append(row[method])
        groups["overall"].append(row[method])
    return {
        fam: {k: float(np.mean([r[k] for r in items])) for k in keys + ("time",)} | {"n": len(items)}
        for fam, items in groups.items()
    }


def _methods_of(rows):
    return [k for k in rows[0] if k in VARIANTS]


def _family_rows(rows, keys):
    """(family, method name, means) in table order: families sorted, overall last."""
    tables = {name: family_means(rows, name, keys) for name in _methods_of(rows)}
    first = next(iter(tables.values()))
    for fam in sorted(first, key=lambda f: (f == "overall", f)):
        for name, table in tables.items():
            yield fam, name, table[fam]


def markdown_table(rows, *, photometric=False) -> str:
    """Per-family table of every variant, in the order run."""
    keys = PHOTO_KEYS if photometric else KEYS
    if photometric:
        head = "| family | pairs | method | MSE | PSNR dB | SSIM | coverage % | time s |"
    else:
        head = "| family | pairs | method | EPE | PEP0.5 % | PEP1 % | PEP2 % | PEP3 % | density % | time s |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for fam, name, m in _family_rows(rows, keys):
        if photometric:
            cells = f"{m['mse']:.1f} | {m['psnr']:.2f} | {m['ssim']:.3f} | {m['coverage']:.1f}"
        else:
            cells = (f"{m['epe']:.3f} | {m['pep_0.5']:.2f} | {m['pep_1']:.2f} | {m['pep_2']:.2f} | "
                     f"{m['pep_3']:.2f} | {m['density']:.1f}")
        lines.append(f"| {fam} | {m['n']} | {LABELS[name]} | {cells} | {m['time']:.3f} |")
    return "\n".join(lines)


def _reference_and_peers(rows):
    """The first d3stereo variant run and the other variants, in the order run."""
    names = _methods_of(rows)
    ref = next((n for n in names if n in D3_VARIANTS), None)
    return ref, [n for n in names if n != ref]


def win_counts(rows, keys=WIN_KEYS):
    """On how many pairs the first d3stereo variant beats each other variant, per metric.

    Parameters
    ----------
    rows : list of dict
        Per-pair results as :func:`evaluate_pairs` returns them (ground-truth metrics).
    keys : sequence of str
        Metrics compared; lower is better for each.

    Returns
    -------
    dict
        ``{family: {"n": pairs, "wins": {against: {key: count}}}}`` per family and
        ``"overall"``, where ``against`` is each other variant and ``"best peer"``: the
        lowest value of all other variants on that pair (a win there beats every peer).
        A tie is no win.  Empty when no d3stereo variant or no other variant was run.
    """
    ref, peers = _reference_and_peers(rows)
    if ref is None or not peers:
        return {}
    out = {}
    for row in rows:
        for fam in (row["family"], "overall"):
            entry = out.setdefault(fam, {"n": 0, "wins": {a: dict.fromkeys(keys, 0) for a in peers + [BEST]}})
            entry["n"] += 1
            for key in keys:
                mine = row[ref][key]
                others = {a: row[a][key] for a in peers}
                others[BEST] = min(others.values())
                for against, value in others.items():
                    entry["wins"][against][key] += int(mine < value)
    return out


def markdown_wins(rows, keys=WIN_KEYS) -> str:
    """Per-pair win counts of :func:`win_counts` as a Markdown table ("wins / pairs")."""
    counts = win_counts(rows, keys)
    if not counts:
        return ""
    ref, peers = _reference_and_peers(rows)
    head = f"| family | pairs | {LABELS[ref]} better than | " + " | ".join(KEY_LABELS[k] for k in keys) + " |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for fam in sorted(counts, key=lambda f: (f == "overall", f)):
        entry = counts[fam]
        for i, against in enumerate(peers + [BEST]):
            label = "the best peer on the pair" if against == BEST else LABELS[against]
            cells = " | ".join(f"{entry['wins'][against][k]} / {entry['n']}" for k in keys)
            first = f"| {fam} | {entry['n']} |" if i == 0 else "| | |"
            lines.append(f"{first} {label} | {cells} |")
    return "\n".join(lines)


def markdown_per_pair(rows, keys=WIN_KEYS + ("time",)) -> str:
    """One Markdown table per metric: a row per pair, a column per variant, the best in bold."""
    names = _methods_of(rows)
    tables = []
    for key in keys:
        head = f"| {KEY_LABELS[key]} | pair | " + " | ".join(LABELS[n] for n in names) + " |"
        lines = [head, "|" + "---|" * (head.count("|") - 1)]
        for row in sorted(rows, key=lambda r: (r["family"], r["pair"])):
            values = [row[n][key] for n in names]
            digits = 3 if key in ("epe", "time") else 2
            cells = [f"**{v:.{digits}f}**" if v == min(values) else f"{v:.{digits}f}" for v in values]
            lines.append(f"| {row['family']} | {row['pair']} | " + " | ".join(cells) + " |")
        tables.append("\n".join(lines))
    return "\n\n".join(tables)


def print_summary(rows, *, photometric=False) -> None:
    """One line per family and variant."""
    for fam, name, m in _family_rows(rows, PHOTO_KEYS if photometric else KEYS):
        if photometric:
            text = f"MSE {m['mse']:7.1f} PSNR {m['psnr']:6.2f} SSIM {m['ssim']:.3f} cov {m['coverage']:5.1f}"
        else:
            text = (f"EPE {m['epe']:.3f} PEP0.5 {m['pep_0.5']:6.2f} PEP1 {m['pep_1']:5.2f} "
                    f"PEP2 {m['pep_2']:5.2f} dens {m['density']:5.1f}")
        print(f"{fam:16s} n={m['n']:2d} {LABELS[name]:18s} {text} t {m['time']:6.2f}s")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="+", help="dataset folders, manifests or pair folders")
    parser.add_argument("-c", "--config", help="YAML config (default: built-in defaults)")
    parser.add_argument("--set", action="append", default=[], help="section.key=value override")
    parser.add_argument("--family", action="append", default=[], help="keep families starting with this")
    parser.add_argument("--methods", default="d3,sgbm", help=f"comma-separated variants of {', '.join(VARIANTS)}")
    parser.add_argument("--photometric", action="store_true",
                        help="score the pairs WITHOUT ground truth photometrically (MSE, PSNR, SSIM)")
    parser.add_argument("--markdown", action="store_true",
                        help="print the per-family Markdown table and the per-pair win counts")
    parser.add_argument("--per-pair", action="store_true",
                        help="also print per-pair Markdown tables (one per metric, the best in bold)")
    args = parser.parse_args(argv)
    cfg = load_config(args.config, args.set)
    pairs = discover(args.inputs)
    if args.family:
        pairs = [p for p in pairs if any(p.family.startswith(f) for f in args.family)]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    rows = evaluate_pairs(pairs, cfg, methods=methods, photometric=args.photometric)
    if not rows:
        print("no pairs " + ("without" if args.photometric else "with") + " ground truth", file=sys.stderr)
        return 1
    print()
    print_summary(rows, photometric=args.photometric)
    if args.markdown:
        print()
        print(markdown_table(rows, photometric=args.photometric))
        wins = "" if args.photometric else markdown_wins(rows)
        if wins:
            print()
            print(wins)
    if args.per_pair and not args.photometric:
        print()
        print(markdown_per_pair(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
