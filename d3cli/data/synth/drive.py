"""A synthetic drive: overlapping stereo frames along a straight road, a GPS track and the
potholes' map positions (:func:`generate_drive`).

Coordinates
-----------
*Road* coordinates (metres) are those of frame 0 extended along the road: ``x`` across it,
positive to the right of the direction of travel, ``y`` along it from the first fix, ``z``
up.  Frame ``k`` is rendered by one fixed rig (:class:`~.rig.StereoRig`, drawn once per
seed) whose mid-point stands above road point ``(0, k * spacing)``; the frame's own (local)
coordinates are the road's shifted by ``k * spacing`` along ``y``, so the rig sits at local
``(0, 0, height_m)`` as in every synthetic pair.

The road is a geodesic on the WGS84 ellipsoid from a start fix drawn near one of a few
cities, with a heading drawn at random.  The fix of frame ``k`` (the *antenna*) is the
road point directly below the rig's mid-point, local ``(0, 0, 0)``; consecutive fixes
are one geodesic step of ``spacing`` metres apart (``pyproj.Geod.fwd``), the heading of
each is the forward azimuth of the road there.  A local point ``(x, y)`` of frame ``k``
lies at ``Geod.fwd(lon_k, lat_k, heading_k + atan2(x, y), hypot(x, y))``.

Every frame draws its own road texture, millimetre undulation and pothole floor relief;
the road's cross slope and grade and the potholes' profiles (position, outline,
orientation, depth) are those of the drive, the same in every frame that sees them.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import logging
import math
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from ...config import INSTALL_GIS
from ...errors import InputError, OutputError, where_what_fix
from ..formats import atomic_write
from .dataset import (_check_memory, _check_size, _claim_folder, _dress_scene, _grid_steps, _out_of_memory,
                      _render_scene, _surface, _visible_patch, _write_pair)
from .potholes import FAMILIES, Pothole, pothole_weight, varied_pothole
from .render import _sample_lighting
from .rig import StereoRig, _road_bounds, sample_rig
from .terrain import _classic_pothole, _RoadShape
from .truth import _OPENING_M, _TRUTH_GRID_M, _group_grid

log = logging.getLogger(__name__)

#: Files a drive writes beside its frame folders.
TRACK_CSV, TRACK_GPX, DRIVE_TRUTH = "track.csv", "track.gpx", "drive_gt.json"

# Mixed into every seed of a drive, so that its frames never repeat a pair of
# generate_dataset (whose pair seeds come from [seed, index]).
_DRIVE_STREAM = 0x64726976

# Start points: city centres on land with streets all around; a start is drawn within
# about 5 km of one of them.
_PLACES = ((48.137, 11.575), (52.520, 13.405), (45.464, 9.190), (40.416, -3.703), (51.507, -0.128),
           (43.651, -79.383), (35.690, 139.692), (-33.869, 151.209), (39.739, -104.990), (59.329, 18.069))

# Families drawn on a drive: a water-filled pothole's visible floor is the water, not the
# profile the drive's truth describes, so that family is left out.
_DRIVE_FAMILIES = tuple(f for f in FAMILIES if f != "water")

# The default spacing puts every pothole centre in this many frames' views or more.
_MIN_VIEWS = 2
_SPACING_SHARE = 1.0 / (_MIN_VIEWS + 0.5)  # of the footprint length; the 0.5 absorbs rounding
_OUTLINE_RAYS = 72  # vertices of a pothole's outline polygon
_PLACEMENT_TRIES = 400


@dataclass(frozen=True)
class Footprint:
    """The stretch of road (metres, frame coordinates) where a pothole centre is seen.

    A centre at lateral ``|x| <= half_width`` and along ``near <= y <= far`` projects into
    the left image both at the road level and 75 mm below it (the deepest floor).
    """

    near: float
    far: float
    half_width: float

    @property
    def length(self) -> float:
        """``far - near``, metres."""
        return self.far - self.near


@dataclass(frozen=True)
class Fix:
    """One GPS fix of the track: where frame ``frame``'s antenna is.

    ``heading_deg`` is the bearing of travel, clockwise from north in [0, 360);
    ``altitude_m`` the road's mean level at the fix; ``time`` ISO 8601 UTC.
    """

    frame: str
    along_m: float
    latitude: float
    longitude: float
    heading_deg: float
    altitude_m: float
    time: str


@dataclass(frozen=True)
class DrivePothole:
    """A pothole of the drive: ``hole`` in road coordinates (``hole.x`` lateral,
    ``hole.y`` along), ``id`` 1-based in order along the road."""

    id: int
    hole: Pothole


def _geod():
    """A WGS84 ``pyproj.Geod``; pyproj is optional (the ``gis`` extra)."""
    try:
        from pyproj import Geod
    except ImportError as exc:
        raise InputError(where_what_fix("synth --drive", "the GPS track needs pyproj, which is not installed",
                                        f"install it with {INSTALL_GIS}")) from exc
    return Geod(ellps="WGS84")


def frame_name(index: int) -> str:
    """Folder name of frame ``index``: ``drive-0000``."""
    return f"drive-{index:04d}"


def footprint(rig: StereoRig) -> Footprint:
    """Where a pothole centre is seen by the left camera of ``rig`` (:class:`Footprint`).

    The lateral band is half the road width the bottom image row sees (the narrowest),
    so a centre anywhere in it is in view over one interval of ``y``.
    """
    left = rig.centres()[0]
    corners = rig.ray_directions(np.array([0.0, rig.width - 1.0]), np.array([rig.height - 1.0] * 2))
    xs = left[0] - left[2] * corners[:, 0] / corners[:, 2]
    half_width = 0.5 * float(min(-xs[0], xs[1]))
    _, _, y_min, y_max = _road_bounds(rig, -0.1, 0.0, 0.0)
    ys = np.arange(y_min, y_max, 1e-3)
    seen = np.ones(ys.shape, bool)
    for x in np.linspace(-half_width, half_width, 21):
        for z in (0.0, -0.075):
            seen &= _in_left_image(rig, np.full(ys.shape, x), ys, z)
    if not seen.any():  # cannot happen for the rigs sample_rig draws
        raise RuntimeError("the rig sees no road ahead")
    return Footprint(float(ys[seen].min()), float(ys[seen].max()), half_width)


def _in_left_image(rig: StereoRig, x: np.ndarray, y: np.ndarray, z: float) -> np.ndarray:
    """Whether world points (x, y, z) project inside the left image."""
    cam = (np.stack([x, y, np.full(x.shape, z)], -1) - rig.centres()[0]) @ rig.rotation().T
    u = rig.f * cam[:, 0] / cam[:, 2] + rig.cx
    v = rig.f * cam[:, 1] / cam[:, 2] + rig.cy
    return (cam[:, 2] > 0) & (u >= 0) & (u <= rig.width - 1) & (v >= 0) & (v <= rig.height - 1)


def default_spacing(rig: StereoRig) -> float:
    """Metres between frames that put every pothole centre in at least two frames' views:
    the footprint length over 2.5, rounded down to the centimetre."""
    return max(0.01, math.floor(100.0 * footprint(rig).length * _SPACING_SHARE) / 100.0)


def _placement_range(foot: Footprint, frames: int, spacing: float) -> tuple[float, float]:
    """Along-road interval for pothole centres: where every frame that could see a centre
    exists (or, on a drive too short for that, where all frames see it)."""
    lo, hi = foot.far, (frames - 1) * spacing + foot.near
    if hi <= lo:
        lo, hi = (frames - 1) * spacing + foot.near, foot.far
    if hi <= lo:
        lo, hi = foot.near, (frames - 1) * spacing + foot.far
    return lo, hi


def _reach(hole: Pothole) -> float:
    """Radius (metres) beyond which ``hole`` does not lower the road (outline harmonics
    included)."""
    return 1.4 * max(hole.semi_a, hole.semi_b)


def _drawn_reach(hole: Pothole) -> float:
    """Half the side of the square window the height field and the truth draw ``hole``
    in (``terrain._grid_window``, ``truth._group_grid``)."""
    return 1.25 * max(hole.semi_a, hole.semi_b)


def _sample_drive_potholes(rng, count: int | None, foot: Footprint, frames: int, spacing: float
                           ) -> tuple[DrivePothole, ...]:
    """Potholes along the road, none overlapping another; ``count`` None: one per 3 m of
    the placement range (at least one)."""
    lo, hi = _placement_range(foot, frames, spacing)
    if count is None:
        count = max(1, int((hi - lo) / 3.0))
    shape_rng = rng.spawn(1)[0]
    start = int(shape_rng.integers(0, len(_DRIVE_FAMILIES)))
    holes: list[Pothole] = []
    for k in range(count):
        hole = varied_pothole(_classic_pothole(rng, 0.0, 0.0), shape_rng,
                              _DRIVE_FAMILIES[(start + k) % len(_DRIVE_FAMILIES)])
        for _ in range(_PLACEMENT_TRIES):
            x, y = rng.uniform(-foot.half_width, foot.half_width), rng.uniform(lo, hi)
            if all(math.hypot(x - o.x, y - o.y) > _reach(hole) + _reach(o) for o in holes):
                holes.append(dataclasses.replace(hole, x=float(x), y=float(y)))
                break
        else:
            raise InputError(where_what_fix(
                "synth", f"--potholes {count}: only {len(holes)} fit on {frames} frames {spacing:g} m apart "
                         "without overlapping", "ask for fewer potholes or more frames"))
    holes.sort(key=lambda h: h.y)
    return tuple(DrivePothole(i + 1, h) for i, h in enumerate(holes))


@dataclass(frozen=True)
class _Road:
    """Where and when the drive happens, and the road's shape (drawn once)."""

    latitude: float
    longitude: float
    heading_deg: float
    altitude_m: float
    start: datetime
    speed_mps: float
    shape: _RoadShape  # undulation, cross slope and grade; holes in road coordinates


def _sample_drive_road(rng, holes: tuple[DrivePothole, ...]) -> _Road:
    lat0, lon0 = _PLACES[int(rng.integers(0, len(_PLACES)))]
    latitude = lat0 + rng.uniform(-0.045, 0.045)
    longitude = lon0 + rng.uniform(-0.045, 0.045) / math.cos(math.radians(lat0))
    heading = float(rng.uniform(0.0, 360.0))
    altitude = float(rng.uniform(20.0, 600.0))
    start = datetime(2025, 1, 1, tzinfo=timezone.utc) + timedelta(days=int(rng.integers(0, 365)),
                                                                 seconds=float(rng.uniform(7, 17)) * 3600.0)
    speed = float(rng.uniform(5.0, 12.0))
    shape = _RoadShape(rng.uniform(1.5e-3, 3.5e-3), rng.uniform(-0.015, 0.015), rng.uniform(-0.015, 0.015),
                       tuple(p.hole for p in holes), None, False)
    return _Road(float(latitude), float(longitude), heading, altitude, start, speed, shape)


def _iso(moment: datetime) -> str:
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _track(geod, road: _Road, frames: int, spacing: float) -> list[Fix]:
    """The exact fixes: geodesic steps of ``spacing`` from the start."""
    fixes = []
    lon, lat, heading = road.longitude, road.latitude, road.heading_deg
    for k in range(frames):
        along = k * spacing
        fixes.append(Fix(frame_name(k), along, lat, lon, heading % 360.0,
                         road.altitude_m + road.shape.grade * along,
                         _iso(road.start + timedelta(seconds=along / road.speed_mps))))
        lon, lat, back = geod.fwd(lon, lat, heading, spacing)
        heading = (back + 180.0) % 360.0
    return fixes


def local_to_geo(geod, fix: Fix, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude (degrees) of local points (x right, y ahead, metres) of the
    frame whose antenna is at ``fix``."""
    x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
    azimuth = fix.heading_deg + np.degrees(np.arctan2(x, y))
    lon, lat, _ = geod.fwd(np.full(x.shape, fix.longitude), np.full(x.shape, fix.latitude), azimuth, np.hypot(x, y))
    return np.asarray(lon), np.asarray(lat)


def _road_to_geo(geod, fixes: list[Fix], spacing: float, x, y) -> tuple[np.ndarray, np.ndarray]:
    """Longitude and latitude of road points, each from the last fix before it."""
    x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
    k = int(np.clip(math.floor(float(np.mean(y)) / spacing), 0, len(fixes) - 1))
    return local_to_geo(geod, fixes[k], x, y - fixes[k].along_m)


def _noisy(geod, fixes: list[Fix], sigma_m: float, rng) -> list[Fix]:
    """The fixes with a Gaussian error of ``sigma_m`` metres std north and east each."""
    if sigma_m <= 0:
        return fixes
    out = []
    for fix in fixes:
        north, east = rng.normal(0.0, sigma_m, 2)
        lon, lat, _ = geod.fwd(fix.longitude, fix.latitude, math.degrees(math.atan2(east, north)),
                               math.hypot(north, east))
        out.append(dataclasses.replace(fix, latitude=float(lat), longitude=float(lon)))
    return out


def _outline(hole: Pothole) -> tuple[np.ndarray, np.ndarray]:
    """The 10 mm-deep contour of ``hole``'s profile: along each of 72 rays from its centre,
    the outermost point deeper than 10 mm (0.1 mm steps); road x, y (closed ring)."""
    angles = np.linspace(0.0, 2.0 * math.pi, _OUTLINE_RAYS, endpoint=False)
    radii = np.arange(0.0, _reach(hole), 1e-4)
    xx = hole.x + np.cos(angles)[:, None] * radii[None, :]
    yy = hole.y + np.sin(angles)[:, None] * radii[None, :]
    deep = hole.depth * pothole_weight(hole, xx, yy) > _OPENING_M
    last = np.where(deep.any(axis=1), radii.size - 1 - np.argmax(deep[:, ::-1], axis=1), 0)
    r = radii[last]
    x, y = hole.x + np.cos(angles) * r, hole.y + np.sin(angles) * r
    return np.append(x, x[0]), np.append(y, y[0])


def _profile_truth(hole: Pothole) -> dict:
    """Depth, area and volume of ``hole``'s profile on the grid of the frames' truth, and
    the centroid of its part deeper than 10 mm (road x, y)."""
    gx, gy = _group_grid([hole], _TRUTH_GRID_M)
    own = hole.depth * pothole_weight(hole, gx, gy)
    opening = own > _OPENING_M
    return {"depth_mm": 1e3 * hole.depth, "area_m2": float(opening.sum() * _TRUTH_GRID_M ** 2),
            "volume_l": float(own.sum() * _TRUTH_GRID_M ** 2 * 1e3),
            "opening_xy": (float(gx[opening].mean()), float(gy[opening].mean())) if opening.any() else (hole.x, hole.y)}


def _frame_scene(rng, rig: StereoRig, road: _Road, along: float, lighting, variant: str, material: str):
    """Frame at ``along`` metres: the drive's potholes moved into its coordinates, those
    that reach its visible patch kept; its own noise, relief and texture from ``rng``.
    Returns the scene and the road indices of the potholes it holds."""
    texel, spacing = _grid_steps(rig)
    moved = tuple(dataclasses.replace(h, y=h.y - along) for h in road.shape.holes)
    # The height range (deepest pothole of the drive) bounds the patch; then the potholes
    # whose drawing window reaches into the patch are the frame's (the height field draws
    # a pothole only in its window, and cannot draw one whose window misses the grid).
    bounds, z_range = _visible_patch(rig, dataclasses.replace(road.shape, holes=moved))
    x_min, x_max, y_min, y_max = bounds
    kept = [i for i, h in enumerate(moved) if h.x + _drawn_reach(h) > x_min and h.x - _drawn_reach(h) < x_max
            and h.y + _drawn_reach(h) > y_min and h.y - _drawn_reach(h) < y_max]
    shape = dataclasses.replace(road.shape, holes=tuple(moved[i] for i in kept))
    field_, h_top = _surface(rng, shape, bounds, spacing, z_range)
    return _dress_scene(rng, variant, material, rig, shape, texel, spacing, bounds, field_, h_top, lighting), kept


def generate_drive(out_dir, *, frames: int, seed: int = 0, width: int = 1280, height: int = 720,
                   spacing: float | None = None, potholes: int | None = None, gps_noise: float = 0.0,
                   variant: str = "sun", material: str = "asphalt", on_frame=None) -> list[Path]:
    """Render a synthetic drive: ``frames`` overlapping pair folders along one road, its
    GPS track and the potholes' map positions.

    ``out_dir`` gets ``drive-0000`` ... (pair folders as :func:`generate_dataset` writes
    them, rendered by one rig; ``defects_gt.json`` ids are per frame and its depth, area
    and volume those of the potholes' profiles, the same in every frame), ``track.csv``
    and ``track.gpx`` (one fix per frame) and ``drive_gt.json`` (rig, track, potholes with
    latitude, longitude, outline and the frames that see them).  Conventions: the module
    docstring and ``definitions`` in ``drive_gt.json``.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Folder of the drive; created when missing.
    frames : int
        Number of frames (1 or more).
    seed : int
        Seed of the whole drive (>= 0); the same arguments give the same files.
    width, height : int
        Image size in pixels.
    spacing : float or None
        Metres travelled between frames (> 0); None: :func:`default_spacing` (every
        pothole centre seen by two frames or more).
    potholes : int or None
        Number of potholes (>= 0); None: one per 3 m of road where they are placed.
    gps_noise : float
        Std (metres) of a Gaussian error added to each fix of ``track.csv`` and
        ``track.gpx`` north and east (``drive_gt.json`` keeps the exact fixes).
    variant, material : str
        Illumination and surface of every frame, as in :func:`render_pair`.
    on_frame : callable, optional
        Called as ``on_frame(index, folder, seconds)`` once each frame is written.

    Returns
    -------
    list of Path
        The frame folders, in order.

    Raises
    ------
    InputError
        A bad count, seed, size, spacing, pothole count or noise; potholes that do not
        fit on the drive; pyproj missing; not enough memory.
    OutputError
        ``out_dir`` holds something else than this drive, or cannot be written.
    """
    frames, seed = _check_arguments(frames, seed, spacing, potholes, gps_noise)
    _check_size(width, height)
    geod = _geod()
    _check_memory(width, height)
    drive_rng = np.random.default_rng(np.random.SeedSequence([seed, _DRIVE_STREAM]))
    rig = sample_rig(drive_rng, width, height)
    foot = footprint(rig)
    spacing = default_spacing(rig) if spacing is None else float(spacing)
    holes = _sample_drive_potholes(drive_rng, potholes, foot, frames, spacing)
    road = _sample_drive_road(drive_rng, holes)
    lighting = _sample_lighting(drive_rng, variant, rig)
    fixes = _track(geod, road, frames, spacing)
    out_dir = _make_folder(Path(out_dir))
    identity = {"generator": "d3stereo synth", "drive": frames, "seed": seed, "width": int(width),
                "height": int(height), "spacing_m": spacing, "potholes": len(holes), "gps_noise_m": float(gps_noise)}
    _claim_folder(out_dir, identity, "the same --drive/--seed/--width/--height/--spacing/--potholes/--gps-noise "
                                     "as before")
    noise_rng = np.random.default_rng(np.random.SeedSequence([seed, _DRIVE_STREAM, 1]))
    reported = _noisy(geod, fixes, float(gps_noise), noise_rng)
    seen: dict[int, list] = {p.id: [] for p in holes}
    folders = []
    for k, fix in enumerate(fixes):
        started = time.perf_counter()
        folders.append(_write_frame(out_dir, k, fix, rig, road, holes, lighting, identity, seen,
                                    variant=variant, material=material))
        _tag_position(folders[-1] / "left.png", reported[k])
        if on_frame is not None:
            on_frame(k, folders[-1], time.perf_counter() - started)
    _write_track_csv(out_dir / TRACK_CSV, reported)
    _write_track_gpx(out_dir / TRACK_GPX, reported, seed)
    _write_truth(out_dir / DRIVE_TRUTH, geod, identity, rig, foot, road, fixes, holes, seen)
    return folders


def _check_arguments(frames, seed, spacing, potholes, gps_noise) -> tuple[int, int]:
    if int(frames) < 1:
        raise InputError(where_what_fix("synth", f"--drive is {frames}", "ask for at least one frame"))
    if int(seed) < 0:  # numpy's SeedSequence takes non-negative integers only
        raise InputError(where_what_fix("synth", f"--seed is {seed}", "give a seed >= 0 (the same seed gives the same drive)"))
    if spacing is not None and not (math.isfinite(float(spacing)) and float(spacing) > 0):
        raise InputError(where_what_fix("synth", f"--spacing is {spacing}", "give the metres between frames, > 0"))
    if potholes is not None and int(potholes) < 0:
        raise InputError(where_what_fix("synth", f"--potholes is {potholes}", "give 0 or more potholes"))
    if not (math.isfinite(float(gps_noise)) and float(gps_noise) >= 0):
        raise InputError(where_what_fix("synth", f"--gps-noise is {gps_noise}", "give a std in metres, >= 0"))
    return int(frames), int(seed)


def _make_folder(out_dir: Path) -> Path:
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(where_what_fix(str(out_dir), f"cannot create the folder ({exc.strerror or exc})",
                                         "choose a writable output folder")) from exc
    return out_dir


def _write_frame(out_dir: Path, k: int, fix: Fix, rig: StereoRig, road: _Road, holes, lighting, identity: dict,
                 seen: dict, *, variant: str, material: str) -> Path:
    """Render and write frame ``k``; note in ``seen`` which drive potholes it shows."""
    frame_seed = int(np.random.SeedSequence([identity["seed"], _DRIVE_STREAM, 0, k]).generate_state(1)[0])
    rng = np.random.default_rng(frame_seed)
    try:
        scene, kept = _frame_scene(rng, rig, road, fix.along_m, lighting, variant, material)
        pair = _render_scene(scene, rng, supersample=2, noise=True, surface_truth=False, seed=frame_seed,
                             variant=variant, material=material, flat=False)
    except MemoryError:
        raise _out_of_memory(rig.width, rig.height) from None
    for entry, index in zip(pair.defects_gt, kept):
        if entry["visible_px"] > 0:
            seen[holes[index].id].append({"frame": fix.frame, "id": entry["id"], "visible_px": entry["visible_px"],
                                          "u": entry["u"], "v": entry["v"]})
    source = [f"frame_seed: {frame_seed}", f"drive_frames: {identity['drive']}",
              f"along_m: {fix.along_m:.6f}", f"spacing_m: {identity['spacing_m']:g}",
              f"reproduce: generate_drive(OUT, frames={identity['drive']}, seed={identity['seed']}, "
              f"width={identity['width']}, height={identity['height']}, spacing={identity['spacing_m']!r}, "
              f"potholes={identity['potholes']}, gps_noise={identity['gps_noise_m']!r}) frame {k}"]
    folder = _write_pair(out_dir / fix.frame, pair, dataset_seed=identity["seed"], index=k, source=source)
    log.info("synth: wrote %s (%d potholes in view)", fix.frame, sum(e["visible_px"] > 0 for e in pair.defects_gt))
    return folder


def _tag_position(path: Path, fix: Fix) -> None:
    """Rewrite the PNG ``path`` with ``fix`` in its EXIF GPS tags (an eXIf chunk), as a
    camera with a GPS receiver tags its pictures; the pixels stay the same."""
    from PIL import ExifTags, Image
    from PIL.TiffImagePlugin import IFDRational

    def dms(value: float) -> tuple:
        degrees, rest = divmod(abs(value) * 3600.0, 3600.0)
        minutes, seconds = divmod(rest, 60.0)
        return IFDRational(int(degrees)), IFDRational(int(minutes)), IFDRational(round(seconds, 6))

    moment = datetime.fromisoformat(fix.time.replace("Z", "+00:00"))
    tag = ExifTags.GPS
    exif = Image.Exif()
    exif[ExifTags.IFD.GPSInfo] = {
        tag.GPSVersionID: b"\x02\x03\x00\x00",
        tag.GPSLatitudeRef: "N" if fix.latitude >= 0 else "S", tag.GPSLatitude: dms(fix.latitude),
        tag.GPSLongitudeRef: "E" if fix.longitude >= 0 else "W", tag.GPSLongitude: dms(fix.longitude),
        tag.GPSAltitudeRef: b"\x00" if fix.altitude_m >= 0 else b"\x01",
        tag.GPSAltitude: IFDRational(round(abs(fix.altitude_m), 3)),
        tag.GPSTimeStamp: (IFDRational(moment.hour), IFDRational(moment.minute),
                           IFDRational(round(moment.second + moment.microsecond / 1e6, 3))),
        tag.GPSDateStamp: moment.strftime("%Y:%m:%d"),
        tag.GPSImgDirectionRef: "T", tag.GPSImgDirection: IFDRational(round(fix.heading_deg, 6)),
        tag.GPSMapDatum: "WGS-84",
    }
    with Image.open(path) as image:
        pixels = image.copy()
    atomic_write(path, lambda tmp: pixels.save(tmp, format="PNG", exif=exif))


def _write_track_csv(path: Path, fixes: list[Fix]) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["frame", "latitude", "longitude", "heading_deg", "altitude_m", "time"])
    for fix in fixes:
        writer.writerow([fix.frame, f"{fix.latitude:.9f}", f"{fix.longitude:.9f}", f"{fix.heading_deg:.6f}",
                         f"{fix.altitude_m:.3f}", fix.time])
    atomic_write(path, lambda tmp: tmp.write_text(buffer.getvalue(), encoding="utf-8"))


_GPX_NS = "http://www.topografix.com/GPX/1/1"


def _write_track_gpx(path: Path, fixes: list[Fix], seed: int) -> None:
    """GPX 1.1: one track, one segment, one ``trkpt`` per fix (``ele``, ``time``, and
    ``name`` = the frame folder, in the order the schema wants)."""
    ET.register_namespace("", _GPX_NS)

    def sub(parent, tag, text=None, **attrs):
        node = ET.SubElement(parent, f"{{{_GPX_NS}}}{tag}", attrs)
        if text is not None:
            node.text = text
        return node

    root = ET.Element(f"{{{_GPX_NS}}}gpx", {"version": "1.1", "creator": "d3stereo synth"})
    track = sub(root, "trk")
    sub(track, "name", f"synthetic drive, seed {seed}")
    segment = sub(track, "trkseg")
    for fix in fixes:
        point = sub(segment, "trkpt", lat=f"{fix.latitude:.9f}", lon=f"{fix.longitude:.9f}")
        sub(point, "ele", f"{fix.altitude_m:.3f}")
        sub(point, "time", fix.time)
        sub(point, "name", fix.frame)
    ET.indent(root)
    data = ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"
    atomic_write(path, lambda tmp: tmp.write_bytes(data))


_DEFINITIONS = {
    "road_coordinates": "metres; x across the road, positive to the right of the direction of travel; y along it "
                        "from the first fix; z up. Frame k's own coordinates are the road's shifted by along_m of "
                        "frame k along y (its rig mid-point at x = 0, y = 0, z = rig.height_m)",
    "antenna": "a fix (latitude, longitude, altitude_m) is the road point directly below the rig's mid-point "
               "(frame coordinates x = 0, y = 0, on the road's mean level z = 0)",
    "heading_deg": "bearing of travel at the fix, clockwise from true north, degrees in [0, 360); the road is "
                   "the WGS84 geodesic through the fixes, consecutive fixes spacing_m apart",
    "local_to_geo": "frame point (x, y) lies at pyproj.Geod(ellps='WGS84').fwd(longitude, latitude, "
                    "heading_deg + degrees(atan2(x, y)), hypot(x, y)) of the frame's fix",
    "altitude_m": "the road's mean level at the fix, metres (start altitude + grade x along_m)",
    "time": "ISO 8601 UTC; the drive at a constant speed",
    "track_files": "track.csv and track.gpx hold these fixes with gps_noise_m of Gaussian error north and "
                   "east each (none when 0); frames here are exact",
    "pothole_position": "latitude, longitude, along_m and lateral_m are the centre of the pothole's ellipse, "
                        "the point whose projection at the pothole's depth is u, v of the frames' "
                        "defects_gt.json; opening_centroid is the centroid of its part deeper than 10 mm",
    "outline_lonlat": "the 10 mm-deep contour of the profile: along 72 rays from the centre the outermost point "
                      "deeper than 10 mm, as a closed ring of [longitude, latitude]",
    "depth_mm": "the profile's depth below the surrounding road (each frame adds up to a few mm of floor relief "
                "of its own, not counted)",
    "area_m2": "horizontal area of the profile deeper than 10 mm, on the 2 mm grid of defects_gt.json",
    "volume_l": "fill volume of the profile up to the surrounding road, same grid",
    "frames": "the frames whose left image shows the pothole (visible_px > 0 in potholes_gt.png); id is its "
              "id in that frame's defects_gt.json, u, v where its centre projects there",
    "exif": "each frame's left.png carries its track.csv fix in EXIF GPS tags (PNG eXIf chunk): latitude, "
            "longitude, altitude, time, GPSImgDirection = heading_deg",
    "angle_deg": "bearing of the ellipse's first semi-axis (semi_axes_m[0]), clockwise from the direction of "
                 "travel, degrees",
}


def _write_truth(path: Path, geod, identity: dict, rig: StereoRig, foot: Footprint, road: _Road,
                 fixes: list[Fix], holes, seen: dict) -> None:
    spacing = identity["spacing_m"]
    entries = []
    for pothole in holes:
        hole = pothole.hole
        truth = _profile_truth(hole)
        lon, lat = _road_to_geo(geod, fixes, spacing, hole.x, hole.y)
        o_lon, o_lat = _road_to_geo(geod, fixes, spacing, *truth["opening_xy"])
        ring_x, ring_y = _outline(hole)
        ring_lon, ring_lat = _road_to_geo(geod, fixes, spacing, ring_x, ring_y)
        entries.append({
            "id": pothole.id, "shape": hole.shape,
            "along_m": hole.y, "lateral_m": hole.x,
            "latitude": float(lat), "longitude": float(lon),
            "opening_centroid": {"latitude": float(o_lat), "longitude": float(o_lon)},
            "depth_mm": truth["depth_mm"], "area_m2": truth["area_m2"], "volume_l": truth["volume_l"],
            "semi_axes_m": [hole.semi_a, hole.semi_b],
            "angle_deg": (90.0 - math.degrees(hole.angle)) % 360.0,
            "outline_lonlat": [[round(float(a), 10), round(float(b), 10)] for a, b in zip(ring_lon, ring_lat)],
            "frames": seen[pothole.id],
        })
    calib = rig.calib()
    doc = {
        "definitions": _DEFINITIONS,
        "drive": identity,
        "rig": calib,
        "footprint": {"near_m": foot.near, "far_m": foot.far, "half_width_m": foot.half_width},
        "road": {"start_latitude": road.latitude, "start_longitude": road.longitude,
                 "start_heading_deg": road.heading_deg, "start_altitude_m": road.altitude_m,
                 "grade": road.shape.grade, "cross_slope": road.shape.cross_slope, "speed_mps": road.speed_mps},
        "frames": [dataclasses.asdict(fix) for fix in fixes],
        "potholes": entries,
    }
    text = json.dumps(doc, indent=2) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))
