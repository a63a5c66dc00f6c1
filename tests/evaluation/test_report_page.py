"""report.html as the one page a user needs: warnings and errors beside their pairs and
counted at the top, the columns of the terminal and summary.md, an unscored run said to be
unscored, the road defects against the pothole ground truth, and the page as a browser
renders it."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess

import cv2
import numpy as np
import pytest
from click.testing import CliRunner
from tests.helpers import textured_pair, write_png

from d3cli.cli import main
from d3cli.data import formats as io
from d3cli.evaluation.html import write_report_html

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def batch_out(tmp_path_factory):
    """A scored sgbm batch of a good pair, the same pair with left and right swapped, and a
    pair whose right image is not an image: (output folder, terminal output)."""
    root = tmp_path_factory.mktemp("pairs")
    left, right, gt = textured_pair(8, (96, 192), seed=3)
    for name, (lt, rt) in (("good", (left, right)), ("swapped", (right, left)), ("broken", (left, None))):
        folder = root / name
        folder.mkdir()
        write_png(folder / "left.png", lt)
        if rt is None:
            (folder / "right.png").write_text("not a PNG")
        else:
            write_png(folder / "right.png", rt)
        io.write_pfm(folder / "disp_gt.pfm", gt)
        (folder / "SOURCE.txt").write_text("provenance: synthetic test pair\ngt_scale: 1\ngt_invalid: inf\n")
    out = tmp_path_factory.mktemp("out")
    result = CliRunner().invoke(main, ["run", str(root), "-o", str(out), "--method", "sgbm",
                                       "--max-disparity", "32", "--eval"])
    assert result.exit_code == 1, result.output  # the broken pair failed; everything else is written
    return out, result.output


def _pair_body(page: str, pair: str) -> str:
    """The pair table's ``<tbody>`` of ``pair``: its row, and under it its warnings or error."""
    table = page[page.index('<h2 id="pairs">'):]
    table = table[:table.index("</table>")]
    body = next(b for b in table.split("<tbody>")[1:] if f">{pair}</a></td>" in b or f'"t">{pair}</td>' in b)
    return body[:body.index("</tbody>")]


def test_a_swapped_pairs_warnings_are_beside_it_and_counted_at_the_top(batch_out):
    out, terminal = batch_out
    warnings = json.loads((out / "swapped" / "result.json").read_text())["warnings"]
    assert warnings and any("swapped?" in w or "left image really the left one" in w for w in warnings)
    assert json.loads((out / "good" / "result.json").read_text())["warnings"] == []
    page = (out / "report.html").read_text()
    n = len(warnings)
    top = page[:page.index('<h2 id="pairs">')]
    assert (f'<p class="problems failed"><a href="#warnings">{n} warning{"s" * (n != 1)}</a> on 1 pair, '
            '<a href="#failures">1 error</a>. Each is shown beside its pair below.</p>') in top
    assert "<p>3 pairs: 2 ok (2 computed, 0 skipped as complete), 1 failed. " in top
    swapped = _pair_body(page, "swapped")
    row, message = swapped.split("</tr>")[:2]
    assert row.startswith('<tr class="warned">')
    assert f'<td class="t">ok, {n} warning{"s" * (n != 1)}</td>' in row
    assert message.startswith('<tr class="warned"><td class="msg" colspan=')  # right under the pair's row
    for text in warnings:  # every warning in full
        assert f"<li>{html.escape(' '.join(text.split()))}</li>" in message
    assert _pair_body(page, "good").count("<tr") == 1 and "warning" not in _pair_body(page, "good")
    broken = _pair_body(page, "broken")
    assert broken.startswith('<tr class="failed">') and "right.png" in broken.split('<td class="msg"')[1]
    # The terminal counts them too, and names the pair; summary.md as the page.
    assert f"{n} warning{'s' * (n != 1)} on 1 pair: swapped (each pair's warnings are in report.html" in terminal
    md = (out / "summary.md").read_text().splitlines()
    assert f"{n} warning{'s' * (n != 1)} on 1 pair, 1 error. Each warning is listed under Warnings below." in md
    assert any(line.startswith(f"| swapped | ok, {n} warning") for line in md)


def test_the_batch_terminal_summary_and_page_name_the_same_columns(batch_out):
    out, terminal = batch_out
    lines = terminal.splitlines()
    head = next(line for line in lines if line.startswith("family "))
    terminal_heads = re.split(r"\s{2,}", head)
    md = (out / "summary.md").read_text().splitlines()
    md_heads = [c.strip() for c in md[md.index("## Overall") + 2].strip("|").split("|")]
    page = (out / "report.html").read_text()
    means = page[page.index("<h2>Means per family"):]
    page_heads = re.findall(r"<th[^>]*>([^<]*)</th>", means[:means.index("</thead>")])
    assert terminal_heads == md_heads == page_heads
    assert terminal_heads[:5] == ["family", "ok", "with gt", "EPE [px]", "PEP 0.5 [%]"]
    assert terminal_heads[-1] == "time [s]" and "D1 (all) [%]" in terminal_heads
    # Defined in the page: exactly the shown columns.
    definitions = page[page.index('<h2 id="definitions">'):page.index("<h2>Config")]
    assert re.findall(r"<dt>(.*?)</dt>", definitions) == [html.escape(h) for h in page_heads[3:]]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")
def test_the_page_renders_in_a_headless_browser(batch_out, tmp_path):
    out, _ = batch_out
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path}",
                           "--dump-dom", (out / "report.html").as_uri()],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    dom = done.stdout
    n = len(json.loads((out / "swapped" / "result.json").read_text())["warnings"])
    assert f'<a href="#warnings">{n} warning{"s" * (n != 1)}</a> on 1 pair, <a href="#failures">1 error</a>' in dom
    # The parsed table: one head row, three pairs (the swapped one's warnings and the broken
    # one's error each in a row under it).
    pairs = dom[dom.index('<h2 id="pairs">'):]
    pairs = pairs[:pairs.index("</table>")]
    assert pairs.count("<tbody>") == 3 and pairs.count("<tr") == 6
    assert pairs.count('class="warned"') == 2 and pairs.count("<li>") == n

    # Sorting by EPE (a click on its head) orders the pairs, each keeping its message row.
    page = (out / "report.html").read_text()
    clicked = tmp_path / "clicked.html"
    clicked.write_text(page.replace("</body>", "<script>document.querySelectorAll('table.grouped th')[3].click()"
                                               "</script></body>"))
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path}",
                           "--dump-dom", clicked.as_uri()], capture_output=True, text=True, timeout=60)
    pairs = done.stdout[done.stdout.index('<h2 id="pairs">'):]
    pairs = pairs[:pairs.index("</table>")]
    names = re.findall(r'<tbody><tr[^>]*><td class="t">(?:<a href="#\w+">)?(\w+)<', pairs)
    assert names == ["good", "swapped", "broken"]  # no EPE (failed): last
    epe = [re.findall(r'<td data-v="([^"]*)">', body)[0] for body in pairs.split("<tbody>")[1:]]
    assert float(epe[0]) < 1.0 < float(epe[1]) and epe[2] == ""  # good, swapped, no EPE
    swapped = pairs[pairs.index('href="#swapped"'):]
    assert swapped.index("<li>") < swapped.index("</tbody>")  # its warnings moved with it


def test_an_unscored_run_says_so_and_names_the_flag_when_pairs_have_ground_truth(tmp_path):
    for name, gt in (("a", "/data/a/disp_gt.pfm"), ("b", None)):
        (tmp_path / name).mkdir()
        (tmp_path / name / "result.json").write_text(json.dumps({"inputs": {"left": "l.png", "gt": gt}}))
    rows = [{"pair": p, "family": "synth", "status": "ok", "time_s": 1.0} for p in ("a", "b")]
    page = write_report_html(tmp_path, rows, title="t").read_text()
    assert ("Not scored: this run was made without --eval, although 1 of 2 ok pairs has ground truth. "
            "Run the same command again with --eval to score them") in page
    assert "no ground truth" not in page and "Histogram" not in page
    heads = re.findall(r'<th title="[^"]*">([^<]*)</th>', page[:page.index("<h2>Means per family")])
    assert heads == ["time [s]"]
    means = page[page.index("<h2>Means per family"):]
    # No "with gt 0" beside "2 pairs have ground truth": the count is shown with scores only.
    assert re.findall(r"<th[^>]*>([^<]*)</th>", means[:means.index("</thead>")]) == ["family", "ok", "time [s]"]
    definitions = page[page.index('<h2 id="definitions">'):page.index("<h2>Config")]
    assert re.findall(r"<dt>(.*?)</dt>", definitions) == ["time [s]"] and "e = |d - gt|" not in definitions
    assert "<p>2 pairs: 2 ok, 0 failed, 0 skipped. " in page and "No warnings, no errors." in page

    (tmp_path / "a" / "result.json").write_text(json.dumps({"inputs": {"left": "l.png", "gt": None}}))
    page = write_report_html(tmp_path, rows[:1], title="t").read_text()
    assert "<p>1 pair: 1 ok, 0 failed, 0 skipped. " in page
    assert "Not scored: this run was made without --eval, and no pair has ground truth" in page


def _square(u0, v0, u1, v1):
    return [[u0, v0], [u1, v0], [u1, v1], [u0, v1]]


def test_road_defects_are_scored_against_the_pothole_ground_truth(tmp_path):
    # The input pair: potholes 1 and 2 (deep enough to count), 3 (5 mm: not counted).
    pair_in = tmp_path / "in" / "p"
    pair_in.mkdir(parents=True)
    ids = np.zeros((100, 200), np.uint8)
    ids[10:40, 10:40], ids[10:40, 100:140], ids[60:90, 10:40] = 1, 2, 3
    cv2.imwrite(str(pair_in / "potholes_gt.png"), ids)
    truth = [{"id": 1, "depth_mm": 20.0, "visible_px": 900}, {"id": 2, "depth_mm": 30.0, "visible_px": 1200},
             {"id": 3, "depth_mm": 5.0, "visible_px": 900}]
    (pair_in / "defects_gt.json").write_text(json.dumps({"potholes": truth}))
    # The outputs: #1 on pothole 1, #2 a fragment of it, #3 on bare road, #4 on the shallow one.
    out = tmp_path / "out"
    (out / "p").mkdir(parents=True)
    (out / "p" / "result.json").write_text(json.dumps({"inputs": {"left": str(pair_in / "left.png")}}))
    io.write_image(out / "p" / "defects.png", np.zeros((4, 8, 3), np.uint8))

    def pothole(i, outline, depth):
        return {"id": i, "kind": "pothole", "outline_px": [outline], "bbox_px": [0, 0, 1, 1], "max_depth_mm": depth,
                "mean_depth_mm": depth / 2, "area_m2": 0.01, "volume_l": 0.1, "decided_share": 0.9,
                "low_confidence": False}

    defects = [pothole(1, _square(12, 12, 38, 38), 22.0), pothole(2, _square(30, 30, 36, 36), 18.0),
               pothole(3, _square(150, 60, 190, 95), 15.0), pothole(4, _square(12, 62, 38, 88), 12.0)]
    (out / "p" / "defects.json").write_text(json.dumps({"defects": defects, "warnings": []}))
    rows = [{"pair": "p", "family": "synth", "status": "ok", "time_s": 1.0, "warnings": ["check the inputs"]}]
    page = write_report_html(out, rows, title="t", config={"road": {"min_depth_mm": 10.0}}).read_text()
    road = page[page.index('<h3 id="road-truth">'):]
    assert "Against the ground truth (1 pair of 1)" in road and "deeper than 10 mm" in road
    table = road[road.index("<tbody>"):road.index("</tbody>")]
    cells = [re.sub(r"<[^>]+>", "", c) for c in re.findall(r"<td[^>]*>(.*?)</td>", table)]
    # pair (its warning counted), counted, found, missed (true depth), false, extra, median |depth error|
    assert cells[:7] == ["p 1 warning", "2", "1", "#2 (30 mm)", "1", "2", "10.0"]
    assert cells[7:] == ["all", "2", "1", "1", "1", "2", "10.0"]
    card = page[page.index('id="road-p"'):]
    assert "found 1 of 2 potholes in its ground truth" in card
    truth_cells = re.findall(r'<td class="t">([^<]*)</td>', card[:card.index("</table>")])
    assert truth_cells == ["#1: 20.0 mm true, +10.0 %", "extra (#1)", "false", "#3, not counted (5 mm deep)"]
