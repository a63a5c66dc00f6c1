"""``report.html``: one static, self-contained page of a batch (inline CSS/JS, no network).

The page a user opens after a run, so it holds everything the other outputs say: at the
top the counts and every per-pair warning and error counted (linked to their lists);
the pair table (click a head to sort) with each pair's warnings or error beside it; the
means per family; a histogram of the per-pair error (inline SVG); every pair's panel as a
thumbnail sorted by error (worst first) linking to the full images; the definitions of
the columns shown (no others); the config and the versions.  The columns, their names
and units are those of summary.md and the terminal
(:func:`d3cli.evaluation.summary.shown_columns`).  A run without ``--eval`` is said to be
unscored, with the number of pairs that have ground truth and the flag that scores them.
Links are relative and point only to files that exist when the page is written.

After ``--road-report`` (a pair folder holds ``defects.json``, :mod:`d3cli.road.outputs`)
the page has a "Road inspection" section, read from those files: the batch totals, the
survey summary of ``road_survey.json``, the defects against the pothole ground truth where
a pair has one (``defects_gt.json`` and ``potholes_gt.png`` beside its left image, as
``d3stereo synth`` writes them), then per pair (deepest pothole first) a ``defects.png``
thumbnail and a table of its defects (with each pothole's ASTM D6433 severity).
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from urllib.parse import quote

import cv2
import numpy as np

from ..data.formats import atomic_write
from .definitions import MEANS, metric, pixels_note
from ..errors import readable
from .report import jsonable
from ..errors import plural
from .summary import summarize
from .tables import HUGE, count_cells, count_heads, counts_sentence, one_line

REPORT_FILE = "report.html"

#: A pair's result.json (d3cli.batch writes it; read here, not imported: the evaluation
#: room does not depend on the batch): ``inputs`` names the pair's files.
RESULT_JSON = "result.json"

#: Pictures linked from a pair's card when they exist, in this order.
PAIR_PICTURES = ("panel.png", "disp_color.png", "error.png", "valid_overlay.png")

#: Figures named on a pair's card, the first ones of these the table shows.
CARD_FIGURES = ("epe", "d1_all", "psnr")

_CSS = """
body{font:15px/1.45 system-ui,sans-serif;margin:1.5em auto;max-width:1500px;padding:0 1.5em;color:#222}
h2{margin-top:1.6em;border-bottom:1px solid #ddd}
.scroll{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;margin:.5em 0}
td,th{border:1px solid #ccc;padding:3px 7px;text-align:right;vertical-align:top}
th{background:#eee;cursor:pointer}th.t,td.t{text-align:left}td.t{white-space:nowrap}table.figures th{white-space:nowrap}
td.msg{text-align:left;font-size:13px;padding-left:2em}td.msg ul{margin:0;padding-left:1.2em}
tr.warned td{background:#fff6dc}tr.failed td{background:#fde8e8;color:#900}
.problems{padding:.5em .8em;border-left:5px solid #999;background:#f4f4f4;font-weight:bold}
.problems.warned{border-color:#d98e00;background:#fff6dc}.problems.failed{border-color:#c00;background:#fde8e8}
.note{padding:.5em .8em;border-left:5px solid #4575b4;background:#eef3fa}
.cards{display:flex;flex-wrap:wrap;gap:12px}.card{width:420px}.card img{width:100%;border:1px solid #999}
.warn{color:#a60;font-weight:bold}.card.road{width:100%}.card.road img{width:auto;max-width:min(100%,720px)}
.card.road table{font-size:13px}.low{color:#b60}
.failed{color:#b00}dt{font-weight:bold}dd{margin:0 0 .4em 1.5em}pre{background:#f6f6f6;padding:.5em;max-height:30em;overflow:auto}
"""

_JS = """
document.querySelectorAll('table.sortable th').forEach(function(th,i){th.onclick=function(){
var t=th.closest('table'),g=t.classList.contains('grouped'),b=g?t:t.tBodies[0],r=Array.from(g?t.tBodies:b.rows);
var d=th.dataset.d==='1'?-1:1;th.dataset.d=d===1?'1':'0';function v(x){var c=(g?x.rows[0]:x).cells[i];return c.dataset.v||c.textContent;}
r.sort(function(x,y){var a=v(x),c=v(y),p=parseFloat(a),q=parseFloat(c);
if(!isNaN(p)&&!isNaN(q))return d*(p-q);if(isNaN(p)!==isNaN(q))return isNaN(p)?1:-1;return d*a.localeCompare(c);});
r.forEach(function(e){b.appendChild(e);});};});
"""


def _num(value) -> float | None:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) else None


def _fmt(value, key: str | None = None) -> str:
    """A table cell: the metric's decimals (3 for an unknown key, 1 from 100 on); empty when missing."""
    v = _num(value)
    if v is None:
        return ""
    if abs(v) >= HUGE:
        return f"{v:.3e}"
    return f"{v:.{metric(key).decimals if key else 3 if abs(v) < 100 else 1}f}"


def sort_key(row: Mapping) -> tuple:
    """Worst first: by EPE, else D1, else negative PSNR; pairs without a figure last."""
    for key, sign in (("epe", -1), ("d1_all", -1), ("psnr", 1)):
        v = _num(row.get(key))
        if v is not None:
            return (0, sign * v)
    return (1, 0.0)


def _bin_of(value: float, lo: float, hi: float, bins: int) -> int:
    """Bin (0 .. bins - 1) of ``value`` in ``bins`` equal bins over [lo, hi]; all in the middle one when lo == hi.

    Halves are compared so that ``hi - lo`` cannot overflow (values of +-1.7e308), and no
    width is added to an empty range (``lo + 1.0 == lo`` from 1e16 on).
    """
    span = hi / 2 - lo / 2
    if not span > 0:
        return bins // 2
    return min(bins - 1, int((value / 2 - lo / 2) / span * bins))


def histogram_svg(values: list[float], *, label: str, bins: int = 12, width: int = 480, height: int = 160) -> str:
    """Inline SVG bar chart of the finite ``values`` (``bins`` equal bins between min and max)."""
    values = [float(v) for v in values if math.isfinite(float(v))]
    if not values:
        return f"<p>No per-pair {html.escape(label)} to plot.</p>"
    lo, hi = min(values), max(values)
    counts = [0] * bins
    for v in values:
        counts[_bin_of(v, lo, hi, bins)] += 1
    top = max(counts)
    bar_w = (width - 40) / bins
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height + 34}" role="img">']
    for i, c in enumerate(counts):
        h = (height - 10) * c / top
        x = 30 + i * bar_w
        # Bounds as lo + i (hi - lo) / bins, in halves (no overflow).
        a, b = (2 * (lo / 2 + k * (hi / 2 - lo / 2) / bins) for k in (i, i + 1))
        parts.append(f'<rect x="{x:.1f}" y="{height - h:.1f}" width="{bar_w - 2:.1f}" height="{h:.1f}" fill="#4575b4">'
                     f'<title>{a:.3g}-{b:.3g}: {c}</title></rect>')
    parts.append(f'<text x="30" y="{height + 15}" font-size="13">{lo:.3g}</text>')
    parts.append(f'<text x="{width - 10}" y="{height + 15}" font-size="13" text-anchor="end">{hi:.3g}</text>')
    parts.append(f'<text x="{width / 2}" y="{height + 30}" font-size="13" text-anchor="middle">'
                 f'{html.escape(label)} (pairs per bin, max {top})</text></svg>')
    return "".join(parts)


def report_html(out_dir: str | Path, rows: Iterable[Mapping], *, title: str,
                config: Mapping | None = None, versions: Mapping | None = None,
                run_counts: Mapping | None = None) -> str:
    """The page's text for the pair rows of a batch whose pair folders lie in ``out_dir``.

    ``run_counts`` (``n_computed``, ``n_skipped``, ``n_failed`` of run.json) splits the
    ok pairs into computed and kept from an earlier run, as summary.md does.  ``config``
    (the run's resolved config) gives ``road.min_depth_mm``, the depth from which a
    ground-truth pothole counts (10 mm without it).
    """
    out_dir = Path(out_dir)
    rows = [dict(r) for r in rows]
    summary = summarize(rows)
    if run_counts is not None:
        summary["run"] = {key: int(run_counts[key]) for key in ("n_computed", "n_skipped", "n_failed")}
    columns = summary["columns"]
    e = html.escape
    out = [f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>'
           f"<style>{_CSS}</style></head><body><h1>{e(title)}</h1>"]
    out.append(f"<p>{e(counts_sentence(summary))} Every column is defined "
               '<a href="#definitions">below</a>; click a column head to sort.</p>')
    out.append(problems_html(summary))
    out.extend(_scoring_note(out_dir, rows, columns))
    out.extend(_pairs_table(out_dir, rows, columns))
    # Family means: the table of summary.md's "Overall" section and of the terminal.
    out.append('<h2>Means per family</h2><div class="scroll"><table class="sortable figures"><thead><tr>'
               '<th class="t">family</th>'
               + "".join(f"<th>{h}</th>" for h in count_heads(columns)) + "".join(_head(c) for c in columns)
               + "</tr></thead><tbody>")
    groups = [*summary["families"].items(), ("overall", summary["overall"])]
    for name, group in groups:
        out.append(f'<tr><td class="t">{e(name)}</td>' + "".join(f"<td>{c}</td>" for c in count_cells(group, columns))
                   + "".join(f"<td>{_fmt(group['means'].get(c), c)}</td>" for c in columns) + "</tr>")
    out.append("</tbody></table></div>")
    key = next((k for k in ("epe", "psnr") if k in columns), None)
    if key is not None:
        values = [_num(r.get(key)) for r in rows if _num(r.get(key)) is not None]
        label = metric(key).label
        out.append(f"<h2>Histogram of per-pair {e(label)}</h2>" + histogram_svg(values, label=label))
    out.extend(failed_section(summary))
    out.extend(warnings_section(summary))
    min_depth = _num(((config or {}).get("road") or {}).get("min_depth_mm"))
    out.extend(road_section(out_dir, rows, min_depth_mm=10.0 if min_depth is None else min_depth))
    out.extend(_cards(out_dir, rows, columns))
    out.extend(definitions_section(columns))
    out.append("<h2>Config</h2><pre>" + e(json.dumps(jsonable(config or {}), indent=2, sort_keys=True)) + "</pre>")
    out.append("<h2>Versions</h2><pre>" + e(json.dumps(jsonable(versions or {}), indent=2, sort_keys=True)) + "</pre>")
    out.append(f"<script>{_JS}</script></body></html>\n")
    return "\n".join(out)


def problems_html(summary: Mapping) -> str:
    """The line at the top that counts the per-pair warnings and errors, each count linking
    to its list: ``3 warnings on 1 pair, 1 error.`` (the words of
    :func:`~d3cli.evaluation.summary.problems_sentence`)."""
    warnings, failures = summary.get("warnings") or [], summary.get("failures") or []
    if not warnings and not failures:
        return '<p class="problems">No warnings, no errors.</p>'
    n_pairs = len({item["pair"] for item in warnings})
    counted = plural(len(warnings), "warning")
    text = (f'<a href="#warnings">{counted}</a> on {plural(n_pairs, "pair")}' if warnings else counted)
    errors = plural(len(failures), "error")
    text += f', <a href="#failures">{errors}</a>' if failures else f", {errors}"
    cls = "failed" if failures else "warned"
    return f'<p class="problems {cls}">{text}. Each is shown beside its pair below.</p>'


def _pair_inputs(out_dir: Path, pair: str) -> dict:
    """``inputs`` of the pair's result.json (left, right, gt paths); {} when unreadable."""
    try:
        inputs = json.loads((out_dir / pair / RESULT_JSON).read_text(encoding="utf-8")).get("inputs")
    except (OSError, ValueError, AttributeError):
        return {}
    return inputs if isinstance(inputs, dict) else {}


def _scoring_note(out_dir: Path, rows: list[dict], columns: list[str]) -> list[str]:
    """When no ok pair has a score (a run without ``--eval``): a note that says so, how many
    pairs have ground truth (their result.json names it) and which flag scores them."""
    ok = [r for r in rows if r.get("status") == "ok"]
    if not ok or columns != ["time_s"]:
        return []
    with_gt = sum(bool(_pair_inputs(out_dir, r["pair"]).get("gt")) for r in ok)
    if with_gt:
        text = (f"Not scored: this run was made without --eval, although {with_gt} of {plural(len(ok), 'ok pair')} "
                f"{'has' if with_gt == 1 else 'have'} ground truth. Run the same command again with --eval "
                "to score them: the maps are kept, only the scores are computed.")
    else:
        text = ("Not scored: this run was made without --eval, and no pair has ground truth; --eval "
                "would add photometric scores (PSNR, SSIM, coverage).")
    return [f'<p class="note">{html.escape(text)}</p>']


def _pairs_table(out_dir: Path, rows: list[dict], columns: list[str]) -> list[str]:
    """HTML of the "Pairs" table: name (linking to its card), family, status (linking to its
    message; ``ok, 2 warnings``), the figures; right under a pair with warnings or an error
    a row across the table with them in full.  Each pair is one ``<tbody>``, so sorting
    keeps its message under it."""
    e = html.escape
    out: list[str] = []
    out.append('<h2 id="pairs">Pairs</h2><div class="scroll"><table class="sortable figures grouped"><thead><tr>'
               '<th class="t">pair</th><th class="t">family</th><th class="t">status</th>'
               + "".join(_head(c) for c in columns) + "</tr></thead>")
    for r in rows:
        status, warnings = str(r.get("status")), [one_line(str(w)) for w in r.get("warnings") or []]
        cls = ' class="failed"' if status == "failed" else ' class="warned"' if warnings else ""
        cells = "".join(f'<td data-v="{_num(r.get(c)) if _num(r.get(c)) is not None else ""}">{_fmt(r.get(c), c)}</td>'
                        for c in columns)
        link = f'<a href="#{e(r["pair"])}">{e(r["pair"])}</a>' if (out_dir / r["pair"]).is_dir() else e(r["pair"])
        shown = e(status) + (f", {plural(len(warnings), 'warning')}" if warnings else "")
        if status in ("failed", "skipped"):  # the message is listed below the tables too
            shown = f'<a href="#{"failures" if status == "failed" else "skipped"}">{shown}</a>'
        if warnings:
            message = "<ul>" + "".join(f"<li>{e(w)}</li>" for w in warnings) + "</ul>"
        else:
            message = e(_own_message(r["pair"], r.get("error") or "")) if status != "ok" else ""
        under = f'<tr{cls}><td class="msg" colspan="{3 + len(columns)}">{message}</td></tr>' if message else ""
        out.append(f'<tbody><tr{cls}><td class="t">{link}</td><td class="t">{e(str(r.get("family") or ""))}</td>'
                   f'<td class="t">{shown}</td>{cells}</tr>{under}</tbody>')
    out.append("</table></div>")
    return out


def _own_message(pair: str, text: str) -> str:
    """``text`` on one line, without the pair's name and colon in front (the pair is named beside it)."""
    text = one_line(text)
    return text[len(pair) + 2:] if text.startswith(f"{pair}: ") else text


def _head(key: str) -> str:
    """A column head: the name with its unit, the definition as its tooltip."""
    m = metric(key)
    return f'<th title="{html.escape(m.definition)}">{html.escape(m.label)}</th>'


def _cards(out_dir: Path, rows: list[dict], columns: list[str]) -> list[str]:
    """The thumbnails, worst first: name, the figures of :data:`CARD_FIGURES` shown, the
    pair's warnings counted, its panel linking to the full pictures."""
    e = html.escape
    out = ['<h2>Pairs by error (worst first)</h2><div class="cards">']
    figures = [c for c in CARD_FIGURES if c in columns]
    for r in sorted(rows, key=sort_key):
        folder = out_dir / r["pair"]
        pics = [p for p in PAIR_PICTURES if (folder / p).is_file()]
        figure = ", ".join(f"{metric(c).name} {metric(c).format(_num(r.get(c)))}" for c in figures
                           if _num(r.get(c)) is not None)
        out.append(f'<div class="card" id="{e(r["pair"])}"><b>{e(r["pair"])}</b> {e(figure)}'
                   f'{_warned(len(r.get("warnings") or []))}<br>')
        if pics:
            thumb = f"{r['pair']}/{pics[0]}"
            href = e(quote(thumb))
            out.append(f'<a href="{href}"><img loading="lazy" src="{href}" alt="{e(r["pair"])}"></a><br>')
            out.append(" ".join(f'<a href="{e(quote(r["pair"] + "/" + p))}">{p}</a>' for p in pics))
        else:
            out.append(f"<i>{e(str(r.get('error') or 'no pictures'))}</i>")
        out.append("</div>")
    out.append("</div>")
    return out


def failed_section(summary: Mapping) -> list[str]:
    """HTML listing every failed pair with its error, and every left-out pair with its reason; [] when none."""
    e = html.escape
    parts = []
    for key, title, field in (("failures", "Failed pairs", "error"), ("skipped", "Left-out pairs", "reason")):
        items = summary.get(key) or []
        if items:
            parts.append(f'<h2 id="{key}">{title}</h2><ul class="failed">')
            for item in items:
                pair = str(item["pair"])
                parts.append(f"<li><b>{e(pair)}</b>: {e(_own_message(pair, item[field] or 'no message'))}</li>")
            parts.append("</ul>")
    return parts


def warnings_section(summary: Mapping) -> list[str]:
    """HTML listing every pair's warnings (the maps of these pairs may be wrong); [] when none."""
    e = html.escape
    by_pair: dict[str, list[str]] = {}
    for item in summary.get("warnings") or []:
        by_pair.setdefault(str(item["pair"]), []).append(one_line(item["warning"]))
    if not by_pair:
        return []
    parts = ['<h2 id="warnings">Warnings</h2><p>The maps of these pairs may be wrong; each pair\'s '
             "result.json keeps its warnings.</p><ul>"]
    for pair, texts in by_pair.items():
        parts.append(f"<li><b>{e(pair)}</b><ul>" + "".join(f"<li>{e(t)}</li>" for t in texts) + "</ul></li>")
    parts.append("</ul>")
    return parts


def definitions_section(keys: Iterable[str]) -> list[str]:
    """HTML of the "Definitions" section: the pixels the figures are computed over (when a
    ground-truth column is shown), the means, then each column of ``keys`` (the columns
    shown, no others)."""
    e = html.escape
    keys = list(dict.fromkeys(keys))
    note = pixels_note(keys)
    parts = ['<h2 id="definitions">Definitions</h2>', f"<p>{e(note + ' ' if note else '')}{e(MEANS)}</p><dl>"]
    for key in keys:
        m = metric(key)
        if m.definition:
            parts.append(f"<dt>{e(m.label)}</dt><dd>{e(m.definition)}</dd>")
    parts.append("</dl>")
    return parts


#: Per-pair road files (d3cli.road.outputs writes them; read here, not imported: the
#: evaluation room does not depend on the road room).
ROAD_JSON, ROAD_PICTURES = "defects.json", ("defects.png", "height_color.png")
#: The batch's survey summary (d3cli.road.severity.survey_summary, written beside defects.csv).
ROAD_SURVEY = "road_survey.json"
#: Pothole ground truth beside a pair's left image, as ``d3stereo synth`` writes it: each
#: pothole's figures, and its id at every left-image pixel it lowers (0 elsewhere).
ROAD_TRUTH, ROAD_TRUTH_IDS = "defects_gt.json", "potholes_gt.png"
#: Share of a detected pothole's pixels that must lie on ground-truth pothole pixels for
#: it to stand for a pothole; below it the detection is a false one.
ON_POTHOLE = 0.5
#: How the page matches detections with the ground truth, in words.
TRUTH_RULE = ("A detected pothole (its outline's pixels) stands for the ground-truth pothole holding most "
              f"of its pixels (potholes_gt.png) when at least {100 * ON_POTHOLE:.0f} % of them lie on "
              "potholes; each ground-truth pothole is found by at most one detection, the one with most "
              "pixels on it; other detections on a pothole are extra (fragments), detections mostly off "
              "potholes are false. Counted: the ground-truth potholes deeper than {min_depth:g} mm "
              "(road.min_depth_mm, the depth from which the report looks) and visible in the left image. "
              "Depth error: (measured - true) / true depth. scripts/bench_road.py scores with the stricter "
              "rule of docs/road.md.")


def _road_reports(out_dir: Path, rows: list[dict]) -> list[tuple[str, dict | None, str]]:
    """(pair, defects.json contents or None, why none) for the pairs of ``rows``."""
    found = []
    for r in rows:
        path = out_dir / r["pair"] / ROAD_JSON
        if not path.is_file():
            found.append((r["pair"], None, "failed" if r.get("status") == "failed" else "no road report"))
            continue
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            data["defects"] = list(data.get("defects") or [])
        except (OSError, ValueError, TypeError, AttributeError) as exc:
            found.append((r["pair"], None, f"unreadable {ROAD_JSON}: {exc}"))
            continue
        found.append((r["pair"], data, ""))
    return found


def detection_mask(d: Mapping, shape) -> np.ndarray:
    """bool (H, W): a detection's pixels, its outline polygons filled (its bounding box without them)."""
    mask = np.zeros(shape, np.uint8)
    polys = [np.asarray(p, np.int32).reshape(-1, 1, 2) for p in d.get("outline_px") or [] if len(p)]
    if polys:
        cv2.fillPoly(mask, polys, 1)
        cv2.polylines(mask, polys, True, 1)
    elif d.get("bbox_px"):
        u0, v0, u1, v1 = (int(x) for x in d["bbox_px"])
        mask[max(v0, 0):v1 + 1, max(u0, 0):u1 + 1] = 1
    return mask.astype(bool)


def road_truth(out_dir: str | Path, pair: str, defects: list, *, min_depth_mm: float = 10.0) -> dict | None:
    """A pair's detected potholes against its pothole ground truth (:data:`TRUTH_RULE`).

    The ground truth is ``defects_gt.json`` and ``potholes_gt.png`` beside the pair's left
    image (its result.json names it); None when the pair has none or it is unreadable.

    Returns
    -------
    dict
        ``counted``: the ground-truth potholes counted (defects_gt.json entries);
        ``found``: ground-truth id -> the detection that found it; ``missed``: the counted
        ones nobody found; ``label``: detection id -> what it is ("#2", "extra (#2)",
        "false", "#4, not counted (5 mm deep)"); ``n_false``, ``n_extra``: detections;
        ``by_id``: every ground-truth pothole by id.
    """
    left = _pair_inputs(Path(out_dir), pair).get("left")
    if not left:
        return None
    folder = Path(left).parent
    try:
        truth = json.loads((folder / ROAD_TRUTH).read_text(encoding="utf-8"))["potholes"]
        by_id = {int(g["id"]): g for g in truth}
    except (OSError, ValueError, TypeError, KeyError):
        return None
    ids_file = folder / ROAD_TRUTH_IDS
    ids = cv2.imread(str(ids_file), cv2.IMREAD_UNCHANGED) if ids_file.is_file() else None
    if ids is None or ids.ndim != 2:
        return None
    counted = [g for g in truth if not g.get("part_of") and (_num(g.get("visible_px")) or 0) > 0
               and (_num(g.get("depth_mm")) or 0.0) > min_depth_mm]
    candidates = []  # (pixels on the pothole, detection index, ground-truth id)
    stands_for: dict[int, int] = {}
    pits = [d for d in defects if d.get("kind") == "pothole"]
    for i, d in enumerate(pits):
        mask = detection_mask(d, ids.shape)
        under = ids[mask]
        on = under[under > 0]
        if mask.any() and on.size >= ON_POTHOLE * mask.sum():
            values, counts = np.unique(on, return_counts=True)
            gid = int(values[np.argmax(counts)])
            stands_for[i] = gid
            candidates.append((int(counts.max()), i, gid))
    counted_ids = {int(g["id"]) for g in counted}
    found: dict[int, Mapping] = {}
    label: dict = {}
    taken = set()
    for _, i, gid in sorted(candidates, reverse=True):
        if gid not in found and gid in counted_ids:
            found[gid] = pits[i]
            taken.add(i)
            label[pits[i].get("id")] = f"#{gid}"
    n_false = n_extra = 0
    for i, d in enumerate(pits):
        if i in taken:
            continue
        gid = stands_for.get(i)
        if gid is None:
            n_false += 1
            label[d.get("id")] = "false"
        elif gid in counted_ids:
            n_extra += 1
            label[d.get("id")] = f"extra (#{gid})"
        else:  # on a pothole too shallow (or too hidden) to be counted: neither found nor false
            n_extra += 1
            label[d.get("id")] = f"#{gid}, not counted ({_num(by_id.get(gid, {}).get('depth_mm')) or 0.0:.0f} mm deep)"
    missed = [g for g in counted if int(g["id"]) not in found]
    return {"counted": counted, "found": found, "missed": missed, "label": label,
            "n_false": n_false, "n_extra": n_extra, "by_id": by_id}


def _depth_error(gt: Mapping, d: Mapping) -> float | None:
    """(measured - true) / true maximum depth, or None."""
    true, got = _num(gt.get("depth_mm")), _num(d.get("max_depth_mm"))
    return (got - true) / true if true and got is not None else None


def road_section(out_dir: str | Path, rows: Iterable[Mapping], *, min_depth_mm: float = 10.0) -> list[str]:
    """HTML of the "Road inspection" section; [] when no pair has a ``defects.json``.

    Batch totals (potholes, bumps, low-confidence ones, summed area and fill volume of the
    potholes, the deepest), the survey summary (``road_survey.json``: per frame, per km,
    per severity level), the detections against the pothole ground truth of the pairs
    that have one (:func:`road_truth`: per pair the potholes counted, found, missed with
    their depths, false and extra detections, the depth error), then one card per pair
    with defects, deepest pothole first: ``defects.png`` as a thumbnail (links to it and
    to ``height_color.png``) and a sortable table of id, kind, depth (bumps: height), mean
    depth, area, diameter, volume, ASTM D6433 severity, decided share, confidence and,
    with ground truth, the pothole each detection found; pairs without defects and pairs
    without a road report are listed by name.
    """
    out_dir = Path(out_dir)
    rows = [dict(r) for r in rows]
    reports = _road_reports(out_dir, rows)
    if not any(data is not None for _, data, _ in reports):
        return []
    e = html.escape
    done = [(pair, data) for pair, data, _ in reports if data is not None]
    warned = {r["pair"]: len(r.get("warnings") or []) for r in rows}
    truths = {pair: road_truth(out_dir, pair, data["defects"], min_depth_mm=min_depth_mm) for pair, data in done}
    parts = ['<h2 id="road">Road inspection</h2>',
             "<p>Depth: below the surrounding road surface (the median height of a ring of road "
             "around the defect); area: of the road plane covered; volume: to fill it up to the "
             "surrounding surface; decided: share of the defect's pixels the method decided itself "
             "(not filled); confidence: ok, or low with the reasons its depth is not trusted (weak match "
             "on little texture: a dark, smooth or wet floor; dark or noisy; few decided pixels; at the "
             "image border; possibly merged with a neighbour; re-match unreliable; narrower than the "
             "matching window, not re-matched; defects.json lists "
             "the numbers behind each).</p>",
             '<table><thead><tr><th>pairs with a road report</th><th>with defects</th><th>potholes</th>'
             "<th>bumps</th><th>flagged (low confidence)</th><th>pothole area [m²]</th><th>pothole volume [l]</th>"
             "<th>deepest pothole</th></tr></thead><tbody>",
             _road_totals_row(done, len(reports))]
    if (out_dir / "defects.csv").is_file():
        parts.append('<p>Every defect of the batch: <a href="defects.csv">defects.csv</a>.</p>')
    parts += _road_survey(out_dir)
    parts += road_map(out_dir)
    parts += _road_truth_table({p: t for p, t in truths.items() if t is not None}, len(done), min_depth_mm, warned)

    def deepest_of(data):
        return max((_num(d.get("max_depth_mm")) or 0.0 for d in data["defects"] if d.get("kind") == "pothole"),
                   default=0.0)

    with_defects = sorted(((p, d) for p, d in done if d["defects"]),
                          key=lambda pd: (-deepest_of(pd[1]), -len(pd[1]["defects"])))
    parts.append('<div class="cards">')
    for pair, data in with_defects:
        parts += _road_card(out_dir, pair, data, truths.get(pair), warned.get(pair, 0))
    parts.append("</div>")
    clean = [(p, d) for p, d in done if not d["defects"]]
    if clean:
        notes = [p + (f" ({'; '.join(map(str, d.get('warnings') or []))})" if d.get("warnings") else "") for p, d in clean]
        parts.append("<p>No defects: " + e(", ".join(notes)) + ".</p>")
    missing = [(p, why) for p, data, why in reports if data is None]
    if missing:
        parts.append("<p>No road outputs (no camera, not run with --road-report, or failed; see each "
                     "result.json): " + e(", ".join(f"{p} ({why})" for p, why in missing)) + ".</p>")
    return parts


def _warned(n_warnings: int) -> str:
    """A link to the warnings list counting a pair's warnings ("3 warnings": its map may be wrong); "" for none."""
    return f' <a class="warn" href="#warnings">{plural(n_warnings, "warning")}</a>' if n_warnings else ""


def _road_truth_table(truths: dict, n_reports: int, min_depth_mm: float, warned: Mapping) -> list[str]:
    """HTML of "Against the ground truth": one row per pair with pothole ground truth (its
    warnings counted beside its name), then the batch's totals; a line saying there is
    none when no pair has it."""
    e = html.escape
    if not truths:
        return ['<p id="road-truth">No pair has pothole ground truth (defects_gt.json and potholes_gt.png '
                "beside its left image, as d3stereo synth writes them): the defects are not scored.</p>"]
    cols = ("pair", "potholes in ground truth", "found", "missed (true depth)", "false detections",
            "extra detections", "median |depth error| [%]")
    parts = [f'<h3 id="road-truth">Against the ground truth ({plural(len(truths), "pair")} of {n_reports})</h3>',
             f"<p>{e(TRUTH_RULE.format(min_depth=min_depth_mm))}</p>",
             '<table class="sortable"><thead><tr>'
             + "".join(f'<th class="t">{c}</th>' if c in ("pair", "missed (true depth)") else f"<th>{c}</th>" for c in cols)
             + "</tr></thead><tbody>"]

    def median_error(items) -> str:
        errors = [abs(x) for x in (_depth_error(g, d) for g, d in items) if x is not None]
        return f"{100 * float(np.median(errors)):.1f}" if errors else "–"

    every = []
    for pair, t in truths.items():
        pairs_found = [(t["by_id"][gid], d) for gid, d in t["found"].items()]
        every += pairs_found
        missed = ", ".join(f"#{g['id']} ({_num(g.get('depth_mm')) or 0.0:.0f} mm)" for g in t["missed"]) or "–"
        parts.append(f'<tr><td class="t"><a href="#road-{e(pair)}">{e(pair)}</a>{_warned(warned.get(pair, 0))}</td>'
                     f'<td>{len(t["counted"])}</td>'
                     f'<td>{len(t["found"])}</td><td class="t">{e(missed)}</td><td>{t["n_false"]}</td>'
                     f'<td>{t["n_extra"]}</td><td>{median_error(pairs_found)}</td></tr>')
    n_counted = sum(len(t["counted"]) for t in truths.values())
    n_found = sum(len(t["found"]) for t in truths.values())
    parts.append(f'<tr><td class="t"><b>all</b></td><td>{n_counted}</td><td>{n_found}</td>'
                 f'<td class="t">{n_counted - n_found}</td><td>{sum(t["n_false"] for t in truths.values())}</td>'
                 f'<td>{sum(t["n_extra"] for t in truths.values())}</td><td>{median_error(every)}</td></tr>')
    parts.append("</tbody></table>")
    return parts


def _road_totals_row(done: list, n_reports: int) -> str:
    """The batch totals' table row of :func:`road_section` (``done``: (pair, defects.json data))."""
    e = html.escape
    every = [(pair, d) for pair, data in done for d in data["defects"]]
    pits = [(pair, d) for pair, d in every if d.get("kind") == "pothole"]
    bumps = [(pair, d) for pair, d in every if d.get("kind") == "bump"]
    low = sum(bool(d.get("low_confidence")) for _, d in every)

    def total(items, key):
        return sum(_num(d.get(key)) or 0.0 for _, d in items)

    deepest = max(pits, key=lambda pd: _num(pd[1].get("max_depth_mm")) or 0.0, default=None)
    deep_txt = (f'<a href="#road-{e(deepest[0])}">{e(deepest[0])}</a> #{e(str(deepest[1].get("id")))} '
                f'{_num(deepest[1].get("max_depth_mm")) or 0.0:.0f} mm') if deepest else "–"
    return (f"<tr><td>{len(done)} of {n_reports}</td><td>{sum(bool(d['defects']) for _, d in done)}</td>"
            f"<td>{len(pits)}</td><td>{len(bumps)}</td><td>{low}</td><td>{total(pits, 'area_m2'):.3f}</td>"
            f"<td>{total(pits, 'volume_l'):.2f}</td><td>{deep_txt}</td></tr></tbody></table>")


def _road_survey(out_dir: Path) -> list[str]:
    """HTML of the survey summary (``road_survey.json``): potholes per frame and per km, and
    per ASTM D6433 severity level; [] when the file is missing or unreadable."""
    try:
        survey = json.loads((out_dir / ROAD_SURVEY).read_text(encoding="utf-8"))
        by = dict(survey.get("by_severity") or {})
    except (OSError, ValueError, TypeError, AttributeError):
        return []  # the per-pair tables above still hold every pothole

    def cell(value) -> str:
        v = _num(value)
        return "–" if v is None else f"{v:g}"

    cols = ("frames", "potholes", "per frame", "survey length [km]", "per km", "low", "medium", "high", "no level")
    vals = [survey.get("frames"), survey.get("potholes"), survey.get("potholes_per_frame"), survey.get("length_km"),
            survey.get("potholes_per_km"), by.get("low"), by.get("medium"), by.get("high"), by.get("none")]
    if survey.get("length_from") == "track":
        length = ("per km from the track's geodesic length, each pothole counted once however many frames "
                  "saw it")
    elif survey.get("length_km") is not None:
        length = "per km from road.frame_spacing_m"
    else:
        length = "per km when the length is known (a track of the frames' positions, or road.frame_spacing_m)"
    return ['<p id="road-survey">Survey summary (<a href="road_survey.json">road_survey.json</a>): potholes per '
            f"frame, {length}, and per ASTM D6433 severity level (equivalent "
            "potholes: one wider than 750 mm counts its area / 0.5 m²; no level: shallower than 13 mm or "
            "narrower than 100 mm).</p>",
            "<table><thead><tr>" + "".join(f"<th>{c}</th>" for c in cols) + "</tr></thead><tbody><tr>"
            + "".join(f"<td>{cell(v)}</td>" for v in vals) + "</tr></tbody></table>"]


#: The map's files (d3cli.survey writes them; read here, not imported).
DEFECTS_GEOJSON = "defects.geojson"
TRACK_GEOJSON = "track.geojson"
#: Fill of a defect on the map by its ASTM D6433 severity (None: too small to grade); bumps blue.
MAP_COLOURS = {"high": "#d73027", "medium": "#fc8d59", "low": "#fee08b", None: "#bdbdbd", "bump": "#4575b4"}
_EARTH_R = 6371008.8


def _read_geojson(path: Path) -> list[dict]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return [f for f in data.get("features", []) if isinstance(f, dict)]
    except (OSError, ValueError, AttributeError):
        return []


def _nice_length(metres: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above ``metres`` (a scale bar's length)."""
    k = 10.0 ** math.floor(math.log10(max(metres, 1e-3)))
    return max(m * k for m in (1, 2, 5) if m * k <= max(metres, 1e-3))


def map_svg(defects: list[dict], track: list[dict], *, width: int = 900) -> str:
    """Inline SVG of the survey map from GeoJSON features: the track, every defect's outline
    with a marker at its centroid (fill by severity, :data:`MAP_COLOURS`; hatched with a
    dashed edge when flagged low confidence), a legend, a scale bar and a north arrow.
    Lon/lat are drawn in a local equirectangular plane (metres east and north of the map's
    centre: true within 0.1 % over a few km); nothing is fetched."""
    e = html.escape
    line = [c for f in track if (f.get("geometry") or {}).get("type") == "LineString"
            for c in f["geometry"]["coordinates"]]
    frames = [(f["geometry"]["coordinates"], (f.get("properties") or {}).get("frame", "")) for f in track
              if (f.get("geometry") or {}).get("type") == "Point"]
    rings = [((f.get("geometry") or {}).get("coordinates") or [[]])[0] for f in defects]
    pts = line + [c for c, _ in frames] + [c for r in rings for c in r]
    pts += [[(f.get("properties") or {}).get("longitude"), (f.get("properties") or {}).get("latitude")]
            for f in defects]
    pts = [p for p in pts if p and all(isinstance(v, (int, float)) and math.isfinite(v) for v in p[:2])]
    if not pts:
        return ""
    lon0 = (min(p[0] for p in pts) + max(p[0] for p in pts)) / 2
    lat0 = (min(p[1] for p in pts) + max(p[1] for p in pts)) / 2
    kx, ky = math.radians(1) * _EARTH_R * math.cos(math.radians(lat0)), math.radians(1) * _EARTH_R

    def metres(p):
        return (p[0] - lon0) * kx, (p[1] - lat0) * ky

    xy = [metres(p) for p in pts]
    span_x = max(max(x for x, _ in xy) - min(x for x, _ in xy), 5.0)
    span_y = max(max(y for _, y in xy) - min(y for _, y in xy), 5.0)
    margin, legend_h = 40, 70
    inner_w = width - 2 * margin
    scale = min(inner_w / span_x, 560 / span_y)
    inner_h = span_y * scale
    height = int(inner_h + 2 * margin + legend_h)
    cx = (max(x for x, _ in xy) + min(x for x, _ in xy)) / 2
    cy = (max(y for _, y in xy) + min(y for _, y in xy)) / 2

    def px(p):
        x, y = metres(p)
        return f"{width / 2 + (x - cx) * scale:.1f},{margin + inner_h / 2 - (y - cy) * scale:.1f}"

    out = [f'<svg class="map" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="{width}" '
           f'height="{height}" role="img" aria-label="map of the defects">', "<defs>"]
    for key, colour in MAP_COLOURS.items():
        out.append(f'<pattern id="hatch-{key or "none"}" width="6" height="6" patternUnits="userSpaceOnUse" '
                   f'patternTransform="rotate(45)"><rect width="6" height="6" fill="#fff"/>'
                   f'<rect width="3" height="6" fill="{colour}"/></pattern>')
    out.append("</defs>")
    out.append(f'<rect x="0" y="0" width="{width}" height="{height}" fill="#fafafa" stroke="#ccc"/>')
    if len(line) >= 2:
        out.append(f'<polyline class="track" points="{" ".join(px(p) for p in line)}" fill="none" stroke="#555" '
                   'stroke-width="2.5" stroke-linejoin="round"/>')
    for coords, frame in frames:
        out.append(f'<circle class="frame" cx="{px(coords).split(",")[0]}" cy="{px(coords).split(",")[1]}" r="2.5" '
                   f'fill="#555"><title>{e(str(frame))}</title></circle>')
    if line:  # "start" beside the first fix, away from the direction driven
        sx, sy = (float(v) for v in px(line[0]).split(","))
        nx_, ny_ = (float(v) for v in px(line[1]).split(",")) if len(line) > 1 else (sx + 1, sy)
        dx, dy = sx - nx_, sy - ny_
        norm = math.hypot(dx, dy) or 1.0
        lx, ly, anchor = sx + 14 * dx / norm, sy + 14 * dy / norm + 4, "end" if dx < 0 else "start"
        if (anchor == "end" and lx < 40) or (anchor == "start" and lx > width - 40):
            lx, ly = sx, sy + (18 if dy >= 0 else -10)  # no room on that side: under (over) the first fix
            anchor = "middle"
        out.append(f'<text x="{lx:.1f}" y="{ly:.1f}" font-size="12" fill="#333" text-anchor="{anchor}">start</text>')
    for f, ring in zip(defects, rings):
        p = f.get("properties") or {}
        key = "bump" if p.get("kind") == "bump" else p.get("severity") if p.get("severity") in MAP_COLOURS else None
        flagged = p.get("confidence") == "low"
        fill = f'url(#hatch-{key or "none"})' if flagged else MAP_COLOURS[key]
        dash = ' stroke-dasharray="3,2"' if flagged else ""
        depth = _num(p.get("depth_mm"))
        tip = (f"#{p.get('id')} {p.get('kind')}, {depth or 0:.0f} mm, severity {p.get('severity') or 'none'}, "
               f"{plural(int(p.get('sightings') or 1), 'sighting')} ({', '.join(map(str, p.get('frames') or []))})"
               + (f"; flagged: {p.get('reasons') or 'low confidence'}" if flagged else ""))
        cls = "defect flagged" if flagged else "defect"
        out.append(f'<g class="{cls}" data-id="{e(str(p.get("id")))}"><title>{e(tip)}</title>')
        size = 0.0
        if len(ring) >= 4:
            pts_px = [tuple(float(v) for v in px(c).split(",")) for c in ring]
            size = max(max(x for x, _ in pts_px) - min(x for x, _ in pts_px),
                       max(y for _, y in pts_px) - min(y for _, y in pts_px))
            out.append(f'<polygon points="{" ".join(f"{x:.1f},{y:.1f}" for x, y in pts_px)}" fill="{fill}" '
                       f'stroke="#222" stroke-width="1"{dash}/>')
        if p.get("longitude") is not None and p.get("latitude") is not None:
            mx, my = (float(v) for v in px([p["longitude"], p["latitude"]]).split(","))
            if size < 14:  # too small to see at this scale: a marker of fixed size
                out.append(f'<circle cx="{mx:.1f}" cy="{my:.1f}" r="7" fill="{fill}" stroke="#222" '
                           f'stroke-width="1.5"{dash}/>')
            out.append(f'<text x="{mx + max(9.0, size / 2 + 3):.1f}" y="{my + 4:.1f}" font-size="12" fill="#111">'
                       f'{e(str(p.get("id")))}</text>')
        out.append("</g>")
    # The north arrow (top right) and the scale bar (bottom left).
    nx = width - margin + 10
    out.append(f'<g class="north"><path d="M{nx},{margin - 25} l-7,18 l7,-5 l7,5 z" fill="#222"/>'
               f'<text x="{nx}" y="{margin + 8}" font-size="13" text-anchor="middle" font-weight="bold">N</text></g>')
    bar_m = _nice_length(0.25 * inner_w / scale)
    bar_px = bar_m * scale
    by = margin + inner_h + 22
    label = f"{bar_m / 1e3:g} km" if bar_m >= 1000 else f"{bar_m:g} m"
    out.append(f'<g class="scale"><path d="M{margin},{by - 6} v6 h{bar_px:.1f} v-6" fill="none" stroke="#222" '
               f'stroke-width="2"/><text x="{margin + bar_px / 2:.1f}" y="{by + 15}" font-size="12" '
               f'text-anchor="middle">{label}</text></g>')
    # The legend, under the map.
    ly = height - 22
    items = [("high", "high"), ("medium", "medium"), ("low", "low"), (None, "too small to grade"), ("bump", "bump")]
    x = margin
    out.append('<g class="legend" font-size="12">')
    for key, text in items:
        out.append(f'<rect x="{x}" y="{ly - 10}" width="14" height="14" fill="{MAP_COLOURS[key]}" stroke="#222"/>'
                   f'<text x="{x + 19}" y="{ly + 2}">{text}</text>')
        x += 40 + 6.6 * len(text)
    out.append(f'<rect x="{x}" y="{ly - 10}" width="14" height="14" fill="url(#hatch-medium)" stroke="#222" '
               f'stroke-dasharray="3,2"/><text x="{x + 19}" y="{ly + 2}">hatched: flagged (low confidence)</text>')
    x += 250
    out.append(f'<path d="M{x},{ly - 3} h24" stroke="#555" stroke-width="2.5"/><text x="{x + 29}" y="{ly + 2}">'
               "track</text></g></svg>")
    return "".join(out)


def road_map(out_dir: str | Path) -> list[str]:
    """HTML of the survey map (``defects.geojson``, ``track.geojson``, :mod:`d3cli.survey`):
    the inline SVG of :func:`map_svg` and a sortable table of the defects on it; [] without
    the files."""
    out_dir = Path(out_dir)
    defects, track = _read_geojson(out_dir / DEFECTS_GEOJSON), _read_geojson(out_dir / TRACK_GEOJSON)
    if not track and not defects:
        return []
    e = html.escape
    svg = map_svg(defects, track)
    props = [f.get("properties") or {} for f in defects]
    line = next((f.get("properties") or {} for f in track if (f.get("geometry") or {}).get("type") == "LineString"
                 or "unplaced_frames" in (f.get("properties") or {})), {})
    unplaced = list(line.get("unplaced_frames") or [])
    n_seen = sum(int(p.get("sightings") or 1) for p in props)
    length = _num(line.get("length_m"))
    merged = n_seen - len(props)
    parts = ['<h3 id="road-map">Map</h3>',
             f"<p>{plural(len(props), 'defect')} on the map from {plural(n_seen, 'sighting')}"
             + (f" ({merged} of them of a defect already seen from another frame, merged)" if merged else "")
             + (f", along {length:.0f} m of track" if length else "")
             + f" (positions: {e(str(line.get('source') or 'the track'))}). "
             'Files: <a href="defects.geojson">defects.geojson</a>, <a href="track.geojson">track.geojson</a> '
             "(GeoJSON, WGS84 longitude/latitude: open them in QGIS or any web map). Colour: ASTM D6433 severity "
             "of the best-measured sighting; hatched with a dashed edge: flagged (low confidence). Hover a "
             "defect for its depth and frames.</p>"]
    if unplaced:
        parts.append(f'<p class="low">{plural(len(unplaced), "frame")} without a position (measured, not on the '
                     f"map): {e(', '.join(map(str, unplaced)))}.</p>")
    if svg:
        parts.append(f'<div class="scroll">{svg}</div>')
    if props:
        cols = ("id", "kind", "severity", "depth [mm] (bump: height)", "area [m²]", "sightings", "frames",
                "best frame", "confidence", "latitude", "longitude")
        parts.append('<div class="scroll"><table class="sortable" id="map-defects"><thead><tr>'
                     + "".join(f"<th>{c}</th>" for c in cols) + "</tr></thead><tbody>")
        for p in props:
            low_d = p.get("confidence") == "low"
            vals = [(p.get("id"), str(p.get("id"))), (None, str(p.get("kind"))), (None, p.get("severity") or "–"),
                    (p.get("depth_mm"), f"{_num(p.get('depth_mm')) or 0.0:.1f}"),
                    (p.get("area_m2"), f"{_num(p.get('area_m2')) or 0.0:.4f}"),
                    (p.get("sightings"), str(p.get("sightings"))), (None, ", ".join(map(str, p.get("frames") or []))),
                    (None, str(p.get("best_frame"))),
                    (None, f"low: {p.get('reasons')}" if low_d and p.get("reasons") else "low" if low_d else "ok"),
                    (p.get("latitude"), f"{_num(p.get('latitude')) or 0.0:.7f}"),
                    (p.get("longitude"), f"{_num(p.get('longitude')) or 0.0:.7f}")]
            cells = "".join(f'<td data-v="{_num(v) if _num(v) is not None else ""}">{e(t)}</td>' for v, t in vals)
            row_cls = ' class="low"' if low_d else ""
            parts.append(f"<tr{row_cls}>{cells}</tr>")
        parts.append("</tbody></table></div>")
    return parts


def _road_card(out_dir: Path, pair: str, data: Mapping, truth: Mapping | None = None,
               n_warnings: int = 0) -> list[str]:
    """HTML of one pair's card in :func:`road_section`: name (its warnings counted),
    thumbnail, links and defects table (with ``truth``, :func:`road_truth`, a last column
    naming the pothole each detection found)."""
    e = html.escape
    cols = ("id", "kind", "depth [mm] (bump: height)", "mean depth [mm]", "area [m²]", "diameter [mm]", "volume [l]",
            "severity (ASTM D6433)", "decided [%]", "confidence", *(("ground truth",) if truth else ()))
    folder = out_dir / pair
    parts = []
    n_pits = sum(d.get("kind") == "pothole" for d in data["defects"])
    found = (f"; found {len(truth['found'])} of {plural(len(truth['counted']), 'pothole')} in its ground truth"
             if truth else "")
    parts.append(f'<div class="card road" id="road-{e(pair)}"><b>{e(pair)}</b>: {plural(n_pits, "pothole")}, '
                 f"{plural(len(data['defects']) - n_pits, 'bump')}{found}{_warned(n_warnings)}<br>")
    pics = [p for p in ROAD_PICTURES if (folder / p).is_file()]
    if pics:
        href = quote(f"{pair}/{pics[0]}")
        parts.append(f'<a href="{e(href)}"><img loading="lazy" src="{e(href)}" alt="defects of {e(pair)}"></a><br>'
                     + " ".join(f'<a href="{e(quote(f"{pair}/{p}"))}">{p}</a>' for p in pics))
    parts.append('<div class="scroll"><table class="sortable"><thead><tr>' + "".join(f"<th>{c}</th>" for c in cols)
                 + "</tr></thead><tbody>")
    for d in data["defects"]:
        low_d = bool(d.get("low_confidence"))
        vals = [(d.get("id"), str(d.get("id"))), (None, str(d.get("kind"))),
                (d.get("max_depth_mm"), f"{_num(d.get('max_depth_mm')) or 0.0:.1f}"),
                (d.get("mean_depth_mm"), f"{_num(d.get('mean_depth_mm')) or 0.0:.1f}"),
                (d.get("area_m2"), f"{_num(d.get('area_m2')) or 0.0:.4f}"),
                (d.get("diameter_mm"), "–" if _num(d.get("diameter_mm")) is None else f"{_num(d.get('diameter_mm')):.0f}"),
                (d.get("volume_l"), f"{_num(d.get('volume_l')) or 0.0:.2f}"),
                (None, d.get("severity") or "–"),
                (d.get("decided_share"), f"{100 * (_num(d.get('decided_share')) or 0.0):.0f}"),
                (None, f"low: {d.get('reasons')}" if low_d and d.get("reasons") else "low" if low_d else "ok")]
        cells = "".join(f'<td data-v="{_num(v) if _num(v) is not None else ""}">{e(t)}</td>' for v, t in vals)
        if truth:
            cells += f'<td class="t">{e(_truth_cell(truth, d))}</td>'
        row_cls = ' class="low"' if low_d else ""
        parts.append(f"<tr{row_cls}>{cells}</tr>")
    parts.append("</tbody></table></div>")
    for w in data.get("warnings") or []:
        parts.append(f'<p class="low">{e(str(w))}</p>')
    parts.append("</div>")
    return parts


def _truth_cell(truth: Mapping, d: Mapping) -> str:
    """What a detection is against the ground truth: ``#2: 26.4 mm true, -3.0 %``, ``false``, ``extra (#2)``;
    bumps are not in the pothole ground truth (``–``)."""
    if d.get("kind") != "pothole":
        return "–"
    text = truth["label"].get(d.get("id"), "–")
    gid = next((g for g, found in truth["found"].items() if found is d), None)
    if gid is None:
        return text
    gt = truth["by_id"][gid]
    err = _depth_error(gt, d)
    return f"{text}: {_num(gt.get('depth_mm')) or 0.0:.1f} mm true" + ("" if err is None else f", {100 * err:+.1f} %")


def write_report_html(out_dir: str | Path, rows: Iterable[Mapping], *, title: str,
                      config: Mapping | None = None, versions: Mapping | None = None,
                      run_counts: Mapping | None = None) -> Path:
    """Write ``out_dir/report.html`` atomically (:func:`report_html`); returns its path."""
    text = readable(report_html(out_dir, rows, title=title, config=config, versions=versions, run_counts=run_counts))
    return atomic_write(Path(out_dir) / REPORT_FILE, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
