"""report.html: valid HTML, every pair named, no broken local link, sorted thumbnails."""

import html
import json
import re
from html.parser import HTMLParser
from urllib.parse import unquote

import numpy as np

from d3cli.data import formats as io
from d3cli.evaluation.definitions import metric
from d3cli.evaluation.html import histogram_svg, write_report_html


class Collector(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.stack, self.ids, self.text = [], [], set(), []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag not in ("br", "img", "meta", "rect", "input"):
            self.stack.append(tag)
        self.links += [attrs[k] for k in ("href", "src") if k in attrs]
        if "id" in attrs:
            self.ids.add(attrs["id"])

    def handle_endtag(self, tag):
        if tag in ("rect",):
            return
        assert self.stack and self.stack[-1] == tag, (tag, self.stack[-5:])
        self.stack.pop()

    def handle_data(self, data):
        self.text.append(data)


def test_report_is_valid_and_links_resolve(tmp_path):
    rows = [
        {"pair": "good", "family": "kitti", "status": "ok", "epe": 0.5, "d1_all": 1.0, "time_s": 1.0},
        {"pair": "bad", "family": "kitti", "status": "ok", "epe": 5.0, "d1_all": 30.0, "time_s": 1.0},
        {"pair": "road<1>", "family": "road", "status": "ok", "psnr": 20.0, "time_s": 2.0},
        {"pair": "broken", "family": "road", "status": "failed", "error": "Error: x & y"},
    ]
    for name in ("good", "bad"):
        (tmp_path / name).mkdir()
        io.write_image(tmp_path / name / "panel.png", np.zeros((4, 8, 3), np.uint8))
    path = write_report_html(tmp_path, rows, title="t", config={"a": 1}, versions={"numpy": "1"})
    text = path.read_text()
    parser = Collector()
    parser.feed(text)
    parser.close()
    assert parser.stack == []
    assert "http" not in " ".join(parser.links) and "<link" not in text  # no network
    for link in parser.links:
        if link.startswith("#"):
            assert link[1:] in parser.ids
        else:
            assert (tmp_path / unquote(link)).is_file(), link
    joined = "".join(parser.text)
    for row in rows:
        assert row["pair"] in joined
    assert text.index('id="bad"') < text.index('id="good"')  # worst first
    assert "<svg" in text


def test_histogram_counts():
    svg = histogram_svg([0.0, 0.1, 1.0], label="epe", bins=2)
    assert svg.count("<rect") == 2 and ": 2</title>" in svg and ": 1</title>" in svg


def _road_pair(folder, defects, warnings=()):
    folder.mkdir()
    io.write_image(folder / "defects.png", np.zeros((4, 8, 3), np.uint8))
    io.write_image(folder / "height_color.png", np.zeros((4, 8, 3), np.uint8))
    items = [{"id": i + 1, "kind": kind, "centroid_px": [1.0, 2.0], "bbox_px": [0, 0, 3, 3],
              "centroid_m": [0.0, 0.0, 2.0], "area_m2": area, "max_depth_mm": depth, "mean_depth_mm": depth / 2,
              "volume_l": vol, "decided_share": share, "low_confidence": share < 0.5}
             for i, (kind, depth, area, vol, share) in enumerate(defects)]
    (folder / "defects.json").write_text(json.dumps({"defects": items, "warnings": list(warnings)}))


def test_road_section_lists_every_defect_and_the_batch_totals(tmp_path):
    _road_pair(tmp_path / "shallow", [("pothole", 25.0, 0.02, 0.3, 0.9)])
    _road_pair(tmp_path / "deep pair", [("pothole", 61.5, 0.1, 3.25, 0.95), ("pothole", 30.0, 0.05, 1.0, 0.2),
                                        ("bump", 22.0, 0.01, 0.1, 0.9)])
    _road_pair(tmp_path / "flat", [], warnings=["no defects: the scene is not road-like"])
    (tmp_path / "defects.csv").write_text("pair,id\n")
    rows = [{"pair": p, "status": "ok", "psnr": 20.0} for p in ("shallow", "deep pair", "flat", "nocam")]
    text = write_report_html(tmp_path, rows, title="t").read_text()
    parser = Collector()
    parser.feed(text)
    parser.close()
    assert parser.stack == []
    for link in parser.links:  # every link resolves, the pair with a space included
        assert (link[1:] in parser.ids) if link.startswith("#") else (tmp_path / unquote(link)).is_file(), link
    road = text[text.index('<h2 id="road">'):text.index("<h2>Pairs by error")]
    # Totals: 3 of 4 pairs have a report, 2 with defects, 3 potholes, 1 bump, 1 low confidence,
    # pothole area 0.17 m^2 and volume 4.55 l, the deepest is #1 of "deep pair".
    totals = re.findall(r"<td>(.*?)</td>", road[:road.index("</table>")])
    assert totals[:7] == ["3 of 4", "2", "3", "1", "1", "0.170", "4.55"]
    assert "deep pair</a> #1 62 mm" in totals[7]
    # Cards: deepest pothole first, one table row per defect with its figures.
    assert road.index('id="road-deep pair"') < road.index('id="road-shallow"')
    card = road[road.index('id="road-deep pair"'):road.index('id="road-shallow"')]
    assert card.count("<tr") == 4 and "61.5" in card and "3.25" in card and ">20</td>" in card
    assert card.count(">low<") == 1 and 'href="deep%20pair/defects.png"' in card
    assert "No defects: flat (no defects: the scene is not road-like)" in road
    assert "nocam (no road report)" in road and 'href="defects.csv"' in road


def test_no_road_section_without_road_outputs(tmp_path):
    text = write_report_html(tmp_path, [{"pair": "a", "status": "ok", "epe": 1.0}], title="t").read_text()
    assert 'id="road"' not in text


def test_histogram_of_equal_values_near_the_float_limit():
    svg = histogram_svg([3e38, 3e38], label="EPE [px]", bins=4)
    assert svg.count("<rect") == 4 and svg.count(": 2</title>") == 1 and svg.count(": 0</title>") == 3
    assert ">3e+38</text>" in svg
    svg = histogram_svg([-1.7e308, 1.7e308], label="EPE [px]", bins=2)  # the span overflows float64
    assert svg.count(": 1</title>") == 2


def test_columns_have_names_with_units_and_only_the_shown_ones_are_defined(tmp_path):
    rows = [{"pair": "a", "family": "k", "status": "ok", "epe": 1.25, "d1_all": 4.0, "bad_2_noc": 7.5,
             "pep_3": 3.0, "a90_noc": 2.0, "time_s": 1.5},
            {"pair": "b", "family": "k", "status": "failed", "error": "b: right.png: not a PNG file;\n  fix it"},
            {"pair": "c", "family": "k", "status": "skipped", "error": "no right image"}]
    text = write_report_html(tmp_path, rows, title="t").read_text()
    heads = re.findall(r'<th title="[^"]*">([^<]*)</th>', text[:text.index("<h2>Means per family")])
    # The shown columns (summary.shown_columns): bad 2, A90 and PEP 3 stay in metrics.csv.
    assert heads == ["EPE [px]", "D1 (all) [%]", "time [s]"]
    d1_definition = html.escape(metric("d1_all").definition)
    assert d1_definition.startswith("KITTI")
    assert f'<th title="{d1_definition}">D1 (all) [%]</th>' in text
    definitions = text[text.index('<h2 id="definitions">'):text.index("<h2>Config")]
    assert re.findall(r"<dt>(.*?)</dt>", definitions) == heads  # defined: what is shown, nothing else
    assert "bad-2" not in text and "A90" not in text and "PEP 3" not in text
    assert "a pixel without an estimate counts as d = 0" in definitions and "README" not in text
    failed = text[text.index('<h2 id="failures">Failed pairs</h2>'):text.index('<h2 id="definitions">')]
    assert "<li><b>b</b>: right.png: not a PNG file; fix it</li>" in failed  # the pair named once
    pair_b = text[text.index('<tbody><tr class="failed"><td class="t">b</td>'):]
    pair_b = pair_b[:pair_b.index("</tbody>")]
    assert '<a href="#failures">failed</a>' in pair_b  # the status links to the list ...
    assert pair_b.endswith('<tr class="failed"><td class="msg" colspan="6">right.png: not a PNG file; fix it</td></tr>')
    assert '<h2 id="skipped">Left-out pairs</h2><ul class="failed">\n<li><b>c</b>: no right image</li>' in failed
    assert "<b>a</b> EPE 1.250 px, D1 (all) 4.00 %<br>" in text
    assert "<h2>Histogram of per-pair EPE [px]</h2>" in text
    assert '<p class="problems failed">0 warnings, <a href="#failures">1 error</a>.' in text


def test_summary_md_names_the_columns_as_the_page_does_and_defines_them(tmp_path):
    from d3cli.evaluation.report import write_summary

    rows = [{"pair": "a", "family": "k", "status": "ok", "epe": 1.0, "pep_1": 2.0, "time_s": 1.0}]
    _, md = write_summary(tmp_path, rows, method="m")
    lines = md.read_text().splitlines()
    assert "| pair | status | EPE [px] | PEP 1 [%] | time [s] |" in lines
    tail = lines[lines.index("## Definitions"):]
    assert tail[4:] == ["- **EPE [px]**: End-point error: mean of e, over the non-occluded pixels where a mask "
                        "exists, else all.",
                        "- **PEP 1 [%]**: Percentage of error pixels: 100 x share of EPE's pixels with e > 1 px.",
                        "- **time [s]**: Wall time of the pair in the run that made its map: reading, matching, "
                        "writing and scoring."]


def test_road_cards_show_each_potholes_diameter_and_astm_severity(tmp_path):
    _road_pair(tmp_path / "p", [("pothole", 61.5, 0.1, 3.25, 0.95), ("bump", 22.0, 0.01, 0.1, 0.9)])
    data = json.loads((tmp_path / "p" / "defects.json").read_text())
    data["defects"][0].update(diameter_mm=356.8, severity="high")  # as d3cli.road writes them
    (tmp_path / "p" / "defects.json").write_text(json.dumps(data))
    text = write_report_html(tmp_path, [{"pair": "p", "status": "ok"}], title="t").read_text()
    card = text[text.index('id="road-p"'):]
    assert "<th>severity (ASTM D6433)</th>" in card and "<th>diameter [mm]</th>" in card
    rows = re.findall(r"<tr[^>]*>(.*?)</tr>", card[card.index("<tbody>"):card.index("</tbody>")])
    cells = [re.findall(r">([^<]*)</td>", row) for row in rows]
    assert cells[0][5:8] == ["357", "3.25", "high"] and cells[1][5:8] == ["–", "0.10", "–"]


def test_road_section_shows_the_survey_summary_by_severity(tmp_path):
    _road_pair(tmp_path / "p", [("pothole", 61.5, 0.1, 3.25, 0.95)])
    survey = {"frames": 4, "potholes": 3, "bumps": 1, "low_confidence": 1,
              "by_severity": {"low": 1.0, "medium": 0.0, "high": 2.5, "none": 0},
              "potholes_per_frame": 0.75, "frame_spacing_m": 5.0, "length_km": 0.02, "potholes_per_km": 150.0}
    (tmp_path / "road_survey.json").write_text(json.dumps(survey))  # as d3cli.road.outputs writes it
    text = write_report_html(tmp_path, [{"pair": "p", "status": "ok"}], title="t").read_text()
    road = text[text.index('<h2 id="road">'):]
    survey_html = road[road.index('id="road-survey"'):]
    survey_html = survey_html[:survey_html.index("</table>")]
    assert re.findall(r"<th>(.*?)</th>", survey_html) == [
        "frames", "potholes", "per frame", "survey length [km]", "per km", "low", "medium", "high", "no level"]
    assert re.findall(r"<td>(.*?)</td>", survey_html) == ["4", "3", "0.75", "0.02", "150", "1", "0", "2.5", "0"]
    assert 'href="road_survey.json"' in road

    # Without road.frame_spacing_m the survey has no length: no per-km figures.
    del survey["frame_spacing_m"], survey["length_km"], survey["potholes_per_km"]
    (tmp_path / "road_survey.json").write_text(json.dumps(survey))
    text = write_report_html(tmp_path, [{"pair": "p", "status": "ok"}], title="t").read_text()
    survey_html = text[text.index('id="road-survey"'):]
    survey_html = survey_html[:survey_html.index("</table>")]
    assert re.findall(r"<td>(.*?)</td>", survey_html) == ["4", "3", "0.75", "–", "–", "1", "0", "2.5", "0"]
