"""Summaries of pair rows: counts, per-family and overall means, failures and warnings,
and the columns every report shows (:func:`shown_columns`).

Rows are described in :mod:`d3cli.evaluation.report`.  Means are plain means of the
per-pair values over the ``ok`` pairs that have the value; failed pairs are listed with
their message, never averaged in silently.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from ..errors import plural

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
    for fig in ("d1", "bad_0.5", "bad_1", "bad_2", "bad_4", "invalid", "avgerr", "rms", "a50", "a90", "a95", "a99")
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

#: Ground-truth columns the reports show (terminal, summary.md, report.html), in order:
#: the mean error, the paper's three outlier shares, KITTI's D1 and the density.  PEP 3 is
#: left out (it is D1 without D1's 5 % clause); metrics.csv and summary.json keep every figure.
SHOWN_GT_COLUMNS = ["epe", "pep_0.5", "pep_1", "pep_2", "d1_all", "density"]

#: Photometric columns the reports show for pairs without ground truth (MSE is left out:
#: PSNR is MSE on a log scale).
SHOWN_PHOTOMETRIC_COLUMNS = ["psnr", "ssim", "coverage"]


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
        ``warnings`` list (e.g. "the pair may be unrectified or swapped");
        ``columns``: the metric keys every report of these rows shows, then ``time_s``
        (:func:`shown_columns`).

    Raises
    ------
    ValueError
        When a row's ``status`` is not one of :data:`STATUSES`.
    """
    rows = [checked_row(row) for row in rows]
    families = sorted({family_of(row) for row in rows})
    return {
        "counts": {
            **{status: sum(row["status"] == status for row in rows) for status in STATUSES},
            "total": len(rows),
        },
        "overall": summarize_group(rows),
        "families": {
            family: summarize_group([row for row in rows if family_of(row) == family])
            for family in families
        },
        "failures": [
            {"pair": row["pair"], "family": family_of(row), "error": row.get("error") or ""}
            for row in rows
            if row["status"] == "failed"
        ],
        "skipped": [
            {"pair": row["pair"], "family": family_of(row), "reason": row.get("error") or ""}
            for row in rows
            if row["status"] == "skipped"
        ],
        "warnings": [
            {"pair": row["pair"], "family": family_of(row), "warning": str(text)}
            for row in rows
            for text in (row.get("warnings") or [])
        ],
        "columns": shown_columns(rows),
    }


def shown_columns(rows: Iterable[Mapping]) -> list[str]:
    """The columns the terminal, summary.md and report.html show for ``rows``, in order.

    The ground-truth columns (:data:`SHOWN_GT_COLUMNS`) when some ok pair has ground truth
    (a numeric EPE); the photometric ones (:data:`SHOWN_PHOTOMETRIC_COLUMNS`) when some ok
    pair without ground truth has photometric scores, so a batch mixing road sequences with
    benchmark pairs shows both; of each set only the columns some ok pair has a value for;
    then ``time_s``, always.  An unscored run (no ``--eval``) shows time alone.
    """
    ok = [row for row in rows if row.get("status") == "ok"]
    with_gt = [row for row in ok if as_number(row.get("epe")) is not None]
    without_gt = [row for row in ok if as_number(row.get("epe")) is None]

    def present(keys: list[str], some: list[Mapping]) -> list[str]:
        return [key for key in keys if any(as_number(row.get(key)) is not None for row in some)]

    return [*present(SHOWN_GT_COLUMNS, with_gt), *present(SHOWN_PHOTOMETRIC_COLUMNS, without_gt), "time_s"]


def columns_of(summary: Mapping) -> list[str]:
    """``summary["columns"]``; for a summary without them (an older summary.json), the same
    choice made from the overall means."""
    if summary.get("columns"):
        return list(summary["columns"])
    overall = summary["overall"]
    means = overall["means"]
    gt = [key for key in SHOWN_GT_COLUMNS if means.get(key) is not None] if overall["with_gt"] else []
    photometric = ([key for key in SHOWN_PHOTOMETRIC_COLUMNS if means.get(key) is not None]
                   if overall["ok"] > overall["with_gt"] else [])
    return [*gt, *photometric, "time_s"]


def problems_sentence(summary: Mapping) -> str:
    """The per-pair warnings and errors counted: ``3 warnings on 1 pair, 1 error.`` (an
    error: a failed pair's message); ``No warnings, no errors.`` when there are none."""
    n_warnings = len(summary.get("warnings") or [])
    warned = len({item["pair"] for item in summary.get("warnings") or []})
    n_errors = len(summary.get("failures") or [])
    if not n_warnings and not n_errors:
        return "No warnings, no errors."
    text = plural(n_warnings, "warning") + (f" on {plural(warned, 'pair')}" if n_warnings else "")
    return f"{text}, {plural(n_errors, 'error')}."


def checked_row(row: Mapping) -> dict:
    """A copy of ``row``; ValueError when its ``status`` is not one of :data:`STATUSES`."""
    status = row.get("status", "")
    if status not in STATUSES:
        raise ValueError(
            f"pair {row.get('pair')!r}: status is {status!r}; expected one of {', '.join(STATUSES)}"
        )
    return dict(row)


def family_of(row: Mapping) -> str:
    """The row's family; :data:`NO_FAMILY` when it has none."""
    return row.get("family") or NO_FAMILY


def summarize_group(rows: list[dict]) -> dict:
    """Counts and means of one group of rows, as in :func:`summarize`'s ``overall``."""
    ok = [row for row in rows if row["status"] == "ok"]
    return {
        "pairs": len(rows),
        "ok": len(ok),
        "failed": sum(row["status"] == "failed" for row in rows),
        "skipped": sum(row["status"] == "skipped" for row in rows),
        "with_gt": sum(as_number(row.get("epe")) is not None for row in ok),
        "means": {key: _mean(as_number(row.get(key)) for row in ok) for key in MEAN_KEYS},
    }


def as_number(value) -> float | None:
    """A row value as float; ``None`` for "not measured" (None, empty, NaN)."""
    if value is None or value == "":
        return None
    number = float(value)
    return None if math.isnan(number) else number


def _mean(values: Iterable[float | None]) -> float | None:
    present = [v for v in values if v is not None]
    # math.fsum: exact sum, so a mean does not depend on the order of the pairs.
    return math.fsum(present) / len(present) if present else None

