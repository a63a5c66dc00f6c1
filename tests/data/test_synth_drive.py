"""`d3stereo synth --drive`: overlapping frames along a road, a GPS track and the potholes'
map positions, all exact (re-derived here from the frames' own ground truth)."""

from __future__ import annotations

import csv
import json
import math
import sys
import xml.etree.ElementTree as ET
from datetime import datetime

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.cli import main
from d3cli.data import formats, synth
from d3cli.data.synth import StereoRig, generate_drive
from d3cli.data.synth.drive import DRIVE_TRUTH, TRACK_CSV, TRACK_GPX
from d3cli.errors import InputError, OutputError

pyproj = pytest.importorskip("pyproj")
GEOD = pyproj.Geod(ellps="WGS84")

W, H, FRAMES, SEED, POTHOLES = 160, 96, 6, 5, 2
ARGS = dict(frames=FRAMES, seed=SEED, width=W, height=H, potholes=POTHOLES)


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    out = tmp_path_factory.mktemp("drive")
    folders = generate_drive(out, **ARGS)
    return out, folders


@pytest.fixture(scope="module")
def truth(drive):
    return json.loads((drive[0] / DRIVE_TRUTH).read_text())


@pytest.fixture(scope="module")
def track(drive):
    with open(drive[0] / TRACK_CSV, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _defects(folder):
    return json.loads((folder / "defects_gt.json").read_text())["potholes"]


def _rig(folder) -> StereoRig:
    calib = dict(line.split(": ") for line in (folder / "calib.txt").read_text().splitlines())
    return StereoRig(*(float(calib[k]) for k in ("f", "baseline", "cx", "cy")), int(calib["width"]),
                     int(calib["height"]), *(float(calib[k]) for k in ("height_m", "pitch_deg", "roll_deg")))


def test_frames_are_pair_folders_of_one_rig(drive):
    out, folders = drive
    assert [f.name for f in folders] == [f"drive-{k:04d}" for k in range(FRAMES)]
    for folder in folders:
        assert {p.name for p in folder.iterdir()} >= {"left.png", "right.png", "disp_gt.pfm", "mask0nocc.png",
                                                     "calib.txt", "defects_gt.json", "potholes_gt.png", "SOURCE.txt"}
    # One calibration (ndisp, the disparity range, is each frame's own).
    calibs = {"\n".join(line for line in (f / "calib.txt").read_text().splitlines() if not line.startswith("ndisp"))
              for f in folders}
    rigs = {_rig(f) for f in folders}
    assert len(rigs) == 1 and len(calibs) == 1


def test_every_pothole_is_seen_by_two_frames_or_more(drive, truth):
    out, folders = drive
    assert len(truth["potholes"]) == POTHOLES
    for pothole in truth["potholes"]:
        in_view = [f for f in pothole["frames"] if 0 <= f["u"] <= W - 1 and 0 <= f["v"] <= H - 1]
        assert len(in_view) >= 2, pothole["frames"]
        for seen in pothole["frames"]:
            (entry,) = [e for e in _defects(out / seen["frame"]) if e["id"] == seen["id"]]
            assert entry["visible_px"] == seen["visible_px"] > 0
            # The profile's truth is the same in every frame and in drive_gt.json.
            assert entry["depth_mm"] == pytest.approx(pothole["depth_mm"], abs=1e-9)
            assert entry["area_m2"] == pytest.approx(pothole["area_m2"], rel=2e-3)
            assert entry["volume_l"] == pytest.approx(pothole["volume_l"], rel=2e-3)
    # Frames really overlap: a pothole moves down the image from one frame to the next.
    vs = [f["v"] for f in truth["potholes"][0]["frames"]]
    assert vs == sorted(vs) and vs[-1] - vs[0] > H / 3


def test_pothole_position_rederived_from_each_frame_matches_to_1_cm(drive, truth, track):
    out, _ = drive
    fixes = {row["frame"]: row for row in track}
    checked = 0
    for pothole in truth["potholes"]:
        for seen in pothole["frames"]:
            folder = out / seen["frame"]
            rig = _rig(folder)
            (entry,) = [e for e in _defects(folder) if e["id"] == seen["id"]]
            # u, v is where the pothole's centre at its depth projects: back onto z = -depth.
            centre = rig.centres()[0]
            ray = rig.ray_directions(np.array(entry["u"]), np.array(entry["v"]))
            t = (-entry["depth_mm"] / 1e3 - centre[2]) / ray[2]
            x, y = centre[0] + t * ray[0], centre[1] + t * ray[1]
            fix = fixes[seen["frame"]]
            lon, lat, _ = GEOD.fwd(float(fix["longitude"]), float(fix["latitude"]),
                                   float(fix["heading_deg"]) + math.degrees(math.atan2(x, y)), math.hypot(x, y))
            _, _, error = GEOD.inv(lon, lat, pothole["longitude"], pothole["latitude"])
            assert error < 0.01
            checked += 1
    assert checked >= 2 * POTHOLES


def test_outline_encloses_the_area_deeper_than_10_mm(truth):
    for pothole in truth["potholes"]:
        ring = np.array(pothole["outline_lonlat"])
        assert (ring[0] == ring[-1]).all()
        area, _ = GEOD.polygon_area_perimeter(ring[:, 0], ring[:, 1])
        assert abs(area) == pytest.approx(pothole["area_m2"], rel=0.05)
        _, _, offset = GEOD.inv(pothole["opening_centroid"]["longitude"], pothole["opening_centroid"]["latitude"],
                                pothole["longitude"], pothole["latitude"])
        assert offset < max(pothole["semi_axes_m"])


def test_track_csv_steps_spacing_along_its_heading(drive, truth, track):
    out, folders = drive
    spacing = truth["drive"]["spacing_m"]
    assert [row["frame"] for row in track] == [f.name for f in folders]
    assert list(track[0]) == ["frame", "latitude", "longitude", "heading_deg", "altitude_m", "time"]
    heading = float(track[0]["heading_deg"])
    assert not any(abs(heading - cardinal) < 1.0 for cardinal in (0, 90, 180, 270, 360))
    times = [datetime.fromisoformat(row["time"].replace("Z", "+00:00")) for row in track]
    assert all(b > a for a, b in zip(times, times[1:])) and times[0].tzinfo is not None
    for a, b in zip(track, track[1:]):
        azimuth, _, distance = GEOD.inv(float(a["longitude"]), float(a["latitude"]),
                                        float(b["longitude"]), float(b["latitude"]))
        assert distance == pytest.approx(spacing, abs=1e-3)
        assert abs((azimuth - float(a["heading_deg"]) + 180.0) % 360.0 - 180.0) < 0.1
    for row, fix in zip(track, truth["frames"]):
        assert float(row["latitude"]) == pytest.approx(fix["latitude"], abs=1e-9)
        assert row["time"] == fix["time"]


def test_gpx_holds_the_same_points(drive, track):
    root = ET.parse(drive[0] / TRACK_GPX).getroot()
    ns = {"g": "http://www.topografix.com/GPX/1/1"}
    assert root.tag == "{http://www.topografix.com/GPX/1/1}gpx" and root.get("version") == "1.1"
    points = root.findall("g:trk/g:trkseg/g:trkpt", ns)
    assert len(points) == len(track)
    for point, row in zip(points, track):
        assert (point.get("lat"), point.get("lon")) == (row["latitude"], row["longitude"])
        assert point.findtext("g:name", namespaces=ns) == row["frame"]
        assert point.findtext("g:time", namespaces=ns) == row["time"]
        assert point.findtext("g:ele", namespaces=ns) == row["altitude_m"]


def test_disparity_ground_truth_passes_the_self_test(drive):
    for folder in drive[1][::2]:
        pair = synth.SynthPair(cv2.imread(str(folder / "left.png"), cv2.IMREAD_GRAYSCALE),
                               cv2.imread(str(folder / "right.png"), cv2.IMREAD_GRAYSCALE),
                               formats.read_pfm(folder / "disp_gt.pfm"),
                               cv2.imread(str(folder / "mask0nocc.png"), cv2.IMREAD_GRAYSCALE) > 0, {})
        assert synth.self_test(pair) < 4.0


def test_same_arguments_give_the_same_files_other_ones_are_refused(drive, tmp_path):
    out, _ = drive
    again = tmp_path / "again"
    generate_drive(again, **ARGS)
    mine = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert mine == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for rel in mine:
        assert (out / rel).read_bytes() == (again / rel).read_bytes(), rel
    with pytest.raises(OutputError, match=r"it holds a synthetic drive of 6 frames with seed 5 and size 160x96\); "
                                          r"give an empty or new folder, or the same --drive/--seed"):
        generate_drive(again, **{**ARGS, "seed": SEED + 1})
    with pytest.raises(OutputError, match="synthetic drive of 6 frames"):
        generate_drive(again, **{**ARGS, "gps_noise": 1.0})


def test_gps_noise_moves_the_track_not_the_truth(tmp_path):
    out = tmp_path / "noisy"
    generate_drive(out, frames=2, seed=SEED, width=W, height=H, potholes=0, gps_noise=1.5)
    truth = json.loads((out / DRIVE_TRUTH).read_text())
    with open(out / TRACK_CSV, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    errors = [GEOD.inv(float(r["longitude"]), float(r["latitude"]), f["longitude"], f["latitude"])[2]
              for r, f in zip(rows, truth["frames"])]
    assert all(0.0 < e < 10.0 for e in errors)
    assert truth["potholes"] == [] and truth["drive"]["gps_noise_m"] == 1.5


@pytest.mark.parametrize("args, message", [
    (["--drive", "0"], "Error: synth: --drive is 0; ask for at least one frame"),
    (["--drive", "3", "--spacing", "0"], "Error: synth: --spacing is 0.0; give the metres between frames, > 0"),
    (["--drive", "3", "--spacing", "-1.5"], "Error: synth: --spacing is -1.5;"),
    (["--drive", "3", "--n", "2"], "Error: synth: --n and --drive both given;"),
    (["--spacing", "1"], "Error: synth: --spacing given without --drive;"),
    (["--drive", "3", "--gps-noise", "-1"], "Error: synth: --gps-noise is -1.0;"),
    (["--drive", "3", "--potholes", "40", "--width", "64", "--height", "48"], "Error: synth: --potholes 40: only "),
])
def test_bad_arguments_give_one_error_line(tmp_path, args, message):
    result = CliRunner().invoke(main, ["synth", str(tmp_path / "d"), *args])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.output.count("\n") == 1 and result.output.startswith(message), result.output
    assert not (tmp_path / "d").exists()


def test_missing_pyproj_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyproj", None)  # import pyproj then raises ImportError
    with pytest.raises(InputError, match=r'pip install "d3stereo\[gis\]"'):
        generate_drive(tmp_path / "d", frames=2, width=W, height=H)
    assert not (tmp_path / "d").exists()


def test_left_images_carry_their_fix_in_exif(drive, track):
    from PIL import ExifTags, Image

    for folder, row in zip(drive[1], track):
        with Image.open(folder / "left.png") as image:
            gps = image.getexif().get_ifd(ExifTags.IFD.GPSInfo)
        lat = sum(float(part) / 60 ** i for i, part in enumerate(gps[ExifTags.GPS.GPSLatitude]))
        lon = sum(float(part) / 60 ** i for i, part in enumerate(gps[ExifTags.GPS.GPSLongitude]))
        lat *= -1 if gps[ExifTags.GPS.GPSLatitudeRef] == "S" else 1
        lon *= -1 if gps[ExifTags.GPS.GPSLongitudeRef] == "W" else 1
        assert (lat, lon) == pytest.approx((float(row["latitude"]), float(row["longitude"])), abs=1e-8)
        assert float(gps[ExifTags.GPS.GPSImgDirection]) == pytest.approx(float(row["heading_deg"]), abs=1e-6)


def test_a_pothole_whose_window_ends_just_before_a_frame_is_left_out_of_it(tmp_path):
    # Seed 17: a pothole's outline bound (1.4 semi-axes) reaches into a frame's patch while
    # the window the height field draws it in (1.25) ends centimetres before it.
    out = tmp_path / "edge"
    generate_drive(out, frames=8, seed=17, width=W, height=H, potholes=3)
    truth = json.loads((out / DRIVE_TRUTH).read_text())
    assert len(truth["potholes"]) == 3 and all(len(p["frames"]) >= 2 for p in truth["potholes"])
