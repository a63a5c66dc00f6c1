"""Write the results tables of docs/results.md, docs/road.md and README.md from benchmark runs.

Families (``--families``, all by default), each run with the configuration meant for it:

- ``middlebury``: the ``middlebury*`` pairs of ``--data`` with the defaults; ELAS with
  libelas's Middlebury preset;
- ``kitti``: the ``kitti*`` pairs with ``-c kitti``; ELAS with libelas's robotics preset
  (``--set peers.elas_preset=robotics``);
- ``road``: 12 synthetic 1280x720 road pairs (``d3stereo synth DIR --n 12 --seed 0``) with
  ``-c road``: PT-D3Stereo, d3stereo without PT, SGBM and PT-SGM;
- ``road-photo``: the road pairs of ``--data`` (no ground truth), the same four methods,
  scored photometrically;
- ``road-check``: the road inspection check, 21 synthetic pairs for each of the seeds 9101,
  9202 and 9303 with ``-c road --road-report --eval``, scored by ``scripts/bench_road.py``
  (about 15 minutes on 2 cores), with the confidence flags on these tuning seeds;
- ``road-confidence``: the confidence check on seeds the road report was not tuned on
  (4243, 6827, 8971; 21 pairs each), scored as the road check, with the targets of
  docs/road.md, "The confidence check".

Middlebury and KITTI run d3stereo, OpenCV SGBM, ELAS and pandora census+SGM (``--methods``)
through ``scripts/benchmark.py``'s evaluation, every method in one process.  A peer whose
package is not installed is skipped and said so; its rows are then kept from the table
already in docs/results.md, and the tables mark them with a dagger.  Then the script
rewrites the blocks between marker comments:

- docs/results.md: ``<!-- table:NAME:begin -->`` ... ``<!-- table:NAME:end -->`` for NAME
  ``middlebury-kitti`` (family means), ``per-set``, ``wins`` (on how many pairs d3stereo is
  better) and ``peer-better`` (the pairs where a peer is better);
- docs/road.md: ``road-synth``, ``road-photometric``, ``road-check`` and ``road-confidence``;
- README.md: ``<!-- results-table:begin -->`` ... ``<!-- results-table:end -->`` (a compact
  table of the Middlebury, KITTI and synthetic road families).

Only the blocks of the families run are rewritten.  The machine (CPU model and count,
library versions) is written under every table.

Usage::

    python scripts/results_tables.py --data DATA                     # run all, rewrite the files
    python scripts/results_tables.py --data DATA --check             # run, print, write nothing
    python scripts/results_tables.py --data DATA --families middlebury,kitti --save run.json
    python scripts/results_tables.py --load run.json --load road.json # rewrite from kept rows

``--check`` exits with 1 when a file's block differs from the one printed (or a file has no
markers), else 0.  Middlebury and KITTI with all four methods take a few minutes on 2 cores
(pandora: 3-9 s a pair).
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import logging
import os
import subprocess
import tempfile
import platform
import re
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("d3", "sgbm", "elas", "pandora-sgm")
#: Metrics of the tables, lower is better (density is shown, not compared).
METRICS = ("epe", "pep_0.5", "pep_1", "pep_2")
METRIC_LABELS = {"epe": "EPE", "pep_0.5": "PEP0.5", "pep_1": "PEP1", "pep_2": "PEP2"}
PEER_LABELS = {"sgbm": "SGBM", "elas": "ELAS", "pandora-sgm": "pandora census+SGM"}
RESULTS_BLOCKS = ("middlebury-kitti", "per-set", "wins", "peer-better")
README_BLOCK = "results-table"
ROAD_BLOCK = "road-synth"
PHOTO_BLOCK = "road-photometric"
CHECK_BLOCK = "road-check"
CONFIDENCE_BLOCK = "road-confidence"
#: The road check of docs/road.md: 21 synthetic 1280x720 pairs per seed, ``-c road --road-report``.
ROAD_CHECK = {"seeds": (9101, 9202, 9303), "n": 21}
#: The confidence check of docs/road.md: the same on seeds never used for tuning.
CONFIDENCE_CHECK = {"seeds": (4243, 6827, 8971), "n": 21}
#: The synthetic road set of docs/road.md: ``d3stereo synth DIR --n 12 --seed 0`` (1280x720).
ROAD_SYNTH = {"n": 12, "seed": 0}
ROAD_METHODS = ("d3stereo+pt", "d3stereo", "sgbm", "pt-sgm")
README_ROAD_METHODS = ("d3stereo+pt", "sgbm", "pt-sgm")
README_ROAD_LABELS = {"d3stereo+pt": "PT-D3Stereo (`-c road`)", "sgbm": "SGBM", "pt-sgm": "PT-SGM"}
ROAD_LABELS = {"d3stereo+pt": "d3stereo, PT on (PT-D3Stereo)", "d3stereo": "d3stereo, PT off", "sgbm": "SGBM",
               "pt-sgm": "PT-SGM"}


@dataclass(frozen=True)
class Family:
    """One row group of the tables: which pairs, with which configuration."""

    key: str  # family prefix of the pairs (``pair.family`` starts with it)
    label: str  # shown in the tables
    config: str | None  # ``-c`` of the run (None: the defaults)
    overrides: tuple[str, ...]  # ``--set`` of the run
    d3_label: str  # d3stereo's method label in the tables


FAMILIES = (
    Family("middlebury", "Middlebury", None, (), "d3stereo (defaults)"),
    Family("kitti", "KITTI", "kitti", ("peers.elas_preset=robotics",), "d3stereo (`-c kitti`)"),
)


def method_label(family: Family, method: str) -> str:
    return family.d3_label if method == "d3" else PEER_LABELS[method]


# ---------------------------------------------------------------- running the benchmark


def installed_methods(methods) -> tuple[list[str], dict[str, str]]:
    """(methods that can run, {method: why not} for the others)."""
    from d3cli.config import method_spec
    from d3cli.errors import BackendUnavailable

    ok, skipped = [], {}
    for name in methods:
        try:
            spec = method_spec(name)
            if spec is not None:  # a name of this script only (e.g. a d3stereo preset) needs nothing more
                spec.require()
        except BackendUnavailable as exc:
            skipped[name] = str(exc)
        else:
            ok.append(name)
    return ok, skipped


def run_family(data, family: Family, methods, log=print) -> list[dict]:
    """Per-pair rows of ``benchmark.evaluate_pairs`` for one family (JSON-ready)."""
    import benchmark
    from d3cli import load_config
    from d3cli.data.layouts import discover

    logging.getLogger("transitions").setLevel(logging.ERROR)  # pandora's state machine talks
    cfg = load_config(family.config, family.overrides)
    pairs = [p for p in discover([str(data)]) if p.family.startswith(family.key)]
    rows = benchmark.evaluate_pairs(pairs, cfg, methods=list(methods), log=log)
    for row in rows:
        for name in methods:
            row[name].pop("pt", None)
    return rows


def run_road(log=print) -> list[dict]:
    """Per-pair rows of the synthetic road set with ``-c road`` (:data:`ROAD_METHODS`)."""
    import benchmark
    from d3cli import load_config
    from d3cli.data.layouts import discover

    with tempfile.TemporaryDirectory(prefix="d3-road-synth-") as folder:
        subprocess.run([sys.executable, "-m", "d3cli", "synth", folder, "--n", str(ROAD_SYNTH["n"]),
                        "--seed", str(ROAD_SYNTH["seed"]), "-q"], check=True)
        rows = benchmark.evaluate_pairs(discover([folder]), load_config("road"), methods=list(ROAD_METHODS), log=log)
    for row in rows:
        for name in ROAD_METHODS:
            row[name].pop("pt", None)
    return rows


def run_road_check(folder, check=ROAD_CHECK, log=print) -> dict:
    """Render, run and score a road check (``check``: its seeds and pairs per seed) in
    ``folder``; see :func:`score_road_check`."""
    folder = Path(folder)
    for seed in check["seeds"]:
        log(f"road check: seed {seed}")
        subprocess.run([sys.executable, "-m", "d3cli", "synth", str(folder / f"T{seed}"), "--n", str(check["n"]),
                        "--seed", str(seed), "--width", "1280", "--height", "720", "-q"], check=True)
        subprocess.run([sys.executable, "-m", "d3cli", "run", str(folder / f"T{seed}"), "-c", "road", "--road-report",
                        "--eval", "-o", str(folder / f"O{seed}"), "-q"], check=True)
    return score_road_check(folder, check)


def score_road_check(folder, check=ROAD_CHECK) -> dict:
    """Pool ``folder``'s ``T<seed>`` pairs and ``O<seed>`` outputs and score them.

    ``scripts/bench_road.py`` on folders of links ``s<seed>-<pair>`` (its summary, per-family
    table and the confidence check's figures and tables) and the mean map accuracy of the
    runs' ``metrics.csv``.
    """
    import contextlib
    import csv

    import bench_road

    folder = Path(folder)
    pooled_t, pooled_o = folder / "T", folder / "O"
    maps = []
    for seed in check["seeds"]:
        for pair in sorted(p for p in (folder / f"T{seed}").iterdir() if p.is_dir()):
            for root, base in ((pooled_t, folder / f"T{seed}"), (pooled_o, folder / f"O{seed}")):
                root.mkdir(exist_ok=True)
                link = root / f"s{seed}-{pair.name}"
                if not link.is_symlink():
                    link.symlink_to(base / pair.name)
        with open(folder / f"O{seed}" / "metrics.csv", newline="") as f:
            maps += [row for row in csv.DictReader(f) if row["status"] == "ok"]
    with contextlib.redirect_stdout(sys.stderr):
        bench_road.main([str(pooled_t), str(pooled_o), "--json", str(folder / "bench_road.json")])
    scored = json.loads((folder / "bench_road.json").read_text())
    rows = scored["pairs"]
    confidence = {"summary": bench_road.confidence_summary(rows), "family": bench_road.confidence_table(rows, "family"),
                  "lighting": bench_road.confidence_table(rows, "lighting")}
    return {"summary": scored["summary"], "families": scored["families"], "confidence": confidence,
            "maps": {k: sum(float(r[k]) for r in maps) / len(maps) for k in METRICS} | {"n": len(maps)}}


def run_road_photometric(data, log=print) -> list[dict]:
    """Photometric rows of the data folder's road pairs (no ground truth) with ``-c road``."""
    import benchmark
    from d3cli import load_config
    from d3cli.data.layouts import discover

    pairs = [p for p in discover([str(data)]) if p.family.startswith("road")]
    rows = benchmark.evaluate_pairs(pairs, load_config("road"), methods=list(ROAD_METHODS), photometric=True, log=log)
    for row in rows:
        for name in ROAD_METHODS:
            row[name].pop("pt", None)
    return rows


# ---------------------------------------------------------------- summarising (pure)


def family_summary(rows, methods) -> dict:
    """``{method: {"n": pairs, metric: mean, "density": mean}}`` over all ``rows``."""
    out = {}
    for name in methods:
        values = [row[name] for row in rows]
        out[name] = {"n": len(values)}
        for key in METRICS + ("pep_3", "density", "time"):
            if all(key in v for v in values):
                out[name][key] = sum(v[key] for v in values) / len(values)
    return out


def best_of(summary, metric, exclude=()) -> str | None:
    """The method with the lowest ``metric`` in ``summary`` (ties: the first)."""
    names = [n for n in summary if n not in exclude]
    return min(names, key=lambda n: summary[n][metric]) if names else None


def wins(rows, ref, peers) -> dict:
    """``{against: {metric: pairs where ref is strictly lower}}``, ``"best"`` = the lowest peer."""
    out = {a: dict.fromkeys(METRICS, 0) for a in list(peers) + ["best"]}
    for row in rows:
        for key in METRICS:
            others = {a: row[a][key] for a in peers}
            others["best"] = min(others.values())
            for against, value in others.items():
                out[against][key] += int(row[ref][key] < value)
    return out


def peer_better(rows, ref, peers) -> dict:
    """``{metric: [(pair, best peer, its value, ref's value)]}`` where a peer is lower."""
    out = {key: [] for key in METRICS}
    for row in sorted(rows, key=lambda r: r["pair"]):
        for key in METRICS:
            best = min(peers, key=lambda a: row[a][key])
            if row[best][key] < row[ref][key]:
                out[key].append((row["pair"], best, row[best][key], row[ref][key]))
    return out


def margin_text(summary, ref="d3") -> str:
    """d3stereo against the best other method of each metric, in words."""
    parts = []
    for key in METRICS:
        peer = best_of(summary, key, exclude=(ref,))
        if peer is None:
            continue
        mine, theirs = summary[ref][key], summary[peer][key]
        name = PEER_LABELS[peer]
        if key == "epe":
            rel = 100.0 * (theirs - mine) / theirs
            parts.append(f"EPE {abs(rel):.1f} % {'below' if rel >= 0 else 'above'} {name}'s")
        else:
            diff = theirs - mine
            parts.append(f"{METRIC_LABELS[key]} {abs(diff):.2f} points {'below' if diff >= 0 else 'above'} {name}'s")
    return ", ".join(parts)


def _fmt(key, value) -> str:
    return f"{value:.3f}" if key == "epe" else (f"{value:.1f}" if key == "density" else f"{value:.2f}")


# ---------------------------------------------------------------- rendering (pure)


def render_family_table(results, *, readme=False) -> str:
    """The family-means table; ``results`` is ``[(Family, summary, carried)]``.

    ``carried`` is the set of methods whose means were not measured in this run (kept
    from the previous table); their rows are marked with a dagger.  The lowest value of
    each metric in a family is bold.
    """
    keys = ("epe", "pep_1", "pep_2", "density") if readme else METRICS + ("density",)
    if readme:
        head = "| family | pairs | method | EPE [px] | PEP1 [%] | PEP2 [%] | density [%] |"
    else:
        head = "| family | pairs | method | EPE | PEP0.5 % | PEP1 % | PEP2 % | density % |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for family, summary, carried in results:
        best = {k: best_of(summary, k) for k in keys if k != "density"}
        for i, (name, means) in enumerate(summary.items()):
            cells = []
            for k in keys:
                text = _fmt(k, means[k])
                cells.append(f"**{text}**" if best.get(k) == name else text)
            label = method_label(family, name) + (" †" if name in carried else "")
            first = f"| {family.label} | {means['n']} |" if i == 0 else "| | |"
            lines.append(f"{first} {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_per_set(per_family) -> str:
    """EPE / PEP1 / PEP2 per data set (``row["family"]``, e.g. middlebury2014) of every method run."""
    head = "| set | pairs | method | EPE | PEP1 % | PEP2 % |"
    lines = [head, "|---|---|---|---|---|---|"]
    for family, rows, peers in per_family:
        methods = ["d3"] + list(peers)
        for name in sorted({row["family"] for row in rows}):
            summary = family_summary([row for row in rows if row["family"] == name], methods)
            best = {k: best_of(summary, k) for k in ("epe", "pep_1", "pep_2")}
            for i, method in enumerate(methods):
                cells = [f"**{_fmt(k, summary[method][k])}**" if best[k] == method else _fmt(k, summary[method][k])
                         for k in ("epe", "pep_1", "pep_2")]
                first = f"| {name} | {summary[method]['n']} |" if i == 0 else "| | |"
                lines.append(f"{first} {method_label(family, method)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_road_table(rows) -> str:
    """Means over the synthetic road pairs, one row per method; the lowest error bold."""
    methods = [m for m in ROAD_METHODS if m in rows[0]]
    summary = family_summary(rows, methods)
    keys = METRICS + ("pep_3", "density")
    best = {k: best_of(summary, k) for k in METRICS + ("pep_3",)}
    head = "| method | EPE | PEP0.5 % | PEP1 % | PEP2 % | PEP3 % | density % | time s/pair (median) |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for name in methods:
        cells = []
        for k in keys:
            text = _fmt(k, summary[name][k])
            cells.append(f"**{text}**" if best.get(k) == name else text)
        time = statistics.median(row[name]["time"] for row in rows)  # a first call may load kernels
        lines.append(f"| {ROAD_LABELS[name]} | " + " | ".join(cells) + f" | {time:.2f} |")
    return "\n".join(lines)


def render_photometric_table(rows) -> str:
    """Photometric means (right view warped onto the left) of the road pairs without ground truth."""
    methods = [m for m in ROAD_METHODS if m in rows[0]]
    means = {m: {k: sum(row[m][k] for row in rows) / len(rows) for k in ("psnr", "ssim", "mse", "coverage")}
             for m in methods}
    best = {"psnr": max(methods, key=lambda m: means[m]["psnr"]), "ssim": max(methods, key=lambda m: means[m]["ssim"]),
            "mse": min(methods, key=lambda m: means[m]["mse"])}
    formats = {"psnr": "{:.2f}", "ssim": "{:.3f}", "mse": "{:.0f}", "coverage": "{:.1f}"}
    lines = [f"| method ({len(rows)} pair{'' if len(rows) == 1 else 's'}) | PSNR dB | SSIM | MSE | coverage % |", "|---|---|---|---|---|"]
    for name in methods:
        cells = []
        for k in ("psnr", "ssim", "mse", "coverage"):
            text = formats[k].format(means[name][k])
            cells.append(f"**{text}**" if best.get(k) == name else text)
        lines.append(f"| {ROAD_LABELS[name]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_road_check(check) -> str:
    """The road check's summary, its per-family table and the maps' accuracy."""
    s, fam = check["summary"], check["families"]
    overall = next(f for f in fam if f["family"] == "overall")
    lines = ["| pairs | potholes > 20 mm | recall | false defects / pair (most in a pair) | duplicates | "
             "median abs depth err | median signed depth err | median abs area err | median abs volume err |",
             "|---|---|---|---|---|---|---|---|---|",
             f"| {s['pairs']} | {s['gt_potholes']} | {100 * s['recall']:.1f} % ({s['found']}/{s['gt_potholes']}) | "
             f"{s['false_defects_per_pair']:.2f} ({s['max_false_defects_in_a_pair']}) | {s['duplicates']} | "
             f"{100 * s['median_depth_error']:.1f} % | {100 * overall['signed_depth']:+.1f} % | "
             f"{100 * s['median_area_error']:.1f} % | {100 * s['median_volume_error']:.1f} % |",
             "", "Per pothole family:", "",
             "| family | potholes | found | recall | median abs depth err | median signed depth err | "
             "median abs area err | median abs volume err |", "|---|---|---|---|---|---|---|---|"]
    for f in fam:
        lines.append(f"| {f['family']} | {f['gt']} | {f['found']} | {100 * f['recall']:.0f} % | "
                     f"{100 * f['depth']:.1f} % | "
                     f"{100 * f['signed_depth']:+.1f} % | {100 * f['area']:.1f} % | {100 * f['volume']:.1f} % |")
    m = check["maps"]
    lines += ["", f"The {m['n']} maps (`--eval`), mean EPE / PEP0.5 / PEP1 / PEP2: "
                  f"{m['epe']:.3f} / {m['pep_0.5']:.2f} / "
                  f"{m['pep_1']:.2f} / {m['pep_2']:.2f}."]
    return "\n".join(lines)


def render_confidence(check, *, targets: bool) -> str:
    """The confidence figures of a road check (:func:`bench_road.confidence_markdown`: the
    targets' figures, with the targets of docs/road.md beside them when ``targets``, and
    the tables per lighting and per family)."""
    import bench_road

    conf = check.get("confidence")
    if not conf:
        return "(no confidence figures in this run)"
    return "\n".join(bench_road.confidence_markdown(conf["summary"], conf, targets=targets)).rstrip()


def render_readme_road_rows(rows) -> str:
    """The synthetic road set's rows of the README table (PT-D3Stereo, SGBM, PT-SGM)."""
    methods = [m for m in README_ROAD_METHODS if m in rows[0]]
    summary = family_summary(rows, methods)
    keys = ("epe", "pep_1", "pep_2", "density")
    best = {k: best_of(summary, k) for k in keys if k != "density"}
    lines = []
    for i, name in enumerate(methods):
        cells = [f"**{_fmt(k, summary[name][k])}**" if best.get(k) == name else _fmt(k, summary[name][k]) for k in keys]
        first = f"| synthetic road | {summary[name]['n']} |" if i == 0 else "| | |"
        lines.append(f"{first} {README_ROAD_LABELS[name]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_wins(per_family) -> str:
    """Per-pair win counts; ``per_family`` is ``[(Family, rows, peers)]`` (measured peers only)."""
    head = "| family | pairs | d3stereo better than | " + " | ".join(METRIC_LABELS[k] for k in METRICS) + " |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for family, rows, peers in per_family:
        if not peers:
            continue
        counts, n = wins(rows, "d3", peers), len(rows)
        for i, against in enumerate(list(peers) + ["best"]):
            label = "the best peer on the pair" if against == "best" else PEER_LABELS[against]
            first = f"| {family.label} | {n} |" if i == 0 else "| | |"
            lines.append(f"{first} {label} | " + " | ".join(f"{counts[against][k]} / {n}" for k in METRICS) + " |")
    return "\n".join(lines)


def render_peer_better(per_family) -> str:
    """Where a peer is better: per family and metric, the pairs (best peer's value / d3stereo's)."""
    lines = ["| family | metric | pairs | where (best peer: its value / d3stereo's) |", "|---|---|---|---|"]
    for family, rows, peers in per_family:
        if not peers:
            continue
        found = peer_better(rows, "d3", peers)
        for key in METRICS:
            items = found[key]
            where = "; ".join(f"{pair} ({PEER_LABELS[peer]}: {_fmt(key, theirs)} / {_fmt(key, mine)})"
                              for pair, peer, theirs, mine in items) or "none"
            lines.append(f"| {family.label} | {METRIC_LABELS[key]} | {len(items)} / {len(rows)} | {where} |")
    return "\n".join(lines)


def machine_text(cpu_model: str, cpus: int, versions: dict) -> str:
    """One line naming the machine and the library versions of the run."""
    libs = ", ".join(f"{name} {version}" for name, version in versions.items() if version)
    return f"{cpu_model}, {cpus} vCPUs; {libs}"


def footer(results, skipped, machine, *, readme=False, road=False) -> str:
    """Lines under a table: the command, the machine, the rows not measured again."""
    if readme:
        pairs = sum(next(iter(summary.values()))["n"] for _, summary, _ in results)
        synth = (f" and {ROAD_SYNTH['n']} synthetic 1280x720 road pairs (`d3stereo synth DIR --n {ROAD_SYNTH['n']} "
                 f"--seed {ROAD_SYNTH['seed']}`)") if road else ""
        lines = ["", f"Written by `python scripts/results_tables.py --data DATA` from the {pairs} development pairs "
                 f"with ground truth{synth}; per-pair wins and the commands: [docs/results.md](docs/results.md)."]
    else:
        lines = ["", "Command: `python scripts/results_tables.py --data DATA` (DATA: the development data, "
                 "[](datasets.md))."]
    lines.append(f"Machine: {machine}.")
    carried = sorted({m for _, _, c in results for m in c})
    if carried:
        names = ", ".join(PEER_LABELS[m] for m in carried)
        why = "; ".join(skipped[m] for m in carried if m in skipped)
        lines.append(f"† {names}: not installed in this run ({why}); rows kept from the previous run.")
    if not readme:
        for family, summary, _ in results:
            if "d3" in summary and len(summary) > 1:
                lines.append(f"{family.label}: d3stereo against the best other method of each metric: "
                             f"{margin_text(summary)}.")
    return "\n".join(lines)


# ---------------------------------------------------------------- blocks in files (pure)


def markers(name: str) -> tuple[str, str]:
    """The begin and end comments of block ``name``."""
    if name == README_BLOCK:
        return "<!-- results-table:begin -->", "<!-- results-table:end -->"
    return f"<!-- table:{name}:begin -->", f"<!-- table:{name}:end -->"


def get_block(text: str, name: str) -> str | None:
    """The text between block ``name``'s markers (None when they are missing)."""
    begin, end = markers(name)
    match = re.search(re.escape(begin) + r"\n(.*?)" + re.escape(end), text, flags=re.S)
    return None if match is None else match.group(1).rstrip("\n")


def replace_block(text: str, name: str, content: str) -> str:
    """``text`` with block ``name``'s content replaced; ValueError when a marker is missing."""
    begin, end = markers(name)
    pattern = re.compile(re.escape(begin) + r"\n.*?" + re.escape(end), flags=re.S)
    if not pattern.search(text):
        raise ValueError(f"no {begin} ... {end} markers")
    return pattern.sub(lambda _: f"{begin}\n{content}\n{end}", text, count=1)


def carried_rows(block: str | None) -> dict:
    """Family means per (family label, method label) of an earlier family table.

    Reads the table of :func:`render_family_table` (not the README form): ``{(family,
    method label): {"n": pairs, "epe": .., "pep_0.5": .., "pep_1": .., "pep_2": ..,
    "density": ..}}``; bold marks and daggers are dropped.
    """
    out, family = {}, None
    for line in (block or "").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 8 or cells[0] == "family":
            continue
        try:
            values = [float(c.replace("*", "")) for c in cells[3:]]
        except ValueError:
            continue
        if cells[0]:
            family, n = cells[0], int(cells[1])
        label = cells[2].replace(" †", "").strip()
        out[(family, label)] = {"n": n} | dict(zip(METRICS + ("density",), values))
    return out


# ---------------------------------------------------------------- the program


def describe_machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {"Python": platform.python_version()}
    for label, dist in (("numpy", "numpy"), ("OpenCV", "opencv-python-headless"), ("OpenCV", "opencv-python"),
                        ("numba", "numba"), ("pandora", "pandora"), ("pyelas", "pyelas")):
        if versions.get(label):
            continue
        try:
            versions[label] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            pass
    return machine_text(model, os.cpu_count() or 0, versions)


def build(runs, skipped, previous_block, machine) -> dict:
    """The new blocks: ``{block name: content}`` for results.md, README.md and road.md.

    ``runs`` is ``{family key or "road": per-pair rows}`` (methods as run), ``skipped`` the
    methods not run with why, ``previous_block`` results.md's current family table (for the
    rows of skipped methods).  Only the blocks of the families in ``runs`` are built.
    """
    previous = carried_rows(previous_block)
    results, per_family = [], []
    for family in FAMILIES:
        rows = runs.get(family.key) or []
        if not rows:
            continue
        ran = [m for m in METHODS if m in rows[0]]
        summary = family_summary(rows, ran)
        carried = set()
        for name in METHODS:
            if name in ran or name not in skipped:
                continue
            old = previous.get((family.label, method_label(family, name)))
            if old is not None:
                summary[name] = old
                carried.add(name)
        summary = {m: summary[m] for m in METHODS if m in summary}
        results.append((family, summary, carried))
        per_family.append((family, rows, [m for m in ran if m != "d3"]))
    blocks = {}
    if results:
        not_run = ", ".join(PEER_LABELS[m] for m in METHODS if m in skipped)
        pair_note = f"\n\nWithout {not_run} (not run)." if not_run else ""
        blocks["middlebury-kitti"] = render_family_table(results) + "\n" + footer(results, skipped, machine)
        blocks["per-set"] = render_per_set(per_family) + pair_note
        blocks["wins"] = render_wins(per_family) + pair_note
        blocks["peer-better"] = render_peer_better(per_family) + pair_note
        table = render_family_table(results, readme=True)
        if runs.get("road"):
            table += "\n" + render_readme_road_rows(runs["road"])
        note = footer(results, skipped, machine, readme=True, road=bool(runs.get("road")))
        blocks[README_BLOCK] = table + "\n" + note
    if runs.get("road"):
        blocks[ROAD_BLOCK] = (render_road_table(runs["road"]) + "\n\nCommand: `python scripts/results_tables.py "
                              "--data DATA` (this table: `--families road`), which renders the set with "
                              f"`d3stereo synth DIR --n {ROAD_SYNTH['n']} --seed {ROAD_SYNTH['seed']}` and runs "
                              "`python scripts/benchmark.py DIR -c road --methods "
                              f"{','.join(ROAD_METHODS)}`; all methods in one process; time: wall seconds on the "
                              "machine below, which is shared (controlled ratios: [](performance.md)).\n"
                              f"Machine: {machine}.")
    if runs.get("road-photo"):
        blocks[PHOTO_BLOCK] = (render_photometric_table(runs["road-photo"]) + "\n\nCommand: `python "
                               "scripts/results_tables.py --data DATA` (this table: `--families road-photo`), which "
                               "runs `python scripts/benchmark.py DATA --family road --photometric -c road --methods "
                               f"{','.join(ROAD_METHODS)}`.\nMachine: {machine}.")
    if runs.get("road-check"):
        seeds = ", ".join(str(seed) for seed in ROAD_CHECK["seeds"])
        blocks[CHECK_BLOCK] = (render_road_check(runs["road-check"]) + "\n\nCommand: `python "
                               "scripts/results_tables.py --data DATA` (this table: `--families road-check`), which "
                               "runs the commands above for the seeds " + seeds
                               + f" ({ROAD_CHECK['n']} pairs each) and "
                               f"scores the pooled pairs.\nMachine: {machine}.")
        blocks[CHECK_BLOCK] = blocks[CHECK_BLOCK].replace(
            "\n\nCommand:", "\n\nConfidence on these tuning seeds:\n\n"
            + render_confidence(runs["road-check"], targets=False) + "\n\nCommand:", 1)
    if runs.get("road-confidence"):
        seeds = ", ".join(str(seed) for seed in CONFIDENCE_CHECK["seeds"])
        check = runs["road-confidence"]
        s = check["summary"]
        blocks[CONFIDENCE_BLOCK] = (
            f"{s['pairs']} pairs, {s['gt_potholes']} potholes deeper than 20 mm, recall {100 * s['recall']:.1f} % "
            f"({s['found']}/{s['gt_potholes']}), false defects {s['false_defects_per_pair']:.2f} per pair.\n\n"
            + render_confidence(check, targets=True) + "\n\nCommand: `python scripts/results_tables.py --data DATA` "
            "(this table: `--families road-confidence`), which runs the commands above for the seeds " + seeds
            + f" ({CONFIDENCE_CHECK['n']} pairs each) and scores the pooled pairs with "
            f"`scripts/bench_road.py --confidence`.\nMachine: {machine}.")
    return blocks


FAMILY_CHOICES = tuple(f.key for f in FAMILIES) + ("road", "road-photo", "road-check", "road-confidence")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", help="data folder with the Middlebury and KITTI pairs")
    parser.add_argument("--families", default=",".join(FAMILY_CHOICES),
                        help="comma-separated subset of " + ", ".join(FAMILY_CHOICES))
    parser.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset of " + ", ".join(METHODS))
    parser.add_argument("--check", action="store_true", help="print the blocks and compare; write nothing")
    parser.add_argument("--save", help="write the per-pair rows of the run to this JSON file")
    parser.add_argument("--load", action="append", default=[],
                        help="take the per-pair rows from this JSON file instead of running (repeatable)")
    parser.add_argument("--results", default=str(ROOT / "docs" / "results.md"), help="results page to rewrite")
    parser.add_argument("--readme", default=str(ROOT / "README.md"), help="README to rewrite")
    parser.add_argument("--road-page", default=str(ROOT / "docs" / "road.md"), help="road page to rewrite")
    args = parser.parse_args(argv)
    families = [f.strip() for f in args.families.split(",") if f.strip()]
    if [f for f in families if f not in FAMILY_CHOICES]:
        parser.error(f"--families: use {', '.join(FAMILY_CHOICES)}")
    if bool(args.data) == bool(args.load):
        parser.error("give --data (run the benchmark) or --load (rows of an earlier run)")

    if args.load:
        runs, skipped, machine = {}, {}, ""
        for name in args.load:
            saved = json.loads(Path(name).read_text())
            runs.update(saved["runs"])
            skipped.update(saved["skipped"])
            machine = machine or saved["machine"]
    else:
        wanted = [m.strip() for m in args.methods.split(",") if m.strip()]
        if [m for m in wanted if m not in METHODS] or "d3" not in wanted:
            parser.error(f"--methods: use d3 and any of {', '.join(METHODS[1:])}")
        ok, skipped = installed_methods(wanted)
        for name, why in skipped.items():
            print(f"skipped {name}: {why}", file=sys.stderr)
        machine = describe_machine()
        runs = {}
        log = lambda line: print(line, file=sys.stderr)  # noqa: E731
        for family in FAMILIES:
            if family.key not in families:
                continue
            print(f"{family.label}: -c {family.config or '(defaults)'} "
                  f"{' '.join('--set ' + o for o in family.overrides)} --methods {','.join(ok)}", file=sys.stderr)
            runs[family.key] = run_family(args.data, family, ok, log=log)
        if "road" in families:
            print(f"synthetic road set: -c road --methods {','.join(ROAD_METHODS)}", file=sys.stderr)
            runs["road"] = run_road(log=log)
        if "road-photo" in families:
            print(f"road pairs without ground truth: -c road --photometric --methods {','.join(ROAD_METHODS)}",
                  file=sys.stderr)
            runs["road-photo"] = run_road_photometric(args.data, log=log)
        if "road-check" in families:
            print(f"road check: seeds {ROAD_CHECK['seeds']}, -c road --road-report", file=sys.stderr)
            with tempfile.TemporaryDirectory(prefix="d3-road-check-") as folder:
                runs["road-check"] = run_road_check(folder, log=log)
        if "road-confidence" in families:
            print(f"confidence check: seeds {CONFIDENCE_CHECK['seeds']}, -c road --road-report", file=sys.stderr)
            with tempfile.TemporaryDirectory(prefix="d3-road-confidence-") as folder:
                runs["road-confidence"] = run_road_check(folder, CONFIDENCE_CHECK, log=log)
        if args.save:
            Path(args.save).write_text(json.dumps({"runs": runs, "skipped": skipped, "machine": machine}, indent=1))

    results_path = Path(args.results)
    previous = get_block(results_path.read_text(), "middlebury-kitti") if results_path.exists() else None
    blocks = build(runs, skipped, previous, machine)

    status = 0
    files = ((results_path, RESULTS_BLOCKS), (Path(args.readme), (README_BLOCK,)),
             (Path(args.road_page), (ROAD_BLOCK, PHOTO_BLOCK, CHECK_BLOCK, CONFIDENCE_BLOCK)))
    for path, names in files:
        names = [name for name in names if name in blocks]
        if not names:
            continue
        text = path.read_text() if path.exists() else ""
        new = text
        for name in names:
            print(f"{markers(name)[0]}\n{blocks[name]}\n{markers(name)[1]}\n")
            try:
                new = replace_block(new, name, blocks[name])
            except ValueError as exc:
                print(f"{path}: {exc}; not written", file=sys.stderr)
                status = 1
        if args.check:
            if new != text:
                print(f"{path}: the tables differ from this run's", file=sys.stderr)
                status = 1
        elif new != text:
            path.write_text(new)
            print(f"{path}: tables written", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
