"""Tables of summaries: ``summary.md`` (Markdown), the side-by-side comparison, the terminal.

Every table shows the columns :func:`~d3cli.evaluation.summary.shown_columns` chooses, named
``name [unit]`` as :mod:`.definitions` names them, so the terminal, summary.md and
report.html cannot disagree; ``n/a`` where a value is missing (never zero).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

from ..errors import plural
from .definitions import HUGE, MEANS, METRICS, WITHOUT_GT, pixels_note
from .summary import (
    SHOWN_GT_COLUMNS,
    SHOWN_PHOTOMETRIC_COLUMNS,
    as_number,
    checked_row,
    columns_of,
    family_of,
    problems_sentence,
    summarize,
    summarize_group,
)

#: Column names with units ("EPE [px]"), as every report names them (:mod:`.definitions`).
LABELS = {key: m.label for key, m in METRICS.items()}

#: Decimals shown per key: 3 for EPE (px), 2 for percentages.
DECIMALS = {key: m.decimals for key, m in METRICS.items()}

MISSING = "n/a"


def count_heads(keys: Iterable[str]) -> list[str]:
    """Heads of the count columns of the per-family tables (terminal, summary.md,
    report.html): ``ok``, then ``with gt`` (the ok pairs scored against ground truth) when
    a ground-truth column is among ``keys`` (an unscored run would read "with gt 0")."""
    return ["ok", "with gt"] if any(key not in WITHOUT_GT for key in keys) else ["ok"]


def count_cells(group: Mapping, keys: Iterable[str]) -> list[str]:
    """The cells under :func:`count_heads` for one family's (or the overall) summary group."""
    return [str(group["ok"]), str(group["with_gt"])][:len(count_heads(keys))]


def label(key: str) -> str:
    """The column head of ``key``: its name with the unit ("EPE [px]"); an unknown key as is."""
    return LABELS.get(key, key)


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
        Markdown.  Columns: ``summary["columns"]`` (:func:`~d3cli.evaluation.summary.shown_columns`).
    """
    rows = [checked_row(row) for row in rows]
    keys = columns_of(summary)
    problems = problems_sentence(summary)
    if summary.get("warnings"):
        problems += " Each warning is listed under Warnings below."
    lines = [
        f"# Evaluation: {summary.get('method', '')}".rstrip(),
        "",
        counts_sentence(summary),
        "",
        problems,
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
    note = pixels_note(keys)
    lines += ["", "## Definitions", "", *([note, ""] if note else [])]
    lines += [f"- **{label(key)}**: {METRICS[key].definition}" for key in keys if key in METRICS]
    return "\n".join(lines) + "\n"


def counts_sentence(summary: Mapping) -> str:
    """``6 pairs: 4 ok, 1 failed, 1 skipped.`` (``1 pair: ...``); after a ``d3stereo run`` (``summary["run"]``)
    the ok pairs are split as run.json counts them: ``6 pairs: 6 ok (2 computed, 4 skipped
    as complete), 0 failed.`` ("skipped" there means kept from an earlier run, never left
    out)."""
    counts = summary["counts"]
    run = summary.get("run")
    total = plural(counts["total"], "pair")
    if run is None:
        return f"{total}: {counts['ok']} ok, {counts['failed']} failed, {counts['skipped']} skipped."
    text = (f"{total}: {counts['ok']} ok ({run['n_computed']} computed, {run['n_skipped']} "
            f"skipped as complete), {counts['failed']} failed")
    if counts["skipped"]:
        text += f", {counts['skipped']} left out"
    return text + "."


def _family_table(rows: list[dict], group: Mapping, keys: list[str]) -> list[str]:
    """One line per pair (a pair with warnings: ``ok, 2 warnings``), then the family's mean line."""
    body = [
        [_md_escape(row["pair"]), _status(row), *(_format_value(k, row.get(k)) for k in keys)]
        for row in rows
    ]
    means = group["means"]
    body.append(["**mean**", f"{group['ok']} ok", *(_format_value(k, means.get(k)) for k in keys)])
    header = ["pair", "status", *(label(k) for k in keys)]
    return _markdown_table(header, body, n_text_columns=2)


def _overall_table(summary: Mapping, keys: list[str]) -> list[str]:
    """One line of means per family, then the overall means."""
    groups = [*summary["families"].items(), ("**overall**", summary["overall"])]
    body = [
        [
            _md_escape(family),
            *count_cells(group, keys),
            *(_format_value(k, group["means"].get(k)) for k in keys),
        ]
        for family, group in groups
    ]
    header = ["family", *count_heads(keys), *(label(k) for k in keys)]
    return _markdown_table(header, body, n_text_columns=1)


def _status(row: Mapping) -> str:
    """The status cell: ``ok``, or ``ok, 2 warnings`` beside a pair with warnings."""
    n = len(row.get("warnings") or [])
    return f"{row['status']}, {plural(n, 'warning')}" if n else str(row["status"])


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
        are not comparable, so the count stands first), the ground-truth columns
        every report shows (EPE, PEP 0.5/1/2, D1 (all), density) when some method has
        ground-truth scores in that family, the photometric ones (PSNR, SSIM,
        coverage) when some method has ok pairs without ground truth there that have
        them, and time.  ``n/a`` where a method has no value (e.g. all its pairs of
        that family failed).
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
            ["", label(key), *(_format_value(key, g["means"].get(key)) for g in by_method)]
            for key in _keys_with_values(by_method)
        ]
    header = ["family", "metric", *(_md_escape(method) for method in summaries)]
    return "\n".join(_markdown_table(header, body, n_text_columns=2)) + "\n"


def _keys_with_values(groups: list[Mapping]) -> list[str]:
    """Side-by-side metric rows of one family, chosen as :func:`~d3cli.evaluation.summary.shown_columns`
    chooses them: ground-truth columns some method has, photometric ones where some method
    has ok pairs without ground truth, then time."""

    def present(key: str, some: list[Mapping]) -> bool:
        return any(group["means"].get(key) is not None for group in some)

    without_gt = [group for group in groups if group["ok"] > group["with_gt"]]
    keys = [key for key in SHOWN_GT_COLUMNS if present(key, groups)]
    keys += [key for key in SHOWN_PHOTOMETRIC_COLUMNS if present(key, without_gt)]
    return [*keys, "time_s"]


def _markdown_table(header: list[str], body: list[list[str]], *, n_text_columns: int) -> list[str]:
    """Lines of a Markdown table; the first ``n_text_columns`` left-aligned, numbers right."""
    align = ["---"] * n_text_columns + ["---:"] * (len(header) - n_text_columns)
    return ["| " + " | ".join(cells) + " |" for cells in (header, align, *body)]


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
        A line with the counts, then the table of summary.md's "Overall" section: one line
        per family and ``overall`` with the ok pairs, the pairs with ground truth
        (:func:`count_heads`) and the columns of ``summary["columns"]`` under the same heads ("EPE [px]"); then one line
        per failed pair, and one line counting the warnings and naming their pairs.
    """
    groups = [*summary["families"].items(), ("overall", summary["overall"])]
    keys = columns_of(summary)
    header = ["family", *count_heads(keys), *(label(key) for key in keys)]
    body = [
        [
            family,
            *count_cells(group, keys),
            *(_format_value(key, group["means"].get(key)) for key in keys),
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
        f"of {plural(counts['total'], 'pair')}",
        render(header),
        *(render(cells) for cells in body),
    ]
    lines += [f"failed {item['pair']}: {one_line(item['error'])}" for item in summary["failures"]]
    warnings = summary.get("warnings") or []
    if warnings:
        # The texts were logged as each pair finished; here they are counted, with their pairs.
        pairs = list(dict.fromkeys(item["pair"] for item in warnings))
        names = ", ".join(pairs[:5]) + (f" and {len(pairs) - 5} more" if len(pairs) > 5 else "")
        lines.append(f"{plural(len(warnings), 'warning')} on {plural(len(pairs), 'pair')}: {names} "
                     "(each pair's warnings are in report.html and its result.json)")
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

