"""Evaluation reports: per-pair CSV, summary JSON and Markdown, side-by-side tables.

A *row* is one pair's outcome, a plain dict::

    {"pair": "kitti2012_000000", "family": "kitti2012", "status": "ok",
     "epe": 0.91, "pep_0.5": 31.2, ..., "n_px": 120345, "time_s": 2.4, "error": None}

``status`` is ``"ok"``, ``"failed"`` (``error`` holds the message) or ``"skipped"``
(``error`` holds the reason).  Metric keys are those of :data:`METRIC_COLUMNS`
(see :mod:`d3cli.evaluation.metrics`); a missing or NaN value means "not measured" (e.g. no
ground truth), never zero.  ``warnings`` (optional) lists the pair's warnings as its
result.json has them (e.g. "were left and right swapped?").

metrics.csv and summary.json keep every figure; the tables people read (terminal,
summary.md, report.html) show the columns :func:`shown_columns` chooses.

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

from ..errors import OutputError, readable, where_what_fix
from ..data.formats import atomic_write
from .summary import (  # noqa: F401 - the row columns and summarize are read from here too
    BENCHMARK_COLUMNS,
    CSV_COLUMNS,
    DISPARITY_COLUMNS,
    MASK_COLUMNS,
    MEAN_KEYS,
    METRIC_COLUMNS,
    NO_FAMILY,
    PHOTOMETRIC_COLUMNS,
    SHOWN_GT_COLUMNS,
    SHOWN_PHOTOMETRIC_COLUMNS,
    STATUSES,
    plural,
    shown_columns,
    summarize,
)
from .tables import (  # noqa: F401 - the tables are read from here too
    DECIMALS,
    LABELS,
    MISSING,
    counts_sentence,
    format_table,
    one_line,
    side_by_side,
    summary_markdown,
)


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
                writer.writerow([readable(_csv_cell(row.get(column))) for column in columns])

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
        return " | ".join(one_line(str(item)) for item in value)
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


# ------------------------------------------------------------------- helpers


def _text_writer(text: str) -> Callable[[Path], None]:
    def write(tmp_path: Path) -> None:
        with open(tmp_path, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(readable(text))

    return write
