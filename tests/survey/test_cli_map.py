"""The map through ``d3stereo run``: tiny synthetic pairs with a track.csv beside them, and
the map of report.html as a browser renders it."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from dataclasses import replace

import pytest

pytest.importorskip("pyproj")
pytest.importorskip("shapely")

from click.testing import CliRunner  # noqa: E402

from d3cli.cli import main  # noqa: E402
from d3cli.config import Config  # noqa: E402
from d3cli.evaluation.html import write_report_html  # noqa: E402
from d3cli.survey import survey_map  # noqa: E402

from .drive import GEOD, pothole, straight_track, write_drive  # noqa: E402

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.slow
def test_run_with_a_track_beside_the_frames_writes_the_map(tmp_path):
    inp, out = tmp_path / "in", tmp_path / "out"
    runner = CliRunner()
    done = runner.invoke(main, ["synth", str(inp), "--n", "2", "--width", "160", "--height", "96", "-q"])
    assert done.exit_code == 0, done.output
    names = sorted(p.name for p in inp.iterdir() if p.is_dir())
    args = ["run", str(inp), "-o", str(out), "--method", "sgbm", "--road-report"]
    # Without a track nothing changes: no map files, the survey line as before.
    done = runner.invoke(main, args)
    assert done.exit_code == 0, done.output
    assert not (out / "defects.geojson").exists() and "on the map" not in done.output
    assert 'id="road-map"' not in (out / "report.html").read_text()
    # With a track.csv beside the pair folders (the pairs are skipped as complete).
    (inp / "track.csv").write_text(f"frame,latitude,longitude\n{names[0]},48.1,11.5\n{names[1]},48.10004,11.50002\n")
    done = runner.invoke(main, args)
    assert done.exit_code == 0, done.output
    road = next(line for line in done.output.splitlines() if line.startswith("road: "))
    assert re.search(r"; \d+ defects? on the map \(\d+ sightings? merged\), 0 frames unplaced$", road)
    track = json.loads((out / "track.geojson").read_text())
    assert track["features"][0]["geometry"]["type"] == "LineString"
    assert track["features"][0]["properties"]["frames"] == names
    assert json.loads((out / "defects.geojson").read_text())["type"] == "FeatureCollection"
    survey = json.loads((out / "road_survey.json").read_text())
    assert survey["length_from"] == "track" and survey["length_km"] == pytest.approx(
        GEOD.inv(11.5, 48.1, 11.50002, 48.10004)[2] / 1e3, abs=1e-4)
    page = (out / "report.html").read_text()
    assert 'id="road-map"' in page and '<svg class="map"' in page and 'href="defects.geojson"' in page
    # --track naming another file wins over the one beside the frames; a third frame of the
    # track (not in this run) is ignored.
    other = tmp_path / "drive.gpx"
    other.write_text('<gpx version="1.1"><trk><trkseg>' + "".join(
        f'<trkpt lat="{48.2 + 0.0001 * i}" lon="11.6"><name>{n}</name></trkpt>' for i, n in enumerate(names + ["x"]))
        + "</trkseg></trk></gpx>")
    done = runner.invoke(main, args + ["--track", str(other)])
    assert done.exit_code == 0, done.output
    line = json.loads((out / "track.geojson").read_text())["features"][0]
    assert line["properties"]["source"] == str(other) and line["geometry"]["coordinates"][0] == [11.6, 48.2]


def _drive_page(tmp_path):
    lons, lats, heads = straight_track(30, 5.0, heading=60.0, curve_deg_per_m=0.6)
    pits = []
    for k, (i, right, depth) in enumerate([(4, 0.5, 30), (9, -1.0, 60), (15, 0.8, 15), (22, 0.0, 45)]):
        lo, la, _ = GEOD.fwd(lons[i], lats[i], heads[i], 2.0)
        lo, la, _ = GEOD.fwd(lo, la, heads[i] + 90.0, right)
        pits.append(pothole(lo, la, 0.2, depth))
    inp, out, pairs = write_drive(tmp_path, lons, lats, heads, pits, unplaced=("f0029",))
    # One flagged defect: every sighting of the third pothole is low confidence.
    for pair in pairs:
        path = out / pair.name / "defects.json"
        data = json.loads(path.read_text())
        for d in data["defects"]:
            if d["truth"] == 2:
                d.update(confidence="low", low_confidence=True, flags=["wet"], reasons="wet or specular surface")
            d["severity"] = ["low", "high", "medium", "low"][d["truth"]]
        path.write_text(json.dumps(data))
    cfg = Config()
    survey_map(out, pairs, replace(cfg, road=replace(cfg.road, report=True)))
    write_report_html(out, [{"pair": p.name, "status": "ok"} for p in pairs], title="drive")
    return out


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed")
def test_the_map_renders_in_a_headless_browser(tmp_path):
    out = _drive_page(tmp_path / "drive")
    page = out / "report.html"
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path / 'u'}",
                           "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr[-2000:]
    dom = done.stdout
    svg = dom[dom.index('<svg class="map"'):dom.index("</svg>")]
    assert svg.count('<polyline class="track"') == 1 and svg.count('class="frame"') == 29
    assert svg.count('<g class="defect') == 4 and svg.count('<g class="defect flagged"') == 1
    assert 'class="north"' in svg and re.search(r'<g class="scale">.*?>\d+ k?m</text>', svg)
    assert "http" not in svg.replace("http://www.w3.org/2000/svg", "")  # nothing fetched: no tiles
    assert "1 frame without a position (measured, not on the map): f0029." in dom
    table = dom[dom.index('id="map-defects"'):]
    assert len(re.findall(r"<tr", table[:table.index("</table>")])) == 1 + 4
    # The picture: the map is drawn (not blank) where the page puts it.
    shot = tmp_path / "map.png"
    view = out / "map_view.html"
    text = page.read_text()
    view.write_text(text[:text.index("<body>") + 6] + text[text.index('<h3 id="road-map">'):text.index("</svg>") + 6])
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={tmp_path / 'u'}",
                    f"--screenshot={shot}", "--window-size=1000,900", view.as_uri()], capture_output=True, timeout=60)
    import cv2

    img = cv2.imread(str(shot))
    assert img is not None and img.shape[:2] == (900, 1000)
    red = (img[..., 2] > 180) & (img[..., 1] < 80) & (img[..., 0] < 80)  # the high-severity pothole's fill
    assert red.sum() > 50
