"""The map's files from a drive with known poses: each pothole once and in its place,
GeoJSON that GIS readers take (pyogrio, shapely), the track, the per-km figure."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from dataclasses import replace

import pytest

pytest.importorskip("pyproj")
pytest.importorskip("shapely")

from shapely.geometry import shape  # noqa: E402

from d3cli.config import Config  # noqa: E402
from d3cli.survey import survey_map  # noqa: E402

from .drive import GEOD, pothole, straight_track, write_drive  # noqa: E402


def _cfg(**road):
    cfg = Config()
    return replace(cfg, road=replace(cfg.road, report=True, **road))


FIVE = [(12.0, 0.5, 0.15, 30), (40.0, -1.0, 0.2, 60), (41.2, -1.0, 0.12, 20), (90.0, 0.8, 0.25, 15),
        (150.0, 0.0, 0.2, 45)]


def _potholes(lons, lats, heads, specs=FIVE):
    """Potholes along the drive: (distance along, right offset, radius, depth) each."""
    out = []
    for along, right, radius, depth in specs:
        i = int(along // 5.0)
        lo, la, _ = GEOD.fwd(lons[i], lats[i], heads[i], along - 5.0 * i)
        lo, la, _ = GEOD.fwd(lo, la, heads[i] + 90.0, right)
        out.append(pothole(lo, la, radius, depth))
    return out


@pytest.fixture
def drive(tmp_path):
    lons, lats, heads = straight_track(40, 5.0, heading=30.0)
    pits = _potholes(lons, lats, heads)
    inp, out, pairs = write_drive(tmp_path, lons, lats, heads, pits, unplaced=("f0039",))
    return inp, out, pairs, pits


def test_each_pothole_is_on_the_map_once_and_in_its_place(drive):
    inp, out, pairs, pits = drive
    summary = survey_map(out, pairs, _cfg())
    features = json.loads((out / "defects.geojson").read_text())["features"]
    assert len(features) == len(pits) == summary["defects"] == summary["potholes"]
    assert summary["sightings"] > summary["defects"] and summary["merged"] == summary["sightings"] - len(pits)
    assert summary["unplaced"] == ["f0039"] and summary["frames_placed"] == 39
    for f, p in zip(features, pits):  # in the order driven
        props = f["properties"]
        assert props["sightings"] == len(props["seen"]) == len(props["frames"]) >= 2
        assert GEOD.inv(p["lon"], p["lat"], props["longitude"], props["latitude"])[2] < 0.01
        assert props["best_frame"] in props["frames"] and props["depth_mm"] == pytest.approx(
            next(s["depth_mm"] for s in props["seen"] if s["frame"] == props["best_frame"]))
        # The best sighting is the nearest (all equally decided): the smallest depth along the axis.
        assert min(s["range_m"] for s in props["seen"]) == next(
            s["range_m"] for s in props["seen"] if s["frame"] == props["best_frame"])
    survey = json.loads((out / "road_survey.json").read_text())
    assert survey["length_from"] == "track" and survey["length_km"] == pytest.approx(38 * 5.0 / 1e3, rel=1e-3)
    assert survey["potholes_per_km"] == pytest.approx(len(pits) / (38 * 5.0 / 1e3), rel=1e-3)
    assert survey["map"]["defects"] == len(pits)


def test_the_geojson_is_what_gis_readers_take(drive):
    pyogrio = pytest.importorskip("pyogrio")
    inp, out, pairs, pits = drive
    survey_map(out, pairs, _cfg())
    info = pyogrio.read_info(out / "defects.geojson")
    assert info["features"] == len(pits) and info["geometry_type"] == "Polygon"
    assert info["crs"] == "EPSG:4326"
    meta, fids, geometry, fields = pyogrio.raw.read(out / "defects.geojson")
    names = list(meta["fields"])
    for key in ("id", "kind", "depth_mm", "area_m2", "volume_l", "severity", "confidence", "reasons", "sightings",
                "frames", "best_frame", "longitude", "latitude"):
        assert key in names
    assert list(fields[names.index("sightings")]) == [len(json.loads((out / "defects.geojson").read_text())
                                                          ["features"][i]["properties"]["frames"]) for i in range(5)]
    for f in json.loads((out / "defects.geojson").read_text())["features"]:
        geom = shape(f["geometry"])
        ring = f["geometry"]["coordinates"][0]
        assert geom.is_valid and geom.exterior.is_ccw and ring[0] == ring[-1]
        assert all(11.0 < lon < 12.0 and 48.0 < lat < 48.2 for lon, lat in ring)  # lon, lat order
        assert geom.contains(shape({"type": "Point", "coordinates": [f["properties"]["longitude"],
                                                                     f["properties"]["latitude"]]}))
    track = pyogrio.read_info(out / "track.geojson")
    assert track["features"] == 1 + 39
    line = json.loads((out / "track.geojson").read_text())["features"][0]
    assert line["geometry"]["type"] == "LineString" and len(line["geometry"]["coordinates"]) == 39
    assert line["properties"]["unplaced_frames"] == ["f0039"]
    assert shape(line["geometry"]).is_valid


def test_heading_from_the_track_and_a_rig_ahead_of_the_antenna(tmp_path):
    # The same drive with headings in the track and the antenna 2 m behind the rig.
    lons, lats, heads = straight_track(12, 5.0, heading=200.0, curve_deg_per_m=0.8)
    pits = _potholes(lons, lats, heads, [(22.0, 0.7, 0.2, 40)])
    # The fixes are the antenna's: 2 m behind the rig's mid-point.
    moved = [GEOD.fwd(lo, la, hd + 180.0, 2.0)[:2] for lo, la, hd in zip(lons, lats, heads)]
    inp, out, pairs = write_drive(tmp_path, lons, lats, heads, pits, heading_in_track=True)
    track = ["frame,latitude,longitude,heading_deg"] + [f"f{i:04d},{la:.9f},{lo:.9f},{hd % 360:.6f}"
                                                        for i, ((lo, la), hd) in enumerate(zip(moved, heads))]
    (inp / "track.csv").write_text("\n".join(track) + "\n")
    survey_map(out, pairs, _cfg(antenna_forward_m=-2.0))
    [f] = json.loads((out / "defects.geojson").read_text())["features"]
    assert GEOD.inv(pits[0]["lon"], pits[0]["lat"], f["properties"]["longitude"], f["properties"]["latitude"])[2] < 0.01
    points = json.loads((out / "track.geojson").read_text())["features"][1:]
    assert {p["properties"]["heading_from"] for p in points} == {"track"}


def test_no_positions_no_map_and_an_earlier_map_is_removed(drive, caplog):
    inp, out, pairs, pits = drive
    survey_map(out, pairs, _cfg())
    assert (out / "defects.geojson").is_file() and (out / "track.geojson").is_file()
    (inp / "track.csv").unlink()
    before = (out / "road_survey.json").read_text()
    assert survey_map(out, pairs, _cfg()) is None
    assert not (out / "defects.geojson").exists() and not (out / "track.geojson").exists()
    assert (out / "road_survey.json").read_text() == before
    # A file of the same name that is not d3stereo's is left alone.
    (out / "track.geojson").write_text('{"type": "FeatureCollection", "features": []}')
    survey_map(out, pairs, _cfg())
    assert (out / "track.geojson").is_file()
    # A broken track beside the frames after the batch: a warning, no map, never a failure.
    (inp / "track.csv").write_text("frame,latitude\n")
    with caplog.at_level(logging.WARNING):
        assert survey_map(out, pairs, _cfg()) is None
    assert "no map of the defects" in caplog.text and "the header lacks the column longitude" in caplog.text


def test_bench_drive_scores_the_map_against_the_drive_truth(drive, capsys):
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_drive", Path(__file__).parents[2] / "scripts" / "bench_drive.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    inp, out, pairs, pits = drive
    survey_map(out, pairs, _cfg())
    truth = [{"latitude": p["lat"], "longitude": p["lon"], "depth_mm": p["depth_mm"], "area_m2": 0.1, "frames": ["x"]}
             for p in pits] + [{"latitude": 48.2, "longitude": 11.6, "depth_mm": 20.0, "area_m2": 0.1, "frames": []}]
    (inp / "drive_gt.json").write_text(json.dumps({"potholes": truth}))
    s = bench.score_drive(out, inp / "drive_gt.json")
    assert s["matched"] == len(pits) and s["missed"] == [] and s["duplicates"] == [] and s["false"] == []
    assert s["seen_by_no_frame"] == 1 and s["median_position_error_m"] < 0.01
    # A pothole put on the map twice (one sighting moved 0.5 m) is a duplicate.
    data = json.loads((out / "defects.geojson").read_text())
    extra = json.loads(json.dumps(data["features"][0]))
    lon, lat, _ = GEOD.fwd(extra["properties"]["longitude"], extra["properties"]["latitude"], 0.0, 0.5)
    extra["properties"].update(id=99, longitude=lon, latitude=lat)
    data["features"].append(extra)
    (out / "defects.geojson").write_text(json.dumps(data))
    assert bench.main([str(out)]) == 0  # the truth beside the track
    printed = capsys.readouterr().out
    assert "duplicates 1" in printed and f"matched within 0.3 m: {len(pits)} of {len(pits)}" in printed


def test_the_survey_line_ends_with_the_map(drive):
    from d3cli.road.outputs import survey_line

    inp, out, pairs, pits = drive
    (out / "defects.csv").write_text("pair,id,kind,max_depth_mm,low_confidence,flags,severity\n")
    assert "on the map" not in survey_line(out)
    summary = survey_map(out, pairs, _cfg())
    line = survey_line(out)
    assert line.endswith(f"; none flagged; 5 defects on the map ({summary['merged']} sightings merged), "
                         "1 frame unplaced") and "\n" not in line


def test_a_track_beside_the_frames_without_the_gis_libraries_is_a_warning(drive, caplog, monkeypatch):
    import d3cli.survey.gis as gis
    from d3cli.survey import check_positions

    inp, out, pairs, pits = drive
    monkeypatch.setattr(gis.importlib.util, "find_spec", lambda name: None)
    with caplog.at_level(logging.WARNING):
        check_positions(pairs, _cfg())  # no Error: the run goes on without a map
        assert survey_map(out, pairs, _cfg()) is None
    assert (f'{inp / "track.csv"}: no map of the defects: pyproj and shapely are not installed; install them with '
            'pip install "d3stereo[gis]"') in caplog.text
    assert not (out / "defects.geojson").exists()
    # Without the road report a track beside the frames is not even read.
    (inp / "track.csv").write_text("broken")
    check_positions(pairs, replace(_cfg(), road=replace(_cfg().road, report=False)))
