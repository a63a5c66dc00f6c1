"""``report.html``: one static, self-contained page of a batch (inline CSS/JS, no network).

Contents: the summary table (click a header to sort), per-family means, a histogram of
the per-pair error (inline SVG), every pair's panel as a thumbnail sorted by error
(worst first) linking to the full images, the config and the versions.  Links are
relative and point only to files that exist when the page is written.

After ``--road-report`` (a pair folder holds ``defects.json``, :mod:`d3cli.road.report`)
the page has a "Road inspection" section, read from those files: the batch totals, then
per pair (deepest pothole first) a ``defects.png`` thumbnail and a table of its defects
(with each pothole's ASTM D6433 severity), and the survey summary of ``road_survey.json``.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from urllib.parse import quote

from ..data.formats import atomic_write
from .definitions import EVALUATED, MEANS, PIXEL_SETS, metric
from .report import jsonable
from .summary import summarize
from .tables import HUGE, counts_sentence, one_line

REPORT_FILE = "report.html"

#: Columns of the page's table (those with at least one value are shown).
TABLE_COLUMNS = ["epe", "d1_all", "d1_noc", "bad_2_noc", "bad_4_noc", "a90_noc", "rms_noc",
                 "pep_3", "density", "psnr", "ssim", "time_s"]

#: Pictures linked from a pair's card when they exist, in this order.
PAIR_PICTURES = ("panel.png", "disp_color.png", "error.png", "valid_overlay.png")

_CSS = """
body{font:14px/1.4 system-ui,sans-serif;margin:1.5em;color:#222}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 6px;text-align:right}
th{background:#eee;cursor:pointer}td:first-child,td:nth-child(2),td:nth-child(3){text-align:left}
.cards{display:flex;flex-wrap:wrap;gap:10px}.card{width:420px}.card img{width:100%;border:1px solid #999}
.card.road{width:640px}.card.road table{font-size:12px}.low{color:#b60}
.failed{color:#b00}dt{font-weight:bold}dd{margin:0 0 .4em 1.5em}pre{background:#f6f6f6;padding:.5em;max-height:30em;overflow:auto}
"""

_JS = """
document.querySelectorAll('table.sortable th').forEach(function(th,i){th.onclick=function(){
var t=th.closest('table'),b=t.tBodies[0],r=Array.from(b.rows),d=th.dataset.d==='1'?-1:1;th.dataset.d=d===1?'1':'0';
r.sort(function(x,y){var a=x.cells[i].dataset.v||x.cells[i].textContent,c=y.cells[i].dataset.v||y.cells[i].textContent;
var p=parseFloat(a),q=parseFloat(c);if(!isNaN(p)&&!isNaN(q))return d*(p-q);if(isNaN(p)!==isNaN(q))return isNaN(p)?1:-1;return d*a.localeCompare(c);});
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
        return "<p>No per-pair errors to plot (no ground truth).</p>"
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
    ok pairs into computed and kept from an earlier run, as summary.md does.
    """
    out_dir = Path(out_dir)
    rows = [dict(r) for r in rows]
    summary = summarize(rows)
    if run_counts is not None:
        summary["run"] = {key: int(run_counts[key]) for key in ("n_computed", "n_skipped", "n_failed")}
    columns = [c for c in TABLE_COLUMNS if any(_num(r.get(c)) is not None for r in rows)]
    e = html.escape
    out = [f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>'
           f"<style>{_CSS}</style></head><body><h1>{e(title)}</h1>"]
    out.append(f"<p>{e(counts_sentence(summary))} {e(PIXEL_SETS)} Every column is defined "
               '<a href="#definitions">below</a>; click a column head to sort.</p>')
    # Summary table
    out.extend(_pairs_table(out_dir, rows, columns))
    # Family means
    fam_cols = [c for c in columns if c in summary["overall"]["means"]]
    out.append('<h2>Means per family</h2><table class="sortable"><thead><tr><th>family</th><th>ok</th>'
               + "".join(_head(c) for c in fam_cols) + "</tr></thead><tbody>")
    groups = [*summary["families"].items(), ("overall", summary["overall"])]
    for name, group in groups:
        out.append(f"<tr><td>{e(name)}</td><td>{group.get('ok', 0)}</td>"
                   + "".join(f"<td>{_fmt(group['means'].get(c), c)}</td>" for c in fam_cols) + "</tr>")
    out.append("</tbody></table>")
    # Histogram
    key = "epe" if any(_num(r.get("epe")) is not None for r in rows) else "psnr"
    values = [_num(r.get(key)) for r in rows if _num(r.get(key)) is not None]
    label = metric(key).label
    out.append(f"<h2>Histogram of per-pair {e(label)}</h2>" + histogram_svg(values, label=label))
    out.extend(failed_section(summary))
    out.extend(road_section(out_dir, rows))
    # Thumbnails, worst first
    out.append("<h2>Pairs by error (worst first)</h2><div class=\"cards\">")
    for r in sorted(rows, key=sort_key):
        folder = out_dir / r["pair"]
        pics = [p for p in PAIR_PICTURES if (folder / p).is_file()]
        figure = ", ".join(f"{metric(c).name} {metric(c).format(_num(r.get(c)))}" for c in ("epe", "d1_all", "a90_noc")
                           if _num(r.get(c)) is not None)
        out.append(f'<div class="card" id="{e(r["pair"])}"><b>{e(r["pair"])}</b> {e(figure)}<br>')
        if pics:
            thumb = f"{r['pair']}/{pics[0]}"
            out.append(f'<a href="{e(thumb)}"><img loading="lazy" src="{e(thumb)}" alt="{e(r["pair"])}"></a><br>')
            out.append(" ".join(f'<a href="{e(r["pair"])}/{p}">{p}</a>' for p in pics))
        else:
            out.append(f"<i>{e(str(r.get('error') or 'no pictures'))}</i>")
        out.append("</div>")
    out.append("</div>")
    out.extend(definitions_section([*columns, *(c for c in ("d1_all", "a90_noc") if c not in columns)]))
    out.append("<h2>Config</h2><pre>" + e(json.dumps(jsonable(config or {}), indent=2, sort_keys=True)) + "</pre>")
    out.append("<h2>Versions</h2><pre>" + e(json.dumps(jsonable(versions or {}), indent=2, sort_keys=True)) + "</pre>")
    out.append(f"<script>{_JS}</script></body></html>\n")
    return "\n".join(out)


def _pairs_table(out_dir: Path, rows: list[dict], columns: list[str]) -> list[str]:
    """HTML of the "Pairs" table: name (linking to its card), family, status (linking to its message), figures."""
    e = html.escape
    out: list[str] = []
    out.append('<h2>Pairs</h2><table class="sortable"><thead><tr><th>pair</th><th>family</th><th>status</th>'
               + "".join(_head(c) for c in columns) + "</tr></thead><tbody>")
    for r in rows:
        cls = ' class="failed"' if r.get("status") == "failed" else ""
        cells = "".join(f'<td data-v="{_num(r.get(c)) if _num(r.get(c)) is not None else ""}">{_fmt(r.get(c), c)}</td>'
                        for c in columns)
        link = f'<a href="#{e(r["pair"])}">{e(r["pair"])}</a>' if (out_dir / r["pair"]).is_dir() else e(r["pair"])
        status = e(str(r.get("status")))
        if r.get("status") in ("failed", "skipped"):  # the message is listed below the tables
            status = f'<a href="#{"failures" if r.get("status") == "failed" else "skipped"}">{status}</a>'
        out.append(f"<tr{cls}><td>{link}</td><td>{e(str(r.get('family') or ''))}</td>"
                   f"<td title=\"{e(str(r.get('error') or ''))}\">{status}</td>{cells}</tr>")
    out.append("</tbody></table>")
    return out


def _head(key: str) -> str:
    """A column head: the name with its unit, the definition as its tooltip."""
    m = metric(key)
    return f'<th title="{html.escape(m.definition)}">{html.escape(m.label)}</th>'


def failed_section(summary: Mapping) -> list[str]:
    """HTML listing every failed pair with its error, and every left-out pair with its reason; [] when none."""
    e = html.escape
    parts = []
    for key, title, field in (("failures", "Failed pairs", "error"), ("skipped", "Left-out pairs", "reason")):
        items = summary.get(key) or []
        if items:
            parts.append(f'<h2 id="{key}">{title}</h2><ul class="failed">')
            for item in items:
                pair, text = str(item["pair"]), one_line(item[field] or "no message")
                text = text[len(pair) + 2:] if text.startswith(f"{pair}: ") else text  # the name once
                parts.append(f"<li><b>{e(pair)}</b>: {e(text)}</li>")
            parts.append("</ul>")
    return parts


def definitions_section(keys: Iterable[str]) -> list[str]:
    """HTML of the "Definitions" section: how the pixels are chosen, the means, then each column of ``keys``."""
    e = html.escape
    parts = ['<h2 id="definitions">Definitions</h2>', f"<p>{e(EVALUATED)} {e(PIXEL_SETS)} {e(MEANS)}</p><dl>"]
    for key in dict.fromkeys(keys):
        m = metric(key)
        if m.definition:
            parts.append(f"<dt>{e(m.label)}</dt><dd>{e(m.definition)}</dd>")
    parts.append("</dl>")
    return parts


#: Per-pair road files (d3cli.road.report writes them; read here, not imported: the
#: evaluation room does not depend on the road room).
ROAD_JSON, ROAD_PICTURES = "defects.json", ("defects.png", "height_color.png")
#: The batch's survey summary (d3cli.road.severity.survey_summary, written beside defects.csv).
ROAD_SURVEY = "road_survey.json"


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


def road_section(out_dir: str | Path, rows: Iterable[Mapping]) -> list[str]:
    """HTML of the "Road inspection" section; [] when no pair has a ``defects.json``.

    Batch totals (potholes, bumps, low-confidence ones, summed area and fill volume of the
    potholes, the deepest), the survey summary (``road_survey.json``: per frame, per km,
    per severity level), then one card per pair with defects, deepest pothole first:
    ``defects.png`` as a thumbnail (links to it and to ``height_color.png``) and a sortable
    table of id, kind, depth (bumps: height), mean depth, area, diameter, volume, ASTM D6433
    severity, decided share and confidence;
    pairs without defects and pairs without a road report are listed by name.
    """
    out_dir = Path(out_dir)
    reports = _road_reports(out_dir, [dict(r) for r in rows])
    if not any(data is not None for _, data, _ in reports):
        return []
    e = html.escape
    done = [(pair, data) for pair, data, _ in reports if data is not None]
    parts = ['<h2 id="road">Road inspection</h2>',
             "<p>Depth: below the surrounding road surface (the median height of a ring of road "
             "around the defect); area: of the road plane covered; volume: to fill it up to the "
             "surrounding surface; decided: share of the defect's pixels the method decided itself "
             "(not filled); low confidence = few decided pixels.</p>",
             '<table><thead><tr><th>pairs with a road report</th><th>with defects</th><th>potholes</th>'
             "<th>bumps</th><th>low confidence</th><th>pothole area [m²]</th><th>pothole volume [l]</th>"
             "<th>deepest pothole</th></tr></thead><tbody>",
             _road_totals_row(done, len(reports))]
    if (out_dir / "defects.csv").is_file():
        parts.append('<p>Every defect of the batch: <a href="defects.csv">defects.csv</a>.</p>')
    parts += _road_survey(out_dir)

    def deepest_of(data):
        return max((_num(d.get("max_depth_mm")) or 0.0 for d in data["defects"] if d.get("kind") == "pothole"),
                   default=0.0)

    with_defects = sorted(((p, d) for p, d in done if d["defects"]),
                          key=lambda pd: (-deepest_of(pd[1]), -len(pd[1]["defects"])))
    parts.append('<div class="cards">')
    for pair, data in with_defects:
        parts += _road_card(out_dir, pair, data)
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
    return ['<p id="road-survey">Survey summary (<a href="road_survey.json">road_survey.json</a>): potholes per '
            "frame, per km when road.frame_spacing_m is set, and per ASTM D6433 severity level (equivalent "
            "potholes: one wider than 750 mm counts its area / 0.5 m²; no level: shallower than 13 mm or "
            "narrower than 100 mm).</p>",
            "<table><thead><tr>" + "".join(f"<th>{c}</th>" for c in cols) + "</tr></thead><tbody><tr>"
            + "".join(f"<td>{cell(v)}</td>" for v in vals) + "</tr></tbody></table>"]


def _road_card(out_dir: Path, pair: str, data: Mapping) -> list[str]:
    """HTML of one pair's card in :func:`road_section`: thumbnail, links and defects table."""
    e = html.escape
    cols = ("id", "kind", "depth [mm] (bump: height)", "mean depth [mm]", "area [m²]", "diameter [mm]", "volume [l]",
            "severity (ASTM D6433)", "decided [%]", "confidence")
    folder = out_dir / pair
    parts = []
    n_pits = sum(d.get("kind") == "pothole" for d in data["defects"])
    parts.append(f'<div class="card road" id="road-{e(pair)}"><b>{e(pair)}</b>: {n_pits} pothole(s), '
                 f"{len(data['defects']) - n_pits} bump(s)<br>")
    pics = [p for p in ROAD_PICTURES if (folder / p).is_file()]
    if pics:
        href = quote(f"{pair}/{pics[0]}")
        parts.append(f'<a href="{e(href)}"><img loading="lazy" src="{e(href)}" alt="defects of {e(pair)}"></a><br>'
                     + " ".join(f'<a href="{e(quote(f"{pair}/{p}"))}">{p}</a>' for p in pics))
    parts.append('<table class="sortable"><thead><tr>' + "".join(f"<th>{c}</th>" for c in cols)
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
                (None, "low" if low_d else "ok")]
        cells = "".join(f'<td data-v="{_num(v) if _num(v) is not None else ""}">{e(t)}</td>' for v, t in vals)
        row_cls = ' class="low"' if low_d else ""
        parts.append(f"<tr{row_cls}>{cells}</tr>")
    parts.append("</tbody></table>")
    for w in data.get("warnings") or []:
        parts.append(f'<p class="low">{e(str(w))}</p>')
    parts.append("</div>")
    return parts


def write_report_html(out_dir: str | Path, rows: Iterable[Mapping], *, title: str,
                      config: Mapping | None = None, versions: Mapping | None = None,
                      run_counts: Mapping | None = None) -> Path:
    """Write ``out_dir/report.html`` atomically (:func:`report_html`); returns its path."""
    text = report_html(out_dir, rows, title=title, config=config, versions=versions, run_counts=run_counts)
    return atomic_write(Path(out_dir) / REPORT_FILE, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
