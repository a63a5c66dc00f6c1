"""Leave-one-out check of tuned parameters, from grid runs of ``d3stereo run --eval``.

A grid is a set of output folders of ``d3stereo run``, all on the same pairs: the shipped
config's own run and, per value of a parameter, one run with that value changed::

    d3stereo run PAIRS [-c CONFIG] -o GRID/shipped --eval -q
    d3stereo run PAIRS [-c CONFIG] -o GRID/KEY=VALUE --eval -q --set KEY=VALUE

Each folder's ``run.json`` holds the full config of its run and ``metrics.csv`` the metrics
of each pair, so nothing is recomputed here.  A run whose config differs from the shipped
run's in one key is a grid point of that key; ``--axis KEY1,KEY2`` makes keys that were
varied together (penalties P1 and P2) one parameter.  Other runs are refused.

For every parameter and every pair, in turn: the value with the lowest mean criterion
(``--criterion``, default PEP1) over the OTHER pairs of the pair's family (the letters of
the family before its year: ``middlebury2006`` -> ``middlebury``) is chosen and its
result on the left-out pair kept.  Printed as Markdown, per family: the means of the
left-out results beside the shipped config's means, and how often each value was chosen
(a tie goes to the shipped value); then the family means of every grid point with the
mean wall time per pair of its run (taken as the runs were: compare on a quiet machine).

Usage::

    python scripts/loo.py GRID/mb/*                        # the shipped run is GRID/mb/shipped
    python scripts/loo.py GRID/kt/* --shipped GRID/kt/shipped --criterion epe
    python scripts/loo.py GRID/* --axis aggregation.sgm_p1,aggregation.sgm_p2 --family kitti
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import sys
from pathlib import Path

METRICS = ("epe", "pep_0.5", "pep_1", "pep_2")
HEAD = "EPE / PEP0.5 / PEP1 / PEP2"


def family_group(family: str) -> str:
    """``middlebury2006`` -> ``middlebury``: the letters of a family name before its year."""
    return re.sub(r"[\d_-].*$", "", family) or family


def _flatten(config: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in config.items():
        if isinstance(value, dict):
            flat |= _flatten(value, f"{prefix}{key}.")
        else:
            flat[f"{prefix}{key}"] = json.dumps(value)  # lists and null compare and print as in JSON
    return flat


def read_run(folder) -> dict:
    """Config (``section.key`` -> JSON text) and metrics of one ``d3stereo run --eval`` folder.

    Parameters
    ----------
    folder : str or Path
        Output folder holding ``run.json`` and ``metrics.csv``.

    Returns
    -------
    dict
        ``{"name", "config", "pairs": {pair: {metric: float}}, "family": {pair: group}}``, the
        metrics with ``time`` (the run's wall seconds of the pair, NaN where not recorded);
        pairs whose status is not ``ok`` and pairs without ground truth are left out.
    """
    folder = Path(folder)
    try:
        config = json.loads((folder / "run.json").read_text(encoding="utf-8"))["config"]
        with open(folder / "metrics.csv", newline="", encoding="utf-8") as fh:
            # pairs without ground truth have empty metric cells: nothing to choose on
            rows = [r for r in csv.DictReader(fh) if r.get("status") == "ok" and r.get("epe")]
        pairs = {r["pair"]: {k: float(r[k]) for k in METRICS} | {"time": float(r.get("time_s") or "nan")}
                 for r in rows}
    except (OSError, KeyError, ValueError) as exc:
        raise SystemExit(f"Error: {folder}: not a finished 'd3stereo run --eval' folder ({exc}); "
                         "run the grid point again") from None
    return {"name": folder.name, "config": _flatten(config), "pairs": pairs,
            "family": {r["pair"]: family_group(r["family"]) for r in rows}}


def _value_order(text: str):
    value = json.loads(text)
    return (0, float(value), "") if isinstance(value, (int, float)) else (1, 0.0, text)


def build_axes(shipped: dict, runs: list, axes=()) -> dict:
    """Grid points per parameter: ``{label: [(value text, run), ...]}``, shipped value first.

    Parameters
    ----------
    shipped : dict
        :func:`read_run` of the shipped config's run.
    runs : list of dict
        :func:`read_run` of the grid runs (the shipped run among them is skipped).
    axes : sequence of tuple of str
        Keys varied together, each tuple one parameter; every other key is its own.

    Raises
    ------
    SystemExit
        When a run differs from the shipped config in keys of more than one parameter.
    """
    points = {}
    for run in runs:
        diff = sorted(k for k in run["config"] if run["config"][k] != shipped["config"].get(k))
        if not diff:
            continue
        group = next((tuple(a) for a in axes if set(diff) <= set(a)), tuple(diff))
        if len(group) > 1 and group not in [tuple(a) for a in axes]:
            raise SystemExit(f"Error: {run['name']}: differs from the shipped run in {', '.join(diff)}; "
                             "change one key per run, or name keys varied together with --axis")
        value = " / ".join(run["config"][k] for k in group)
        points.setdefault(group, []).append((value, run))
    axes_out = {}
    for group, items in points.items():
        label = " / ".join(group)
        shipped_value = " / ".join(shipped["config"][k] for k in group)
        items = sorted(items, key=lambda item: [_value_order(v) for v in item[0].split(" / ")])
        axes_out[label] = [(shipped_value, shipped)] + items
    return axes_out


def _mean(values) -> float:
    values = list(values)
    return sum(values) / len(values)


def leave_one_out(points, pairs, criterion="pep_1") -> dict:
    """Choose a value per left-out pair on the others; the left-out pairs' results.

    Parameters
    ----------
    points : list of (str, dict)
        Grid points of one parameter, the shipped value first (:func:`build_axes`).
    pairs : list of str
        The pairs of one family; every point must have all of them.
    criterion : str
        Metric whose mean over the other pairs chooses the value (lower is better).

    Returns
    -------
    dict
        ``{"means": {metric: mean over the left-out results}, "chosen": {pair: value}}``.
        A tie goes to the earlier point, so the shipped value wins ties.
    """
    chosen, results = {}, []
    for left_out in pairs:
        others = [p for p in pairs if p != left_out]
        best = min(range(len(points)),
                   key=lambda i: (_mean(points[i][1]["pairs"][p][criterion] for p in others), i))
        chosen[left_out] = points[best][0]
        results.append(points[best][1]["pairs"][left_out])
    return {"means": {k: _mean(r[k] for r in results) for k in METRICS}, "chosen": chosen}


def _cells(means) -> str:
    return f"{means['epe']:.3f} / {means['pep_0.5']:.2f} / {means['pep_1']:.2f} / {means['pep_2']:.2f}"


def family_tables(shipped, axes, family, criterion="pep_1") -> str:
    """Markdown of one family: leave-one-out per parameter, then every grid point's means."""
    pairs = sorted(p for p, f in shipped["family"].items() if f == family)
    base = {k: _mean(shipped["pairs"][p][k] for p in pairs) for k in METRICS}
    lines = [f"{family}: {len(pairs)} pairs; each value chosen on the mean {criterion} of the other "
             f"{len(pairs) - 1}, measured on the left-out pair",
             "", f"| parameter | shipped | shipped: {HEAD} | leave-one-out: {HEAD} | chosen (value: pairs) |",
             "|---|---|---|---|---|"]
    grid = [f"| parameter | value | {HEAD} | {criterion} better than shipped on | time s/pair |",
            "|---|---|---|---|---|"]
    for label, points in axes.items():
        missing = [(v, run["name"]) for v, run in points if not set(pairs) <= set(run["pairs"])]
        if missing:
            raise SystemExit(f"Error: {missing[0][1]}: lacks pairs of {family} that the shipped run has; "
                             "run the grid point on the same pairs")
        loo = leave_one_out(points, pairs, criterion)
        counts = {}
        for value in loo["chosen"].values():
            counts[value] = counts.get(value, 0) + 1
        chosen = ", ".join(f"{v}: {n}" for v, n in sorted(counts.items(), key=lambda item: -item[1]))
        lines.append(f"| {label} | {points[0][0]} | {_cells(base)} | {_cells(loo['means'])} | {chosen} |")
        for value, run in points:
            means = {k: _mean(run["pairs"][p][k] for p in pairs) for k in METRICS}
            wins = sum(run["pairs"][p][criterion] < shipped["pairs"][p][criterion] for p in pairs)
            mark = " (shipped)" if run is shipped else ""
            seconds = _mean(run["pairs"][p]["time"] for p in pairs)
            grid.append(f"| {label} | {value}{mark} | {_cells(means)} | {wins} / {len(pairs)} | {seconds:.2f} |")
    return "\n".join(lines + [""] + grid)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", help="output folders of d3stereo run --eval (the grid)")
    parser.add_argument("--shipped", help="the shipped config's run (default: the folder named 'shipped')")
    parser.add_argument("--criterion", default="pep_1", choices=METRICS, help="metric that chooses (default pep_1)")
    parser.add_argument("--axis", action="append", default=[], help="keys varied together, comma-separated")
    parser.add_argument("--family", action="append", default=[], help="only these families (e.g. kitti)")
    args = parser.parse_args(argv)
    folders = [Path(f) for f in args.runs if Path(f).is_dir()]
    shipped_dir = Path(args.shipped) if args.shipped else next((f for f in folders if f.name == "shipped"), None)
    if shipped_dir is None:
        raise SystemExit("Error: no run folder named 'shipped' among the runs; name the shipped config's run "
                         "with --shipped FOLDER")
    shipped = read_run(shipped_dir)
    runs = [read_run(f) for f in folders if f.resolve() != shipped_dir.resolve()]
    axes = build_axes(shipped, runs, [tuple(a.split(",")) for a in args.axis])
    families = sorted(set(shipped["family"].values()))
    for family in families:
        if args.family and not any(family.startswith(f) for f in args.family):
            continue
        print(family_tables(shipped, axes, family, args.criterion))
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
