"""Evaluation reports: per-pair CSV, summary JSON and Markdown, side-by-side tables.

A *row* is one pair's outcome, a plain dict::

    {"pair": "kitti2012_000000", "family": "kitti2012", "status": "ok",
     "epe": 0.91, "pep_0.5": 31.2, ..., "n_px": 120345, "time_s": 2.4, "error": None}

``status`` is ``"ok"``, ``"failed"`` (``error`` holds the message) or ``"skipped"``
(``error`` holds the reason).  Metric keys are those of :data:`METRIC_COLUMNS`
(see :mod:`d3cli.evaluation.metrics`); a missing or NaN value means "not measured" (e.g. no
ground truth), never zero.

Means (:func:`summarize`) are plain means of the per-pair values over the ``ok`` pairs
that have the value: EPE/PEP/density over the pairs with ground truth, photometric
scores over the pairs where they were computed, time over all ok pairs.  Failed pairs
are listed with their message, never averaged in silently.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

import numpy as np

from ..errors import OutputError, where_what_fix
from ..data.formats import atomic_write

#: Metrics computed against ground truth; a pair "has gt" when its EPE is a number.
DISPARITY_COLUMNS = ["epe", "pep_0.5", "pep_1", "pep_2", "pep_3", "density"]

#: Metrics of the warped right image (no ground truth needed).
PHOTOMETRIC_COLUMNS = ["mse", "psnr", "ssim", "coverage"]

#: Metric keys in display order (disparity errors, then photometric scores).
METRIC_COLUMNS = [*DISPARITY_COLUMNS, *PHOTOMETRIC_COLUMNS]

#: KITTI D1 and Middlebury figures (:func:`d3cli.evaluation.metrics.benchmark_metrics`),
#: each on all ground-truth pixels (``_all``) and on the non-occluded ones (``_noc``).
BENCHMARK_COLUMNS = [
    f"{fig}_{mask}"
    for fig in ("d1", "bad_0.5", "bad_1", "bad_2", "bad_4", "avgerr", "rms", "a50", "a90", "a95", "a99")
    for mask in ("all", "noc")
] + ["d1_bg", "d1_fg"]

#: Columns naming the mask files behind the ``_all`` and ``_noc`` figures.
MASK_COLUMNS = ["mask_all", "mask_noc"]

#: Columns of ``metrics.csv``, in order; keys of a row outside this list follow them.
CSV_COLUMNS = ["pair", "family", "status", *METRIC_COLUMNS, "n_px", *BENCHMARK_COLUMNS,
               *MASK_COLUMNS, "n_px_all", "n_px_noc", "time_s", "error"]

#: Pair outcomes.
STATUSES = ("ok", "failed", "skipped")

#: Keys averaged by :func:`summarize`.
MEAN_KEYS = [*METRIC_COLUMNS, *BENCHMARK_COLUMNS, "time_s"]

#: Family label of rows whose ``family`` is empty.
NO_FAMILY = "other"

LABELS = {
    "epe": "EPE (px)",
    "pep_0.5": "PEP 0.5 (%)",
    "pep_1": "PEP 1 (%)",
    "pep_2": "PEP 2 (%)",
    "pep_3": "PEP 3 (%)",
    "density": "density (%)",
    "mse": "MSE",
    "psnr": "PSNR (dB)",
    "ssim": "SSIM",
    "coverage": "coverage (%)",
    "time_s": "time (s)",
}

#: Short labels for the fixed-width terminal table.
SHORT_LABELS = {
    "epe": "EPE",
    "pep_0.5": "PEP0.5",
    "pep_1": "PEP1",
    "pep_2": "PEP2",
    "pep_3": "PEP3",
    "density": "dens%",
    "mse": "MSE",
    "psnr": "PSNR",
    "ssim": "SSIM",
    "coverage": "cov%",
    "time_s": "time_s",
}

#: Decimals shown per key: 3 for EPE (px), 2 for percentages.
DECIMALS = {
    "epe": 3,
    "pep_0.5": 2,
    "pep_1": 2,
    "pep_2": 2,
    "pep_3": 2,
    "density": 2,
    "mse": 2,
    "psnr": 2,
    "ssim": 4,
    "coverage": 2,
    "time_s": 2,
}

MISSING = "n/a"


# ----------------------------------------------------------------------------- CSV


def write_pair_csv(path: str | Path, rows: Iterable[Mapping]) -> Path:
    """Write one line per pair to a CSV file, atomically.

    Parameters
    ----------
    path : str or Path
        Output file (usually ``<out>/metrics.csv``).
    rows : iterable of dict
        Pair rows (see the module docstring).  Columns are :data:`CSV_COLUMNS`, then any
        other keys in the order first seen.

    Returns
    -------
    Path
        ``path``.

    Notes
    -----
    Floats are written with full precision (``repr``), so :func:`read_pair_csv` gives
    back the same numbers; ``None`` and NaN become empty cells, infinities ``inf``.
    """
    rows = list(rows)
    columns = list(CSV_COLUMNS)
    for row in rows:
        columns.extend(key for key in row if key not in columns)

    def write(tmp_path: Path) -> None:
        with open(tmp_path, "w", newline="", encoding="utf-8") as handle:
            writer = csv.writer(handle, lineterminator="\n")
            writer.writerow(columns)
            for row in rows:
                writer.writerow([_csv_cell(row.get(column)) for column in columns])

    path = Path(path)
    atomic_write(path, write)
    return path


def read_pair_csv(path: str | Path) -> list[dict]:
    """Read a CSV written by :func:`write_pair_csv` back into rows.

    Metric columns and ``time_s`` become float (``None`` for empty cells), ``n_px`` int
    (or ``None``), ``error`` a string or ``None``; other columns stay strings.
    """
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return [_parse_csv_row(row) for row in rows]


def _csv_cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return "" if math.isnan(value) else repr(value)
    if isinstance(value, (list, tuple)):  # e.g. a pair's warnings: one cell
        return " | ".join(_one_line(str(item)) for item in value)
    return str(value)


def _parse_csv_row(row: dict) -> dict:
    parsed = dict(row)
    for key in MEAN_KEYS:
        if key in parsed:
            parsed[key] = float(parsed[key]) if parsed[key] != "" else None
    for key in ("n_px", "n_px_all", "n_px_noc"):
        if key in parsed:
            parsed[key] = int(parsed[key]) if parsed[key] != "" else None
    for key in ("error", *MASK_COLUMNS):
        if key in parsed:
            parsed[key] = parsed[key] or None
    return parsed


# ------------------------------------------------------------------------- summary


def summarize(rows: Iterable[Mapping]) -> dict:
    """Counts, overall and per-family means, and the list of failures.

    Parameters
    ----------
    rows : iterable of dict
        Pair rows (see the module docstring).

    Returns
    -------
    dict
        ``counts``: ``{"ok", "failed", "skipped", "total"}``;
        ``overall`` and ``families[<family>]`` (families sorted by name; an empty family
        is :data:`NO_FAMILY`): ``{"pairs", "ok", "failed", "skipped", "with_gt",
        "means"}`` where ``with_gt`` counts the ok pairs with a numeric EPE and
        ``means`` maps every key of :data:`MEAN_KEYS` to the mean over the ok pairs
        that have a numeric value (``None`` when none has);
        ``failures``: ``[{"pair", "family", "error"}]``;
        ``skipped``: ``[{"pair", "family", "reason"}]``;
        ``warnings``: ``[{"pair", "family", "warning"}]``, one per entry of a row's
        ``warnings`` list (e.g. "the pair may be unrectified or swapped").

    Raises
    ------
    ValueError
        When a row's ``status`` is not one of :data:`STATUSES`.
    """
    rows = [_checked_row(row) for row in rows]
    families = sorted({_family(row) for row in rows})
    return {
        "counts": {
            **{status: sum(row["status"] == status for row in rows) for status in STATUSES},
            "total": len(rows),
        },
        "overall": _summarize_group(rows),
        "families": {
            family: _summarize_group([row for row in rows if _family(row) == family])
            for family in families
        },
        "failures": [
            {"pair": row["pair"], "family": _family(row), "error": row.get("error") or ""}
            for row in rows
            if row["status"] == "failed"
        ],
        "skipped": [
            {"pair": row["pair"], "family": _family(row), "reason": row.get("error") or ""}
            for row in rows
            if row["status"] == "skipped"
        ],
        "warnings": [
            {"pair": row["pair"], "family": _family(row), "warning": str(text)}
            for row in rows
            for text in (row.get("warnings") or [])
        ],
    }


def _checked_row(row: Mapping) -> dict:
    status = row.get("status", "")
    if status not in STATUSES:
        raise ValueError(
            f"pair {row.get('pair')!r}: status is {status!r}; expected one of {', '.join(STATUSES)}"
        )
    return dict(row)


def _family(row: Mapping) -> str:
    return row.get("family") or NO_FAMILY


def _summarize_group(rows: list[dict]) -> dict:
    ok = [row for row in rows if row["status"] == "ok"]
    return {
        "pairs": len(rows),
        "ok": len(ok),
        "failed": sum(row["status"] == "failed" for row in rows),
        "skipped": sum(row["status"] == "skipped" for row in rows),
        "with_gt": sum(_number(row.get("epe")) is not None for row in ok),
        "means": {key: _mean(_number(row.get(key)) for row in ok) for key in MEAN_KEYS},
    }


def _number(value) -> float | None:
    """A row value as float; ``None`` for "not measured" (None, empty, NaN)."""
    if value is None or value == "":
        return None
    number = float(value)
    return None if math.isnan(number) else number


def _mean(values: Iterable[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    # math.fsum: exact sum, so a mean does not depend on the order of the pairs.
    return math.fsum(present) / len(present) if present else None


def write_summary(
    out_dir: str | Path,
    rows: Iterable[Mapping],
    *,
    method: str,
    extra: dict | None = None,
    run_counts: Mapping | None = None,
) -> tuple[Path, Path]:
    """Write ``metrics.csv``, ``summary.json`` and ``summary.md`` into ``out_dir``, atomically.

    Parameters
    ----------
    out_dir : str or Path
        Output folder; created when missing.
    rows : iterable of dict
        Pair rows (see the module docstring).
    method : str, keyword-only
        Name of the method that produced the disparities (e.g. ``"d3stereo"``).
    extra : dict, optional, keyword-only
        Passed through into ``summary.json`` under ``"extra"`` (config, versions, ...).
    run_counts : dict, optional, keyword-only
        ``{"n_computed", "n_skipped", "n_failed"}`` as ``run.json`` of a ``d3stereo run``
        has them (``n_skipped``: pairs kept complete from an earlier run, ``ok`` rows
        here).  Stored as ``summary.json["run"]`` and stated in summary.md's counts line,
        so the summary and run.json never disagree about what this run computed.

    Returns
    -------
    json_path, md_path : Path
        ``out_dir/summary.json`` and ``out_dir/summary.md``.

    Raises
    ------
    OutputError
        When the folder cannot be created or written.

    Notes
    -----
    ``summary.json`` holds ``method``, the keys of :func:`summarize` and ``extra``.
    JSON has no NaN or infinity: non-finite numbers are written as ``null`` (a mean
    PSNR is infinite only when some pair was warped without any error).
    """
    rows = list(rows)
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            where_what_fix(
                str(out_dir),
                f"cannot create the report folder ({exc.strerror or exc})",
                "choose a writable output folder",
            )
        ) from exc

    summary = {"method": method, **summarize(rows), "extra": dict(extra or {})}
    if run_counts is not None:
        summary["run"] = {key: int(run_counts[key]) for key in ("n_computed", "n_skipped", "n_failed")}
    write_pair_csv(out_dir / "metrics.csv", rows)
    json_path = out_dir / "summary.json"
    md_path = out_dir / "summary.md"
    json_text = json.dumps(jsonable(summary), indent=2, allow_nan=False) + "\n"
    atomic_write(json_path, _text_writer(json_text))
    atomic_write(md_path, _text_writer(summary_markdown(summary, rows)))
    return json_path, md_path


def jsonable(value):
    """Plain JSON types: numpy scalars/arrays unwrapped, paths as strings, NaN/inf as None."""
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [jsonable(item) for item in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        return jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (str, int, bool)):
        return value
    return str(value)


# ------------------------------------------------------------------------ Markdown


def summary_markdown(summary: Mapping, rows: Iterable[Mapping]) -> str:
    """The ``summary.md`` text: a table per family, the overall table, failed pairs.

    Parameters
    ----------
    summary : dict
        Output of :func:`summarize` (with ``method`` added by :func:`write_summary`).
    rows : iterable of dict
        The pair rows the summary was made from.

    Returns
    -------
    str
        Markdown.  Columns are the metrics that some pair has a value for, then time.
    """
    rows = [_checked_row(row) for row in rows]
    keys = _columns_with_values(rows)
    lines = [
        f"# Evaluation: {summary.get('method', '')}".rstrip(),
        "",
        counts_sentence(summary),
        "",
        "Means over the ok pairs that have the value. EPE in px; PEP(δ) = % of pixels with "
        "|d - gt| > δ px over pixels with valid ground truth (a pixel without an estimate "
        "counts as an error of |gt|); density = % of those pixels with an estimate. "
        "Photometric scores compare the left image with the warped right image over the "
        "covered pixels.",
        "",
    ]
    for family, group in summary["families"].items():
        family_rows = [row for row in rows if _family(row) == family]
        lines += [f"## {family}", "", *_family_table(family_rows, group, keys), ""]
    lines += ["## Overall", "", *_overall_table(summary, keys), ""]
    lines += ["## Failed pairs", ""]
    failures = [f"- {item['pair']}: {_one_line(item['error'])}" for item in summary["failures"]]
    lines += failures or ["None."]
    if summary.get("skipped"):
        lines += ["", "## Skipped pairs", ""]
        lines += [f"- {item['pair']}: {_one_line(item['reason'])}" for item in summary["skipped"]]
    if summary.get("warnings"):
        lines += ["", "## Warnings", "", "Maps of these pairs may be wrong; see each pair's result.json.", ""]
        lines += [f"- {item['pair']}: {_one_line(item['warning'])}" for item in summary["warnings"]]
    return "\n".join(lines) + "\n"


def counts_sentence(summary: Mapping) -> str:
    """``6 pairs: 4 ok, 1 failed, 1 skipped.``; after a ``d3stereo run`` (``summary["run"]``)
    the ok pairs are split as run.json counts them: ``6 pairs: 6 ok (2 computed, 4 skipped
    as complete), 0 failed.`` (issue 12 item 7: "skipped" there means kept from an earlier
    run, never left out)."""
    counts = summary["counts"]
    run = summary.get("run")
    if run is None:
        return f"{counts['total']} pairs: {counts['ok']} ok, {counts['failed']} failed, {counts['skipped']} skipped."
    text = (f"{counts['total']} pairs: {counts['ok']} ok ({run['n_computed']} computed, {run['n_skipped']} "
            f"skipped as complete), {counts['failed']} failed")
    if counts["skipped"]:
        text += f", {counts['skipped']} left out"
    return text + "."


def _family_table(rows: list[dict], group: Mapping, keys: list[str]) -> list[str]:
    """One line per pair, then the family's mean line."""
    body = [
        [_md_escape(row["pair"]), row["status"], *(_format_value(k, row.get(k)) for k in keys)]
        for row in rows
    ]
    means = group["means"]
    body.append(["**mean**", f"{group['ok']} ok", *(_format_value(k, means[k]) for k in keys)])
    header = ["pair", "status", *(LABELS[k] for k in keys)]
    return _markdown_table(header, body, n_text_columns=2)


def _overall_table(summary: Mapping, keys: list[str]) -> list[str]:
    """One line of means per family, then the overall means."""
    groups = [*summary["families"].items(), ("**overall**", summary["overall"])]
    body = [
        [
            _md_escape(family),
            str(group["ok"]),
            str(group["with_gt"]),
            *(_format_value(k, group["means"][k]) for k in keys),
        ]
        for family, group in groups
    ]
    header = ["family", "ok", "with gt", *(LABELS[k] for k in keys)]
    return _markdown_table(header, body, n_text_columns=1)


def side_by_side(results: Mapping[str, Iterable[Mapping]]) -> str:
    """Markdown table comparing methods: one column per method, rows (family, metric).

    Parameters
    ----------
    results : dict of str to list of dict
        Method name -> its pair rows; columns follow the dict's order.

    Returns
    -------
    str
        A Markdown table.  Per family (sorted by name), then ``overall`` last, the rows
        are: the number of ok pairs with ground truth (means over different pair sets
        are not comparable, so the count stands first), EPE (3 decimals), PEP
        0.5/1/2/3 and density (%, 2 decimals) when some method has ground-truth scores
        in that family, MSE/PSNR/SSIM/coverage when some method has them there, and
        time (s).  ``n/a`` where a method has no value (e.g. all its pairs of that
        family failed).
    """
    summaries = {method: summarize(rows) for method, rows in results.items()}
    families = sorted({family for s in summaries.values() for family in s["families"]})
    empty_group = _summarize_group([])
    groups = [
        (family, [s["families"].get(family, empty_group) for s in summaries.values()])
        for family in families
    ]
    groups.append(("**overall**", [s["overall"] for s in summaries.values()]))

    body = []
    for family, by_method in groups:
        body.append([_md_escape(family), "pairs with gt", *(str(g["with_gt"]) for g in by_method)])
        body += [
            ["", LABELS[key], *(_format_value(key, g["means"][key]) for g in by_method)]
            for key in _keys_with_values(by_method)
        ]
    header = ["family", "metric", *(_md_escape(method) for method in summaries)]
    return "\n".join(_markdown_table(header, body, n_text_columns=2)) + "\n"


def _keys_with_values(groups: list[Mapping]) -> list[str]:
    """Side-by-side metric rows of one family: metric blocks some method has, then time."""

    def present(key: str) -> bool:
        return any(group["means"][key] is not None for group in groups)

    keys = list(DISPARITY_COLUMNS) if any(map(present, DISPARITY_COLUMNS)) else []
    keys += [key for key in PHOTOMETRIC_COLUMNS if present(key)]
    return [*keys, "time_s"]


def _markdown_table(header: list[str], body: list[list[str]], *, n_text_columns: int) -> list[str]:
    """Lines of a Markdown table; the first ``n_text_columns`` left-aligned, numbers right."""
    align = ["---"] * n_text_columns + ["---:"] * (len(header) - n_text_columns)
    return ["| " + " | ".join(cells) + " |" for cells in (header, align, *body)]


def _columns_with_values(rows: list[dict]) -> list[str]:
    """Metric columns that some row has a value for, then time (always shown)."""
    present = [
        key for key in METRIC_COLUMNS if any(_number(row.get(key)) is not None for row in rows)
    ]
    return [*present, "time_s"]


def _md_escape(text: str) -> str:
    return str(text).replace("|", "\\|")


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


# ------------------------------------------------------------------------ terminal


def format_table(summary: Mapping) -> str:
    """A fixed-width text table of a summary for the terminal.

    Parameters
    ----------
    summary : dict
        Output of :func:`summarize` (``method`` shown when present).

    Returns
    -------
    str
        A header line with the counts, one line per family and ``overall`` (columns:
        ok pairs, pairs with gt, the metrics that have values, time), then one line per
        failed pair.
    """
    groups = [*summary["families"].items(), ("overall", summary["overall"])]
    keys = [key for key in METRIC_COLUMNS if any(g["means"][key] is not None for _, g in groups)]
    keys.append("time_s")
    header = ["family", "ok", "gt", *(SHORT_LABELS[key] for key in keys)]
    body = [
        [
            family,
            str(group["ok"]),
            str(group["with_gt"]),
            *(_format_value(key, group["means"][key]) for key in keys),
        ]
        for family, group in groups
    ]
    widths = [max(len(line[i]) for line in (header, *body)) for i in range(len(header))]

    def render(cells: list[str]) -> str:
        first = cells[0].ljust(widths[0])
        rest = (cell.rjust(width) for cell, width in zip(cells[1:], widths[1:]))
        return "  ".join([first, *rest]).rstrip()

    counts = summary["counts"]
    title = f"{summary['method']}: " if summary.get("method") else ""
    lines = [
        f"{title}{counts['ok']} ok, {counts['failed']} failed, {counts['skipped']} skipped "
        f"of {counts['total']} pairs",
        render(header),
        *(render(cells) for cells in body),
    ]
    lines += [f"failed {item['pair']}: {_one_line(item['error'])}" for item in summary["failures"]]
    return "\n".join(lines)


def _format_value(key: str, value) -> str:
    number = _number(value)
    if number is None:
        return MISSING
    if math.isinf(number):
        return "inf" if number > 0 else "-inf"
    return f"{number:.{DECIMALS.get(key, 3)}f}"


# ------------------------------------------------------------------- helpers


def _text_writer(text: str) -> Callable[[Path], None]:
    def write(tmp_path: Path) -> None:
        with open(tmp_path, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)

    return write
