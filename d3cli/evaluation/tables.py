"""Tables of summaries: ``summary.md`` (Markdown), the side-by-side comparison, the terminal.

Columns are the metrics that some pair has a value for, then time; ``n/a`` where a value
is missing (never zero).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from .definitions import EVALUATED, HUGE, MEANS, METRICS
from .summary import (
    DISPARITY_COLUMNS,
    METRIC_COLUMNS,
    PHOTOMETRIC_COLUMNS,
    as_number,
    checked_row,
    family_of,
    summarize,
    summarize_group,
)

#: Column names with units ("EPE [px]"), as report.html names them too (:mod:`.definitions`).
LABELS = {key: m.label for key, m in METRICS.items()}

#: Short labels for the fixed-width terminal table.
SHORT_LABELS = {key: m.short for key, m in METRICS.items()}

#: Decimals shown per key: 3 for EPE (px), 2 for percentages.
DECIMALS = {key: m.decimals for key, m in METRICS.items()}

MISSING = "n/a"


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
    rows = [checked_row(row) for row in rows]
    keys = _columns_with_values(rows)
    lines = [
        f"# Evaluation: {summary.get('method', '')}".rstrip(),
        "",
        counts_sentence(summary),
        "",
        f"{MEANS} The columns are defined at the end.",
        "",
    ]
    for family, group in summary["families"].items():
        family_rows = [row for row in rows if family_of(row) == family]
        lines += [f"## {family}", "", *_family_table(family_rows, group, keys), ""]
    lines += ["## Overall", "", *_overall_table(summary, keys), ""]
    lines += ["## Failed pairs", ""]
    failures = [f"- {item['pair']}: {one_line(item['error'])}" for item in summary["failures"]]
    lines += failures or ["None."]
    if summary.get("skipped"):
        lines += ["", "## Skipped pairs", ""]
        lines += [f"- {item['pair']}: {one_line(item['reason'])}" for item in summary["skipped"]]
    if summary.get("warnings"):
        lines += ["", "## Warnings", "", "Maps of these pairs may be wrong; see each pair's result.json.", ""]
        lines += [f"- {item['pair']}: {one_line(item['warning'])}" for item in summary["warnings"]]
    lines += ["", "## Definitions", "", EVALUATED, ""]
    lines += [f"- **{LABELS[key]}**: {METRICS[key].definition}" for key in keys]
    return "\n".join(lines) + "\n"


def counts_sentence(summary: Mapping) -> str:
    """``6 pairs: 4 ok, 1 failed, 1 skipped.``; after a ``d3stereo run`` (``summary["run"]``)
    the ok pairs are split as run.json counts them: ``6 pairs: 6 ok (2 computed, 4 skipped
    as complete), 0 failed.`` ("skipped" there means kept from an earlier run, never left
    out)."""
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
    empty_group = summarize_group([])
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
        key for key in METRIC_COLUMNS if any(as_number(row.get(key)) is not None for row in rows)
    ]
    return [*present, "time_s"]


def _md_escape(text: str) -> str:
    return str(text).replace("|", "\\|")


def one_line(text: str) -> str:
    """``text`` on one line: every run of whitespace one space."""
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
    lines += [f"failed {item['pair']}: {one_line(item['error'])}" for item in summary["failures"]]
    return "\n".join(lines)


def _format_value(key: str, value) -> str:
    number = as_number(value)
    if number is None:
        return MISSING
    if math.isinf(number):
        return "inf" if number > 0 else "-inf"
    if abs(number) >= HUGE:
        return f"{number:.3e}"
    return f"{number:.{DECIMALS.get(key, 3)}f}"

