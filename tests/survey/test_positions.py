"""Where each frame was taken: track.csv, GPX, EXIF GPS tags; headings from the fixes;
malformed tracks refused with one Error line naming the file, the line and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("pyproj")
pytest.importorskip("shapely")

from click.testing import CliRunner  # noqa: E402
from pyproj import Geod  # noqa: E402

from d3cli.cli import main  # noqa: E402
from d3cli.errors import InputError  # noqa: E402
from d3cli.survey.positions import (EXIF_SOURCE, Fix, fill_headings, frame_positions, read_gpx,  # noqa: E402
                                    read_track_csv, track_length_m)

GEOD = Geod(ellps="WGS84")


def _frames(root: Path, names) -> dict:
    out = {}
    for name in names:
        (root / name).mkdir(parents=True, exist_ok=True)
        out[name] = root / name / "left.png"
    return out


def test_track_csv_gives_fixes_in_row_order_and_empty_rows_are_unplaced(tmp_path):
    frames = _frames(tmp_path, ["a", "b", "c", "d"])
    (tmp_path / "track.csv").write_text("\ufefftime,frame,longitude,latitude,heading_deg,extra\n"
                                        "t0,b,11.5,48.1,10,x\n"
                                        "t1,a,11.5,48.10005,,x\n"
                                        "t2,c,,,,x\n")
    assert read_track_csv(tmp_path / "track.csv") == {"b": Fix(48.1, 11.5, 10.0, None, "t0"),
                                                      "a": Fix(48.10005, 11.5, None, None, "t1"), "c": None}
    pos = frame_positions(frames, folders=[tmp_path])
    assert pos.source == str(tmp_path / "track.csv")
    assert pos.placed == ["b", "a"] and pos.unplaced == ["c", "d"]
    assert pos.headings["b"] == 10.0 and pos.heading_from == {"b": "track", "a": "fixes"}
    assert pos.headings["a"] == pytest.approx(0.0, abs=1e-6)  # due north, from b to a
    assert track_length_m(pos) == pytest.approx(GEOD.inv(11.5, 48.1, 11.5, 48.10005)[2])


def test_gpx_named_points_and_unnamed_points_in_sorted_frame_order(tmp_path):
    frames = _frames(tmp_path, ["f2", "f1", "f3"])
    pts = [(48.1, 11.5), (48.1001, 11.5), (48.1001, 11.5002)]

    def gpx(names):
        body = "".join(f'<trkpt lat="{la}" lon="{lo}"><ele>500</ele>{f"<name>{n}</name>" if n else ""}</trkpt>'
                       for (la, lo), n in zip(pts, names))
        return ('<?xml version="1.0"?><gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1">'
                f"<trk><trkseg>{body}</trkseg></trk></gpx>")

    (tmp_path / "named.gpx").write_text(gpx(["f3", "f1", "f2"]))
    fixes = read_gpx(tmp_path / "named.gpx", list(frames))
    assert list(fixes) == ["f3", "f1", "f2"] and fixes["f1"] == Fix(48.1001, 11.5, None, 500.0)
    (tmp_path / "plain.gpx").write_text(gpx([None, None, None]))
    pos = frame_positions(frames, track=tmp_path / "plain.gpx")
    assert pos.placed == ["f1", "f2", "f3"] and pos.fixes["f3"].longitude == 11.5002
    assert pos.headings["f1"] == pytest.approx(0.0, abs=1e-6)
    assert pos.headings["f3"] == pytest.approx(GEOD.inv(11.5, 48.1001, 11.5002, 48.1001)[0] % 360)


def test_exif_gps_tags_of_the_left_images(tmp_path):
    from PIL import Image

    frames = _frames(tmp_path, ["p0", "p1", "p2"])
    for i, name in enumerate(frames):
        img = Image.new("RGB", (32, 24), (90, 90, 90))
        exif = Image.Exif()
        if name != "p2":  # p2: no GPS tags
            exif[0x8825] = {1: "S", 2: (33.0, 51.0, 54.0 + i), 3: "W", 4: (151.0, 12.0, 36.0), 16: "T", 17: 181.5}
        frames[name] = tmp_path / name / "left.jpg"
        img.save(frames[name], exif=exif)
    pos = frame_positions(frames, folders=[tmp_path])
    assert pos.source == EXIF_SOURCE and pos.unplaced == ["p2"]
    assert pos.fixes["p0"].latitude == pytest.approx(-(33 + 51 / 60 + 54 / 3600))
    assert pos.fixes["p1"].longitude == pytest.approx(-(151 + 12 / 60 + 36 / 3600))
    assert pos.headings == {"p0": 181.5, "p1": 181.5}
    # Images without GPS tags and no track: no positions, nothing changes.
    assert frame_positions({"p2": frames["p2"]}, folders=[tmp_path]) is None


def _fix_at(lon, lat, az, dist):
    lo, la, _ = GEOD.fwd(lon, lat, az, dist)
    return Fix(la, lo)


def test_headings_from_the_fixes_follow_an_arc_stand_still_and_end_with_the_previous_bearing():
    # A circular arc, 5 m apart, turning 2 degrees per metre: the chord through a frame's
    # neighbours is the arc's tangent at the frame.
    fixes, heading, lon, lat = {}, 40.0, 11.5, 48.1
    truth = {}
    for i in range(6):
        fixes[f"f{i}"] = Fix(lat, lon)
        truth[f"f{i}"] = heading
        lon, lat, _ = GEOD.fwd(lon, lat, heading + 5.0, 5.0)
        heading += 10.0
    headings, source = fill_headings(list(fixes), fixes)
    for name in ["f1", "f2", "f3", "f4"]:
        assert headings[name] == pytest.approx(truth[name], abs=0.01)
    assert headings["f0"] == pytest.approx(truth["f0"] + 5.0, abs=0.01)  # s / 2R off at the ends
    last = GEOD.inv(fixes["f4"].longitude, fixes["f4"].latitude, fixes["f5"].longitude, fixes["f5"].latitude)[0]
    assert headings["f5"] == pytest.approx(last % 360)
    assert set(source.values()) == {"fixes"}

    # The car stood still: f1's neighbours f0 and f2 coincide; f1 takes its nearest valid one.
    a = Fix(48.1, 11.5)
    b = _fix_at(11.5, 48.1, 90.0, 0.01)  # 1 cm: GPS noise, no direction
    c = _fix_at(11.5, 48.1, 90.0, 5.0)
    still = {"f0": a, "f1": b, "f2": Fix(a.latitude, a.longitude), "f3": c}
    headings, _ = fill_headings(list(still), still)
    assert headings["f1"] == pytest.approx(headings["f2"]) == pytest.approx(90.0, abs=0.01)
    assert headings["f0"] == pytest.approx(90.0, abs=1.0)
    # A single fix without a heading: no heading, the frame is unplaced.
    assert fill_headings(["f0"], {"f0": a}) == ({}, {})


@pytest.fixture
def pair_root(tmp_path, make_pair_folder):
    root = tmp_path / "pairs"
    for name in ("f0001", "f0002"):
        make_pair_folder(root, name, size=(32, 64), gt=False)
    return root


BAD_TRACKS = [
    ("frame,lat,lon\nf0001,48.1,11.5\n", "{p}, line 1: the header lacks the columns latitude, longitude; start the "
                                         "file with the header frame,latitude,longitude[,heading_deg][,altitude_m][,time]"),
    ("frame,latitude,longitude\nf0001,48.1,11.5\nf0002,abc,11.5\n",
     "{p}, line 3: latitude 'abc' is not a number; write latitude in decimal degrees north (south negative), e.g. 48.137154"),
    ("frame,latitude,longitude\nf0001,48.1,191.5\n",
     "{p}, line 2: longitude 191.5 is outside -180..180; write longitude in decimal degrees east (west negative), e.g. 11.576124"),
    ("frame,latitude,longitude\nf0001,48.1,11.5,7\n",
     "{p}, line 2: 4 fields where the header has 3; write one value per column (empty for none)"),
    ("frame,latitude,longitude\nf0001,48.1,11.5\n\nf0001,48.2,11.5\n",
     "{p}, line 4: frame 'f0001' is listed again (first on line 2); give each frame once"),
    ("frame,latitude,longitude\nf0001,,11.5\n",
     "{p}, line 2: latitude is empty; give both latitude and longitude, or leave both empty for a frame without a fix"),
    ("frame,latitude,longitude,heading_deg\nf0001,48.1,11.5,400\n",
     "{p}, line 2: heading_deg 400 is outside 0..360; write heading_deg in degrees clockwise from north, e.g. 87.5"),
    ("frame,latitude,longitude\nother,48.1,11.5\n",
     "{p}: names none of the 2 frames of this run (its first is 'other', the run's first 'f0001'); name each frame by "
     "its pair folder in the frame column (or <name>)"),
    ("", "{p}: is empty; write the header frame,latitude,longitude[,heading_deg][,altitude_m][,time] and one row per frame"),
]


@pytest.mark.parametrize("text, message", BAD_TRACKS)
def test_a_malformed_track_is_one_error_line_before_any_pair_is_computed(pair_root, tmp_path, text, message):
    track = tmp_path / "track.csv"
    track.write_text(text)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(pair_root), "-o", str(out), "--method", "sgbm", "--road-report",
                                       "--track", str(track)])
    assert result.exit_code != 0
    assert result.output.strip().splitlines() == ["Error: " + message.format(p=track)]
    assert not out.exists()  # refused before the batch


def test_bad_gpx_files_name_the_point_and_the_fix(pair_root, tmp_path):
    def run(text):
        track = tmp_path / "t.gpx"
        track.write_text(text)
        result = CliRunner().invoke(main, ["run", str(pair_root), "-o", str(tmp_path / "o"), "--road-report",
                                           "--track", str(track)])
        assert result.exit_code != 0 and "Traceback" not in result.output
        return result.output.strip().splitlines(), track

    lines, t = run('<gpx><trk><trkseg><trkpt lat="48.1" lon="11.5"/></trkseg></trk></gpx>')
    assert lines == [f"Error: {t}: 1 track points without <name> for 2 frames; name each point after its frame "
                     "(<name>frame</name>) or give exactly one point per frame"]
    lines, t = run('<gpx><trk><trkseg><trkpt lat="48.1" lon="11.5"><name>f0001</name></trkpt>'
                   '<trkpt lat="48.1"><name>f0002</name></trkpt></trkseg></trk></gpx>')
    assert lines == [f'Error: {t}, track point 2: has no lat or lon attribute; write <trkpt lat="48.137154" '
                     'lon="11.576124">']
    lines, t = run("<gpx><trk>\n<trkseg>\n<trkpt></trk></gpx>")
    assert len(lines) == 1 and lines[0].startswith(f"Error: {t}, line 3: not valid XML (")


def test_a_track_without_the_gis_libraries_is_an_error_naming_the_install(pair_root, tmp_path, monkeypatch):
    import d3cli.survey.gis as gis

    monkeypatch.setattr(gis.importlib.util, "find_spec", lambda name: None)
    track = tmp_path / "track.csv"
    track.write_text("frame,latitude,longitude\nf0001,48.1,11.5\nf0002,48.1001,11.5\n")
    result = CliRunner().invoke(main, ["run", str(pair_root), "-o", str(tmp_path / "o"), "--road-report",
                                       "--track", str(track)])
    assert result.exit_code != 0
    assert result.output.strip().splitlines() == [
        f'Error: {track}: a map of the defects needs pyproj and shapely, which are not installed; install them '
        'with pip install "d3stereo[gis]"']
    with pytest.raises(InputError):
        frame_positions({"f0001": tmp_path / "l.png"}, track=track)
