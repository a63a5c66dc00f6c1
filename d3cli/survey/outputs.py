"""The files of the map, written after a ``--road-report`` batch whose frames have positions.

* ``OUT/defects.geojson``: a GeoJSON FeatureCollection (RFC 7946: WGS84 longitude,
  latitude; polygons closed, exterior ring counter-clockwise), one Feature per defect
  after merging (:mod:`d3cli.survey.merge`): its outline as a Polygon and ``id``, ``kind``,
  ``depth_mm`` (bump: height), ``mean_depth_mm``, ``area_m2``, ``volume_l``,
  ``diameter_mm``, ``severity``, ``confidence``, ``reasons``, ``flags`` of its best
  sighting, ``sightings`` (how many), ``frames``, ``best_frame``, ``best_id``,
  ``longitude``/``latitude`` of its centroid (the area centroid of its outline on the
  road), ``spread_m`` and ``seen`` (per sighting:
  frame, id, depth_mm, area_m2, confidence, range_m, score, longitude, latitude).
* ``OUT/track.geojson``: the drive as a LineString through the frames' fixes (properties:
  ``source``, ``frames``, ``length_m``, ``unplaced_frames``) and one Point per placed
  frame (``frame``, ``heading_deg``, ``heading_from``).
* ``OUT/road_survey.json``: ``length_km`` from the track's geodesic length and
  ``potholes_per_km`` of the merged potholes (``length_from``: ``track``, replacing
  ``road.frame_spacing_m``), and ``map``: the counts of the map.

Every file is written atomically; a run without positions removes the map files an
earlier run wrote (they would describe other maps).
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

from ..data.formats import atomic_write, read_calib
from ..errors import InputError, plural
from ..road.pointcloud import camera_from
from ..road.outputs import DEFECTS_CSV, DEFECTS_JSON, SURVEY_JSON
from .geolocate import locate_defect, road_axes
from .gis import INSTALL, have_gis, local_projection
from .merge import merge_sightings
from .positions import Positions, find_track, frame_positions, read_track, track_length_m

log = logging.getLogger(__name__)

DEFECTS_GEOJSON = "defects.geojson"
TRACK_GEOJSON = "track.geojson"
MAP_FILES = (DEFECTS_GEOJSON, TRACK_GEOJSON)
#: Top-level member that marks a GeoJSON file as d3stereo's (RFC 7946 foreign member).
GENERATOR = "d3stereo"
#: Decimal places of the coordinates written (1e-8 degrees: about 1 mm).
DIGITS = 8


def _folders(pairs) -> list[Path]:
    """The folders that may hold a track beside the pair folders, nearest first."""
    seen: list[Path] = []
    for pair in pairs:
        if getattr(pair, "left", None) is None:
            continue
        left = Path(pair.left)
        for folder in (left.parent.parent, left.parent):
            if folder not in seen:
                seen.append(folder)
    return seen


def _frames(pairs) -> dict[str, Path]:
    return {pair.name: Path(pair.left) for pair in pairs if getattr(pair, "left", None) is not None}


def check_positions(pairs, cfg) -> None:
    """Before a batch: read the track the run would use, so a malformed one is an Error
    before any pair is computed.

    ``road.track`` (``--track``) given: read it; pyproj or shapely missing is an Error
    (:data:`~d3cli.survey.gis.INSTALL`); without ``--road-report`` a warning (no map without
    defects).  A track beside the frames: read it with the road report only; pyproj or
    shapely missing is a warning, and the run goes on without a map.

    Raises
    ------
    InputError
    """
    track = cfg.road.track or None
    if track is None:
        if not cfg.road.report:
            return
        found = find_track(_folders(pairs))
        if found is None:
            return
        if not have_gis():
            log.warning("%s: no map of the defects: pyproj and shapely are not installed; install them with %s",
                        found, INSTALL)
            return
        read_track(found, list(_frames(pairs)))
        return
    frame_positions(_frames(pairs), track=track, folders=())
    if not cfg.road.report:
        log.warning("--track %s: no map without the road report's defects; add --road-report", track)


def _remove_ours(out: Path) -> None:
    for name in MAP_FILES:
        path = out / name
        try:
            ours = json.loads(path.read_text(encoding="utf-8")).get("generator") == GENERATOR
        except (OSError, ValueError, AttributeError):
            continue
        if ours:
            path.unlink(missing_ok=True)
            log.info("%s: removed (no positions for this run's frames)", path)


def _write_json(path: Path, data: dict, indent: int | None = 2) -> Path:
    text = json.dumps(data, indent=indent, ensure_ascii=False) + "\n"
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def _camera(pair, out: Path, cfg):
    """The pair's camera (calib.txt, else the camera section) at its image size."""
    shape = None
    try:
        shape = tuple(json.loads((out / pair.name / "result.json").read_text(encoding="utf-8"))["shape"])[:2]
    except (OSError, ValueError, KeyError, TypeError):
        try:
            from PIL import Image

            with Image.open(pair.left) as im:
                shape = (im.height, im.width)
        except Exception:  # noqa: BLE001 - no size: no camera, the frame's defects are not placed
            return None
    try:
        calib = read_calib(pair.calib) if getattr(pair, "calib", None) is not None else None
    except InputError:
        calib = None
    return camera_from(calib, cfg, shape)


def _sightings(out: Path, pairs, positions: Positions, cfg) -> tuple[list[dict], list[str], int]:
    """(sightings on the earth, frames with a road report but no position, defects not placed)."""
    order = {f: i for i, f in enumerate(positions.placed)}
    offsets = {"antenna_forward_m": cfg.road.antenna_forward_m, "antenna_right_m": cfg.road.antenna_right_m,
               "camera_yaw_deg": cfg.road.camera_yaw_deg}
    sightings, unplaced, lost = [], [], 0
    for pair in pairs:
        path = out / pair.name / DEFECTS_JSON
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue  # no road report for this pair (failed, or no camera)
        if pair.name not in order:
            unplaced.append(pair.name)
            continue
        defects = data.get("defects") or []
        if not defects:
            continue
        camera = _camera(pair, out, cfg)
        plane = data.get("plane") or {}
        axes = road_axes(plane.get("normal", (0, 0, 0)), float(plane.get("offset_m", 0.0)), camera.baseline) \
            if camera is not None else None
        if axes is None:
            lost += len(defects)
            continue
        fix = positions.fixes[pair.name]
        for d in defects:
            loc = locate_defect(d, camera, axes, fix.longitude, fix.latitude, positions.headings[pair.name], **offsets)
            if loc is None:
                lost += 1
                continue
            sightings.append({**d, **loc, "frame": pair.name, "order": order[pair.name]})
    return sightings, unplaced, lost


def _shape(rings_xy, xy, area_m2):
    """The sighting's outline as one valid polygon in the local plane (the largest part),
    or, without a usable outline, the circle of its area around its centroid."""
    from shapely import make_valid
    from shapely.geometry import Point, Polygon

    def polygons(g):
        if isinstance(g, Polygon):
            return [g] if g.area > 0 else []
        return [p for part in getattr(g, "geoms", []) for p in polygons(part)]

    parts = []
    for ring in rings_xy:
        if len(ring) >= 3:
            parts += polygons(make_valid(Polygon(ring)))
    if parts:
        return max(parts, key=lambda p: p.area)
    radius = math.sqrt(max(float(area_m2 or 0.0), 1e-4) / math.pi)
    return Point(xy).buffer(radius, 8)


def _ring_lonlat(poly, to_ll) -> list:
    from shapely.geometry.polygon import orient

    poly = orient(poly, sign=1.0)  # counter-clockwise exterior (east, north: as lon, lat)
    xs, ys = zip(*poly.exterior.coords)
    lons, lats = to_ll(list(xs), list(ys))
    ring = [[round(float(a), DIGITS), round(float(b), DIGITS)] for a, b in zip(lons, lats)]
    ring[-1] = ring[0]  # closed exactly
    return ring


def _feature(n: int, group: list[dict], to_ll, frame_order: dict) -> dict:
    best = group[0]
    frames = sorted({s["frame"] for s in group}, key=lambda f: frame_order[f])
    spread = max(math.dist(best["xy"], s["xy"]) for s in group)
    props = {
        "id": n, "kind": best.get("kind"), "depth_mm": best.get("max_depth_mm"),
        "mean_depth_mm": best.get("mean_depth_mm"), "area_m2": best.get("area_m2"), "volume_l": best.get("volume_l"),
        "diameter_mm": best.get("diameter_mm"), "severity": best.get("severity"),
        "confidence": best.get("confidence", "low" if best.get("low_confidence") else "ok"),
        "reasons": best.get("reasons") or "", "flags": list(best.get("flags") or []),
        "sightings": len(group), "frames": frames, "best_frame": best["frame"], "best_id": best.get("id"),
        "longitude": round(best["centroid"][0], DIGITS), "latitude": round(best["centroid"][1], DIGITS),
        "spread_m": round(spread, 3),
        "seen": [{"frame": s["frame"], "id": s.get("id"), "depth_mm": s.get("max_depth_mm"),
                  "area_m2": s.get("area_m2"), "confidence": s.get("confidence", "ok"),
                  "range_m": round(s["range_m"], 3), "score": round(s["score"], 2),
                  "longitude": round(s["centroid"][0], DIGITS), "latitude": round(s["centroid"][1], DIGITS)}
                 for s in sorted(group, key=lambda s: (frame_order[s["frame"]], s.get("id", 0)))],
    }
    return {"type": "Feature", "id": n, "geometry": {"type": "Polygon", "coordinates": [_ring_lonlat(best["shape"], to_ll)]},
            "properties": props}


def survey_map(out: str | Path, pairs, cfg) -> dict | None:
    """Write the map's files (module docstring) after a batch; the ``map`` counts, or None.

    Called after ``OUT/defects.csv`` and ``OUT/road_survey.json`` are written (from the
    pairs' defects.json).  No map (and an earlier one removed) without them or without
    positions.  A track that
    cannot be read, or pyproj/shapely missing, is a warning here (the CLI has refused a bad
    ``--track`` before the batch): the defects stay in defects.csv.

    Parameters
    ----------
    out : path
        The batch's output folder.
    pairs : list of Pair
        The run's pairs, in the order driven when no track says otherwise.
    cfg : Config
    """
    out = Path(out)
    if not (out / DEFECTS_CSV).is_file() or not (out / SURVEY_JSON).is_file():
        _remove_ours(out)
        return None
    frames = _frames(pairs)
    try:
        positions = frame_positions(frames, track=cfg.road.track or None, folders=_folders(pairs))
    except InputError as exc:
        log.warning("no map of the defects: %s", exc)
        _remove_ours(out)
        return None
    if positions is None:
        _remove_ours(out)
        return None
    sightings, unplaced, lost = _sightings(out, pairs, positions, cfg)
    placed = positions.placed
    lat0 = sum(positions.fixes[f].latitude for f in placed) / max(len(placed), 1)
    lon0 = sum(positions.fixes[f].longitude for f in placed) / max(len(placed), 1)
    to_xy, to_ll = local_projection(lat0, lon0)
    for s in sightings:
        s["xy"] = tuple(float(v) for v in to_xy(s["centroid"][0], s["centroid"][1]))
        rings = [list(zip(*to_xy([p[0] for p in r], [p[1] for p in r]))) for r in s["outline"]]
        s["shape"] = _shape(rings, s["xy"], s.get("area_m2"))
        # The outline's area centroid on the road: the centroid pixel's ray is off by the
        # perspective (the near half of a defect covers more pixels than the far half).
        c = s["shape"].centroid
        lon, lat = to_ll(c.x, c.y)
        s["xy"], s["centroid"] = (float(c.x), float(c.y)), (float(lon), float(lat))
    groups = merge_sightings(sightings, distance_m=cfg.road.merge_distance_m)
    frame_order = {f: i for i, f in enumerate(placed)}
    features = [_feature(n, g, to_ll, frame_order) for n, g in enumerate(groups, 1)]
    _write_json(out / DEFECTS_GEOJSON, {"type": "FeatureCollection", "generator": GENERATOR, "features": features},
                indent=None)
    length_m = track_length_m(positions)
    unplaced_all = unplaced  # frames with a road report and no position, in the run's order
    line = [[round(positions.fixes[f].longitude, DIGITS), round(positions.fixes[f].latitude, DIGITS)] for f in placed]
    track_features = [{"type": "Feature", "geometry": {"type": "LineString", "coordinates": line} if len(line) >= 2
                       else None,
                       "properties": {"source": positions.source, "frames": placed, "length_m": round(length_m, 3),
                                      "unplaced_frames": unplaced_all}}]
    track_features += [{"type": "Feature", "geometry": {"type": "Point", "coordinates": xy},
                        "properties": {"frame": f, "heading_deg": round(positions.headings[f], 3),
                                       "heading_from": positions.heading_from[f]}} for f, xy in zip(placed, line)]
    _write_json(out / TRACK_GEOJSON, {"type": "FeatureCollection", "generator": GENERATOR, "features": track_features},
                indent=None)
    n_pits = sum(f["properties"]["kind"] == "pothole" for f in features)
    summary = {"defects": len(features), "potholes": n_pits, "bumps": len(features) - n_pits,
               "sightings": len(sightings), "merged": len(sightings) - len(features),
               "frames_placed": len(placed), "frames_unplaced": len(unplaced_all), "unplaced": unplaced_all,
               "defects_not_placed": lost, "track": positions.source}
    survey = json.loads((out / SURVEY_JSON).read_text(encoding="utf-8"))
    survey.pop("frame_spacing_m", None)
    survey.update(length_from="track", length_km=round(length_m / 1e3, 4), map=summary)
    if length_m > 0:
        survey["potholes_per_km"] = round(n_pits / (length_m / 1e3), 2)
    else:
        survey.pop("potholes_per_km", None)
    _write_json(out / SURVEY_JSON, survey)
    log.info("map: %s on the map (%s merged), %s unplaced", plural(len(features), "defect"),
             plural(summary["merged"], "sighting"), plural(len(unplaced_all), "frame"))
    return summary
