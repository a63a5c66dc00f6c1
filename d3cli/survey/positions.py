"""Where each frame was taken: its fix (latitude, longitude; WGS84 degrees) and heading.

Sources, the first that exists:

1. the track given as ``--track FILE`` (``road.track``), else ``track.csv`` or
   ``track.gpx`` in the folder that holds the pair folders;
2. the GPS tags of each left image's EXIF (``GPSLatitude``/``Ref``,
   ``GPSLongitude``/``Ref``, ``GPSImgDirection`` as the heading, ``GPSAltitude``).

``track.csv``: a header naming ``frame,latitude,longitude`` and optionally
``heading_deg``, ``altitude_m``, ``time`` (any order; other columns are ignored), then one
row per frame in the order driven; ``frame`` is the pair folder's name, the heading the
bearing of travel in degrees clockwise from north.  A row whose latitude and longitude
are both empty is a frame without a fix.  A GPX 1.1 file: its track points (``trkpt``,
``lat``/``lon``, optional ``ele`` and ``time``) in the order driven, each named after its
frame (``<name>``); points without names are matched to the frames in sorted order, and
only when there are as many points as frames.

A frame without a fix is still measured (its defects.json and defects.csv rows) and is
listed as unplaced.  A track that cannot be read is an :class:`~d3cli.errors.InputError`
naming the file, the line (or track point) and the fix.

Headings not given are the bearing of the chord through the frame's two neighbours
(:func:`fill_headings`), which is the tangent of the path at the frame on any circular arc
driven at constant spacing; the first and the last frame take the bearing to and from
their one neighbour.  Where the two neighbours coincide (the car stood still) the frame
takes the heading of the nearest frame that has one.
"""

from __future__ import annotations

import csv
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError, readable, shorten, where_what_fix
from .gis import geod, require_gis

#: Names of a track beside the pair folders, in the order they are looked for.
TRACK_NAMES = ("track.csv", "track.gpx")
#: What a track.csv header must and may name.
CSV_REQUIRED = ("frame", "latitude", "longitude")
CSV_OPTIONAL = ("heading_deg", "altitude_m", "time")
CSV_HEADER = "frame,latitude,longitude[,heading_deg][,altitude_m][,time]"
#: Two fixes nearer than this (metres) give no heading: GPS noise, not travel.
MIN_BASE_M = 0.05
EXIF_SOURCE = "EXIF GPS tags of the left images"
_GPS_IFD = 0x8825


@dataclass(frozen=True)
class Fix:
    """Where a frame was taken: the point on the road below the stereo rig's mid-point.

    Attributes
    ----------
    latitude, longitude : float
        WGS84 degrees.
    heading_deg : float or None
        Bearing of travel, degrees clockwise from north, as given (None: from the fixes).
    altitude_m : float or None
    time : str or None
    """

    latitude: float
    longitude: float
    heading_deg: float | None = None
    altitude_m: float | None = None
    time: str | None = None


@dataclass
class Positions:
    """The frames' fixes and headings.

    Attributes
    ----------
    source : str
        The track file, or :data:`EXIF_SOURCE`.
    fixes : dict
        Frame -> :class:`Fix`, in the order driven.
    headings : dict
        Frame -> heading used, degrees clockwise from north.
    heading_from : dict
        Frame -> ``"track"`` (given) or ``"fixes"`` (:func:`fill_headings`).
    unplaced : list of str
        Frames of the run without a fix (or without any heading: a single fix that gives none).
    """

    source: str
    fixes: dict
    headings: dict = field(default_factory=dict)
    heading_from: dict = field(default_factory=dict)
    unplaced: list = field(default_factory=list)

    @property
    def placed(self) -> list[str]:
        """Frames with a fix and a heading, in the order driven."""
        return [f for f in self.fixes if f in self.headings]


def _fail(where: str, what: str, fix: str):
    raise InputError(where_what_fix(readable(where), readable(what), fix))


#: How each number of a track is written (the fix of an error message).
_UNITS = {"latitude": "decimal degrees north (south negative), e.g. 48.137154",
          "longitude": "decimal degrees east (west negative), e.g. 11.576124",
          "heading_deg": "degrees clockwise from north, e.g. 87.5", "altitude_m": "metres, e.g. 512.3"}


def _number(text: str, name: str, where: str, low: float, high: float) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        _fail(where, f"{name} {shorten(text)!r} is not a number", f"write {name} in {_UNITS[name]}")
    if not low <= value <= high:
        _fail(where, f"{name} {value:g} is outside {low:g}..{high:g}", f"write {name} in {_UNITS[name]}")
    return value


def _fix_of(values: dict, where: str) -> Fix | None:
    """A :class:`Fix` from text values (None: latitude and longitude both empty)."""
    lat_text, lon_text = (values.get(k, "").strip() for k in ("latitude", "longitude"))
    if not lat_text and not lon_text:
        return None
    if not lat_text or not lon_text:
        _fail(where, f"{'latitude' if not lat_text else 'longitude'} is empty",
              "give both latitude and longitude, or leave both empty for a frame without a fix")
    lat = _number(lat_text, "latitude", where, -90.0, 90.0)
    lon = _number(lon_text, "longitude", where, -180.0, 180.0)
    heading = values.get("heading_deg", "").strip()
    alt = values.get("altitude_m", "").strip()
    return Fix(lat, lon,
               _number(heading, "heading_deg", where, 0.0, 360.0) % 360.0 if heading else None,
               _number(alt, "altitude_m", where, -1e4, 1e5) if alt else None,
               values.get("time", "").strip() or None)


def read_track_csv(path: str | Path) -> dict[str, Fix | None]:
    """Frame -> :class:`Fix` (None: a row without a fix) of a ``track.csv``, in row order.

    Raises
    ------
    InputError
        The file cannot be read, its header lacks a column, or a row is malformed
        (``<file>, line <n>: <what>; <fix>``).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        _fail(str(path), "not a UTF-8 text file", f"write the track as CSV with the header {CSV_HEADER}")
    except OSError as exc:
        _fail(str(path), f"cannot be read ({exc.strerror or exc})", "give an existing track.csv or GPX file")
    rows = list(csv.reader(text.splitlines()))
    lines = [(i + 1, row) for i, row in enumerate(rows) if any(cell.strip() for cell in row)]
    if not lines:
        _fail(str(path), "is empty", f"write the header {CSV_HEADER} and one row per frame")
    head_line, head = lines[0]
    names = [h.strip().lower() for h in head]
    missing = [c for c in CSV_REQUIRED if c not in names]
    if missing:
        _fail(f"{path}, line {head_line}", f"the header lacks the column{'s' * (len(missing) > 1)} {', '.join(missing)}",
              f"start the file with the header {CSV_HEADER}")
    fixes: dict[str, Fix | None] = {}
    first: dict[str, int] = {}
    for n, row in lines[1:]:
        where = f"{path}, line {n}"
        if len(row) != len(names):
            _fail(where, f"{len(row)} fields where the header has {len(names)}",
                  "write one value per column (empty for none)")
        values = dict(zip(names, row))
        frame = values["frame"].strip()
        if not frame:
            _fail(where, "the frame is empty", "name the frame's pair folder in the frame column")
        if frame in first:
            _fail(where, f"frame {shorten(frame)!r} is listed again (first on line {first[frame]})",
                  "give each frame once")
        first[frame] = n
        fixes[frame] = _fix_of(values, where)
    if not fixes:
        _fail(str(path), "has a header but no rows", "add one row per frame")
    return fixes


def _local(tag: str) -> str:
    return tag.rpartition("}")[2]


def read_gpx(path: str | Path, frames: list[str]) -> dict[str, Fix]:
    """Frame -> :class:`Fix` of a GPX file's track points, in track order.

    Parameters
    ----------
    path : path
    frames : list of str
        The run's frames: points without ``<name>`` are matched to them in sorted order
        when there are as many.

    Raises
    ------
    InputError
        Not GPX, a point without a valid lat/lon, unnamed points that do not match the frames
        one to one (``<file>, track point <n>: <what>; <fix>``).
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        _fail(str(path), f"cannot be read ({exc.strerror or exc})", "give an existing track.csv or GPX file")
    if b"<!DOCTYPE" in raw[:4096] or b"<!ENTITY" in raw:
        _fail(str(path), "declares a DOCTYPE or entities, which a GPX file has no use for",
              "export the track again as plain GPX 1.1")
    try:
        root = ET.fromstring(raw)
    except ET.ParseError as exc:
        line = exc.position[0] if getattr(exc, "position", None) else "?"
        _fail(f"{path}, line {line}", f"not valid XML ({shorten(str(exc))})", "export the track again as GPX 1.1")
    if _local(root.tag) != "gpx":
        _fail(str(path), f"the root element is <{shorten(_local(root.tag))}>, not <gpx>",
              "give a GPX 1.1 file or a track.csv")
    points = [el for el in root.iter() if _local(el.tag) == "trkpt"]
    if not points:
        _fail(str(path), "has no track points (<trkpt>)", "record a track (trk/trkseg/trkpt) with one point per frame")
    items = []
    for i, el in enumerate(points, 1):
        where = f"{path}, track point {i}"
        child = {_local(c.tag): (c.text or "").strip() for c in el}
        if "lat" not in el.attrib or "lon" not in el.attrib:
            _fail(where, "has no lat or lon attribute", 'write <trkpt lat="48.137154" lon="11.576124">')
        fix = _fix_of({"latitude": el.attrib["lat"], "longitude": el.attrib["lon"],
                       "altitude_m": child.get("ele", ""), "time": child.get("time", "")}, where)
        items.append((child.get("name") or None, fix, where))
    named = [name for name, _, _ in items if name]
    if named and len(named) != len(items):
        where = next(w for name, _, w in items if not name)
        _fail(where, "has no <name> while other points have", "name every point after its frame, or none")
    if not named:
        ordered = sorted(frames)
        if len(items) != len(ordered):
            _fail(str(path), f"{len(items)} track points without <name> for {len(ordered)} frames",
                  "name each point after its frame (<name>frame</name>) or give exactly one point per frame")
        return {frame: fix for frame, (_, fix, _) in zip(ordered, items)}
    fixes: dict[str, Fix] = {}
    for name, fix, where in items:
        if name in fixes:
            _fail(where, f"frame {shorten(name)!r} is named again", "give each frame one point")
        fixes[name] = fix
    return fixes


def read_track(path: str | Path, frames: list[str]) -> dict[str, Fix | None]:
    """A track file (:func:`read_gpx` for ``.gpx`` or a file starting with ``<``, else
    :func:`read_track_csv`)."""
    path = Path(path)
    if not path.is_file():
        _fail(str(path), "no such file" if not path.exists() else "not a file",
              "give an existing track.csv or GPX file")
    with path.open("rb") as f:
        start = f.read(64).lstrip(b"\xef\xbb\xbf \t\r\n")
    if path.suffix.lower() == ".gpx" or start.startswith(b"<"):
        return read_gpx(path, frames)
    return read_track_csv(path)


def find_track(folders) -> Path | None:
    """The first :data:`TRACK_NAMES` file in ``folders`` (the folders that hold the pair folders)."""
    for folder in folders:
        for name in TRACK_NAMES:
            if (Path(folder) / name).is_file():
                return Path(folder) / name
    return None


def _rational(value) -> float:
    if isinstance(value, tuple) and len(value) == 2 and not isinstance(value[0], tuple):
        return float(value[0]) / float(value[1])
    return float(value)


def exif_fix(image: str | Path) -> Fix | None:
    """The :class:`Fix` of an image's EXIF GPS tags, or None (no tags, not readable)."""
    try:
        from PIL import Image

        with Image.open(image) as im:
            gps = im.getexif().get_ifd(_GPS_IFD)
        if not gps or 2 not in gps or 4 not in gps:
            return None
        lat = sum(_rational(v) / 60.0 ** k for k, v in enumerate(gps[2]))
        lon = sum(_rational(v) / 60.0 ** k for k, v in enumerate(gps[4]))
        lat = -lat if str(gps.get(1, "N")).strip().upper().startswith("S") else lat
        lon = -lon if str(gps.get(3, "E")).strip().upper().startswith("W") else lon
        heading = _rational(gps[17]) % 360.0 if 17 in gps else None
        alt = _rational(gps[6]) * (-1 if gps.get(5) in (1, b"\x01") else 1) if 6 in gps else None
    except Exception:  # noqa: BLE001 - any unreadable image or tag: no fix, the frame is unplaced
        return None
    if not (math.isfinite(lat) and math.isfinite(lon) and abs(lat) <= 90 and abs(lon) <= 180):
        return None
    return Fix(lat, lon, heading, alt)


def fill_headings(order: list[str], fixes: dict[str, Fix]) -> tuple[dict[str, float], dict[str, str]]:
    """Heading of every frame of ``order`` (module docstring): given, else from the fixes.

    Parameters
    ----------
    order : list of str
        The frames with a fix, in the order driven.
    fixes : dict
        Frame -> :class:`Fix`.

    Returns
    -------
    headings : dict
        Frame -> degrees clockwise from north; a frame is missing only when no frame gives a
        heading (a single fix without one, or a car that never moved).
    source : dict
        Frame -> ``"track"`` or ``"fixes"``.
    """
    n = len(order)
    bearing: list[float | None] = [None] * n
    for i in range(n):
        a, b = max(i - 1, 0), min(i + 1, n - 1)
        if a == b:
            continue
        fa, fb = fixes[order[a]], fixes[order[b]]
        az, _, dist = geod().inv(fa.longitude, fa.latitude, fb.longitude, fb.latitude)
        if dist >= MIN_BASE_M:
            bearing[i] = az % 360.0
    valid = [i for i in range(n) if bearing[i] is not None]
    headings, source = {}, {}
    for i, frame in enumerate(order):
        if fixes[frame].heading_deg is not None:
            headings[frame], source[frame] = fixes[frame].heading_deg, "track"
        elif valid:
            j = min(valid, key=lambda k: (abs(k - i), k))
            headings[frame], source[frame] = bearing[j], "fixes"
    return headings, source


def frame_positions(frames: dict[str, Path], *, track: str | Path | None = None,
                    folders=()) -> Positions | None:
    """The positions of the run's frames, or None when there are none (no track, no EXIF GPS).

    Parameters
    ----------
    frames : dict
        Frame (pair name) -> its left image, in the run's order.
    track : path, optional, keyword-only
        The track file given (``--track``, ``road.track``); else one of
        :data:`TRACK_NAMES` in ``folders``, else the EXIF of the left images.
    folders : iterable of Path, keyword-only
        The folders that hold the pair folders.

    Raises
    ------
    InputError
        A track that cannot be read, or that names none of the frames; pyproj or shapely
        missing (:func:`~d3cli.survey.gis.require_gis`) where positions exist.
    """
    names = list(frames)
    path = Path(track) if track else find_track(folders)
    if path is not None:
        read = read_track(path, names)
        if not any(f in read for f in names):
            example = next(iter(read))
            _fail(str(path), f"names none of the {len(names)} frames of this run (its first is {shorten(example)!r}, "
                             f"the run's first {shorten(names[0]) if names else '-'!r})",
                  "name each frame by its pair folder in the frame column (or <name>)")
        fixes = {f: fix for f, fix in read.items() if f in frames and fix is not None}
        source = str(path)
    else:
        fixes = {}
        for f in sorted(names):
            fix = exif_fix(frames[f])
            if fix is not None:
                fixes[f] = fix
        if not fixes:
            return None
        source = EXIF_SOURCE
    require_gis(source)
    order = list(fixes)
    headings, heading_from = fill_headings(order, fixes)
    unplaced = [f for f in names if f not in headings]
    return Positions(source=source, fixes=fixes, headings=headings, heading_from=heading_from, unplaced=unplaced)


def track_length_m(positions: Positions) -> float:
    """Geodesic length of the drive: the sum of the distances between consecutive fixes."""
    pts = [positions.fixes[f] for f in positions.fixes]
    if len(pts) < 2:
        return 0.0
    lons = [p.longitude for p in pts]
    lats = [p.latitude for p in pts]
    return float(geod().line_length(lons, lats))
