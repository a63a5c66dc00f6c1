"""Road inspection outputs of one pair (``--road-report``) and the batch's defects.csv.

Per pair: ``height.pfm`` (signed height above the road plane, metres, + up, inf where no
estimate), ``height_color.png`` (diverging colour map in mm with a colour bar),
``defects.json`` (plane, definitions, potholes and bumps, :mod:`d3cli.road.defects`) and
``defects.png`` (the left image with each defect outlined and labelled, and a legend,
:mod:`d3cli.road.overlay`).
"""

from __future__ import annotations

import csv
import io as _io
import json
import logging
import re
from pathlib import Path

import cv2
import numpy as np

from ..data.formats import atomic_write, write_image, write_pfm
from ..errors import plural
from ..data.legend import vertical_colour_bar
from .confidence import REASONS, describe
from .defects import DefectTuning, candidate_regions, find_defects, remeasure, with_flags
from .grid import Grid
from .morphology import dilate_near, grown_box
from .overlay import defects_overlay
from .plane import fit_road_plane, height_map, seen_by_both
from .compiled import back_project, height_colours
from .pointcloud import Camera
from .rematch import MIN_RELIABLE, REACH, WINDOWS, grey_image, hopeless, match_margin, noise_limit, rematch
from .severity import pothole_severity, survey_summary
from .threads import Job, map_on_threads

log = logging.getLogger(__name__)

HEIGHT_FILE = "height.pfm"
HEIGHT_COLOR_FILE = "height_color.png"
DEFECTS_JSON = "defects.json"
DEFECTS_PNG = "defects.png"
DEFECTS_CSV = "defects.csv"
SURVEY_JSON = "road_survey.json"
CSV_FIELDS = ("pair", "id", "kind", "u", "v", "x_m", "y_m", "z_m", "area_m2", "max_depth_mm",
              "mean_depth_mm", "volume_l", "decided_share", "low_confidence", "confidence", "flags", "diameter_mm",
              "severity", "equivalent_potholes")


def _write_json(path: Path, data: dict) -> None:
    text = json.dumps(data, indent=2) + "\n"
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def _defects_json_text(data: dict) -> str:
    """defects.json's text: indented, but each defect's ``outline_px`` on one line.

    Indented, an outline puts each coordinate on a line of its own (most of the file) and
    runs through the json module's Python encoder; written compactly it is one line a defect
    and takes the C encoder.  The outlines are swapped for placeholder strings, the rest
    indented, then the placeholders replaced by the outlines' compact text."""
    outlines = []

    def placeholder(outline) -> str:
        outlines.append(json.dumps(outline, separators=(",", ":")))
        return f"@outline:{len(outlines) - 1}@"

    swapped = {**data, "defects": [{**d, "outline_px": placeholder(d["outline_px"])} if "outline_px" in d else d
                                   for d in data.get("defects", [])]}
    text = json.dumps(swapped, indent=2)
    return re.sub(r'"@outline:(\d+)@"', lambda m: outlines[int(m.group(1))], text) + "\n"


def height_colour(height: np.ndarray, *, range_mm: float = 50.0) -> np.ndarray:
    """RGB uint8 (H, W + bar, 3): blue below the plane, white on it, red above; grey = no estimate.

    The colour saturates at +-``range_mm``; a labelled colour bar is appended on the right.
    """
    h, w = height.shape

    def ramp(x):  # x in [-1, 1] -> RGB float: blue - white - red
        r = np.where(x < 0, 1 + x, 1.0)
        b = np.where(x > 0, 1 - x, 1.0)
        g = 1 - np.abs(x)
        return np.stack([r, g, b], axis=-1)

    if height.dtype == np.float32:  # the maps of height_map: the same ramp, compiled
        img = np.empty((h, w, 3), np.uint8)
        height_colours(height, float(range_mm), img)
    else:
        finite = np.isfinite(height)
        t = np.clip(np.where(finite, height * 1e3, 0.0) / range_mm, -1.0, 1.0)
        img = (ramp(t) * 255).astype(np.uint8)
        img[~finite] = 96
    ticks = [(0.5 - v / (2 * range_mm), f"{v:+g} mm" if v else "0 mm") for v in (range_mm, range_mm / 2, 0.0,
                                                                              -range_mm / 2, -range_mm)]
    bar = vertical_colour_bar(h, (ramp(np.linspace(1.0, -1.0, 256)) * 255).astype(np.uint8), ticks,
                              "height above road plane [mm]; grey: no estimate")
    return np.concatenate([img, bar], axis=1)


def road_report(pair_dir: Path, left: np.ndarray, disparity: np.ndarray, decided: np.ndarray,
                camera: Camera | None, info: dict, road_cfg, *, right: np.ndarray | None = None,
                groups: frozenset | None = None, averaging_px: float | None = None) -> tuple[list[dict], list[str]]:
    """Write the road outputs of one pair into ``pair_dir``.

    Parameters
    ----------
    pair_dir : Path
    left : ndarray, (H, W[, 3])
        Left image, for defects.png.
    disparity : ndarray, float32, (H, W)
        disp.pfm (filled pixels included; inf = no estimate).
    decided : ndarray, bool, (H, W)
        valid.png.
    camera : Camera or None
        None: a warning and no road outputs.
    info : dict
        The pair's result info; ``info['pt']['fallback']`` True (no road surface): height
        outputs but no defects, defects.json saying so (``road_like`` false, a
        "no road surface" line with ``info['pt']['reason']``) and no warning returned (the
        fallback's own warning is the pair's).
    road_cfg : RoadConfig
    right : ndarray, optional, keyword-only
        The right image.  Given, the disparity inside each defect (grown by its ring) is
        matched again with a small window (:mod:`d3cli.road.rematch`), the defects are
        measured on that, and how decisively the images support each defect's disparity is
        part of its confidence (``match_margin``, :mod:`d3cli.road.confidence`); disp.pfm
        is not changed.
    groups : frozenset, optional, keyword-only
        The optional files of ``run.outputs`` (:data:`d3cli.config.OUTPUT_GROUPS`):
        height.pfm with ``height``, height_color.png and defects.png with ``pictures``;
        None: all.  defects.json is always written; a road file not asked for is removed
        (it would describe an earlier report).
    averaging_px : float, optional, keyword-only
        How far around a pixel the method that made ``disparity`` averages, pixels
        (:attr:`d3cli.config.MethodSpec.averaging_px`): with the right image, a defect that
        keeps the stored map's depth and is narrower than that is flagged ``narrow``
        (:mod:`d3cli.road.confidence`; evidence ``averaging_px`` and ``inscribed_px``).
        None: not known, no such flag.

    Returns
    -------
    defects : list of dict
        The defects as written to defects.json.
    warnings : list of str
        What the run should warn about (also in defects.json's ``warnings``).
    """
    warnings: list[str] = []
    if camera is None:
        return [], ["no road report: focal length or baseline unknown; add calib.txt to the pair "
                    "or set camera.f and camera.baseline"]
    # Only pixels the right camera sees too are measurements (the left-border strip is
    # extrapolated by the hole filling): they are "no estimate" in every road output.
    finite = seen_by_both(disparity)
    # The plane and the defects on the measuring grid (d3cli.road.grid): its cells'
    # disparities and their 3-D points (disparity_to_points' points of the cells' centres).
    grid = Grid.for_shape(disparity.shape)
    cells, cells_decided = grid.disparities(disparity, finite, decided)
    g_camera = grid.camera(camera)
    points = back_project(cells, np.isfinite(cells), float(g_camera.f), float(g_camera.baseline), float(g_camera.cx),
                          float(g_camera.cy), float(g_camera.doffs))
    plane = fit_road_plane(points, camera, sigma_disparity=road_cfg.sigma_disparity,
                           decimate=grid.decimate(16), fine_decimate=grid.decimate(4))
    if plane is None:
        return [], ["no road report: too few points for a road plane"]
    groups = frozenset(("height", "pictures")) if groups is None else groups

    def write_height(disparity_map):  # the height files, in the image's pixels
        values = height_map(disparity_map, finite, camera, plane)
        if "height" in groups:
            write_pfm(pair_dir / HEIGHT_FILE, values)
        if "pictures" in groups:
            write_image(pair_dir / HEIGHT_COLOR_FILE, height_colour(values, range_mm=road_cfg.colour_range_mm))

    # The height files are written on a second thread while the rest of the report runs
    # (with one thread: at the end), once, with the final heights: at once where no
    # re-match can change them, else after the re-match (or after finding no defect).
    pt = (info or {}).get("pt")
    fallback = bool(pt and pt.get("fallback"))
    writing = []  # the Job writing the height files, once started

    def start_writing(values):
        if groups & {"height", "pictures"}:
            writing.append(Job(write_height, values))

    if right is None or fallback:
        start_writing(disparity)
    try:
        return _report(pair_dir, left, disparity, decided, camera, road_cfg, right, groups, finite, plane,
                       (grid, cells, cells_decided), pt, fallback, None if writing else start_writing, warnings,
                       averaging_px)
    finally:
        for job in writing:
            job.result()


def _report(pair_dir, left, disparity, decided, camera, road_cfg, right, groups, finite, plane, grid_maps, pt,
            fallback, start_writing, warnings, averaging_px):
    """The rest of :func:`road_report` once the plane is known; ``start_writing(disparity)``,
    unless None (started already), starts writing the height files once the final
    disparities are known.  The defects are found and measured on the measuring grid
    (``grid_maps``: the :class:`~d3cli.road.grid.Grid`, its cells' disparities and decided
    cells), re-matched and drawn in the image's pixels."""
    decided_share = float(decided.mean()) if decided.size else 0.0
    grid, cell_disparities, cells_decided = grid_maps
    g_camera = grid.camera(camera)
    cells = height_map(cell_disparities, np.isfinite(cell_disparities), g_camera, plane)  # the cells' heights
    on_grid = dict(camera=g_camera, plane=plane, road=grid.road(road_cfg), tuning=grid.tuning(DefectTuning()))
    rules = grid.rules()  # the confidence's rules, their widths in cells

    def in_pixels(defects, masks):  # the defects of the grid and their masks, in the image's pixels
        both = [grid.defect(d, m) for d, m in zip(defects, masks)]
        return [d for d, _ in both], [m for _, m in both]
    notes: list[str] = []
    if fallback:
        # No road plane to measure against: no defects.  Said in defects.json (report.html
        # shows it) but not returned: the pair's warning of the fallback already says why.
        reason = pt.get("reason") or "the perspective transformation fell back"
        notes.append(f"no road surface: {reason}; no defects measured")
        defects, regions = [], []
    elif right is None:
        defects, regions = in_pixels(*find_defects(cells, cells_decided, **on_grid, return_regions=True, rules=rules))
        if start_writing is not None:
            start_writing(disparity)
    else:
        # With the right image the defects found on the stored map are matched again with a
        # small window, then found and measured on that map (remeasure).
        stored = candidate_regions(cells, cells_decided, **on_grid, rules=rules)
        defects, regions = [], stored.regions
        if regions:
            grey = (grey_image(left), grey_image(right))  # made once for every region
            depths = [d.max_depth_mm * 1e-3 for d in stored.defects]  # as the stored map reads them
            measured, windows, zones = _rematched(grey, disparity, finite, in_pixels(stored.defects, regions)[1],
                                                  camera, plane, road_cfg, depths)
        if start_writing is not None:
            start_writing(measured if regions else disparity)
        if regions:
            # the zones' cells again, and their heights (the other cells' are the stored map's)
            zone_cells = grid.any_of(zones)
            remeasured, box = cells.copy(), grown_box(zone_cells, 0, 0)
            if box is not None:
                patched = grid.patched(cell_disparities, measured, finite, zones)[box]
                remeasured[box] = height_map(patched, np.isfinite(patched), g_camera, plane,
                                             origin=(box[0].start, box[1].start))
            defects, regions = in_pixels(*remeasure(stored, remeasured, zone_cells, return_regions=True))
            # How decisively the images support each defect's disparity (the confidence's
            # weak_match), on the disparity it was measured on; the defects on both threads.
            margins = map_on_threads(lambda region: match_margin(*grey, measured, region), regions)
            averaging = {} if averaging_px is None else {"averaging_px": float(averaging_px)}
            defects = [with_flags(d, road_cfg, rematch_window=_window_of(d, r, windows),
                                  match_margin=round(m, 4) if np.isfinite(m) else None,
                                  inscribed_px=_inscribed_radius(d, r), **averaging)
                       for d, r, m in zip(defects, regions, margins)]
    if not fallback and decided_share < road_cfg.min_decided_share:
        warnings.append(f"few decided pixels ({100 * decided_share:.0f} %): every defect is low confidence")
        defects = [with_flags(d, road_cfg, map_decided_share=round(decided_share, 3)) for d in defects]
    # Potholes graded as road agencies do (ASTM D6433, d3cli.road.severity).
    items = [{**d.to_dict(), "reasons": describe(d.flags) if d.flags else "",
              **(pothole_severity(d.max_depth_mm, d.area_m2) if d.kind == "pothole" else {})} for d in defects]
    text = _defects_json_text({
        "plane": plane.to_info(), "decided_share": decided_share, "road_like": not fallback,
        "definitions": "depth: below the median height of the surrounding road ring, mm; area_m2: "
                       "area of the road plane covered by the region; volume_l: fill volume up to the "
                       "surrounding surface; severity: ASTM D6433 pothole level from max depth and the "
                       "equivalent-circle diameter_mm of the area; confidence: ok, or low with the reason "
                       "codes in flags (in words in reasons) and the numbers they were decided from in "
                       "evidence", "defects": items, "warnings": warnings + notes})
    atomic_write(pair_dir / DEFECTS_JSON, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))
    if "pictures" in groups:
        write_image(pair_dir / DEFECTS_PNG, defects_overlay(left, defects, regions))
    for name, group in ((HEIGHT_FILE, "height"), (HEIGHT_COLOR_FILE, "pictures"), (DEFECTS_PNG, "pictures")):
        if group not in groups:
            (pair_dir / name).unlink(missing_ok=True)
    if fallback:
        log.info("%s: no road surface, no defects measured", pair_dir.name)
    else:
        log.info("%s: road plane %.3f m below the camera, %d defects", pair_dir.name, plane.offset, len(items))
    return items, warnings


def _window_of(defect, region: np.ndarray, windows: np.ndarray) -> int:
    """The re-match window most of ``defect``'s pixels were measured with (0: the stored map),
    read in its bounding box."""
    u0, v0, u1, v1 = defect.bbox_px
    box = (slice(v0, v1 + 1), slice(u0, u1 + 1))
    return int(np.bincount(windows[box][region[box]]).argmax())


def _inscribed_radius(defect, region: np.ndarray) -> float:
    """Radius (pixels, one decimal) of the largest disc inside ``region`` (the confidence's
    ``narrow``): its largest Euclidean distance to a pixel outside, read in its bounding box."""
    u0, v0, u1, v1 = defect.bbox_px
    inside = np.pad(region[v0:v1 + 1, u0:u1 + 1], 1).astype(np.uint8)
    return round(float(cv2.distanceTransform(inside, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).max()), 1)


def _rematched(grey, disparity, finite, regions, camera: Camera, plane, road_cfg,
               depths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(disparity, window, zones) with the disparity inside each defect (grown by two rings:
    the ring gives the reference height) matched again (:mod:`d3cli.road.rematch`) on the
    grey images ``grey`` (left, right), with the smallest window of
    :data:`~d3cli.road.rematch.WINDOWS` that re-measures at least ``MIN_RELIABLE`` of the
    zone and whose re-measured heights scatter on the outer ring (:func:`_highpass_noise`)
    by at most :func:`~d3cli.road.rematch.noise_limit` of the defect's stored depth
    (``depths``, metres, the regions' order); a defect no window measures that cleanly
    keeps the stored map (the larger windows are not tried once none of them can match
    ``MIN_RELIABLE`` of the zone, :func:`~d3cli.road.rematch.hopeless`).  ``regions``: bool
    (H, W) masks in the image's pixels; ``window``: uint8 (H, W), the window side used at
    each pixel, 0 where the stored map was kept; ``zones``: bool (H, W), every pixel of a
    zone matched again."""
    ring = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * road_cfg.ring_px + 1, 2 * road_cfg.ring_px + 1))
    left, right = grey
    # Everything a zone's re-match reads lies within this many pixels of its defect: the
    # two rings, then the larger of the smoothing's support around the outer ring (four
    # windows, :func:`_highpass_noise`) and the match's own box (a window and the reach).
    margin = 2 * road_cfg.ring_px + max(4 * max(WINDOWS) + 2, max(WINDOWS) + int(np.ceil(REACH)) + 1)

    def zone_disparity(item):
        """(the zone's window of the map, the zone in it, its re-matched disparity and
        window, or None and 0 where no window matches it cleanly).  Worked on that window
        of the map: the same pixels as on the whole map, at the cost of the window."""
        region, depth = item
        limit = noise_limit(depth)
        crop = grown_box(region, margin, margin)
        origin = (crop[0].start, crop[1].start)
        near, known = disparity[crop], finite[crop]
        inner = dilate_near(region[crop], ring)
        zone = dilate_near(inner, ring) & known
        band = zone & ~inner  # flat road: its high-pass residual is matching noise only
        # The warps of the first window's box, made once for the zone: most zones stop there
        # (a larger window warps its own, larger box).
        shared = {"grey": grey}
        for i, window in enumerate(WINDOWS):
            new, got = rematch(left, right, near, zone, window=window, shared=shared, origin=origin)
            share = float(got[zone].mean())
            if share < MIN_RELIABLE:
                if hopeless(share, len(WINDOWS) - 1 - i):
                    break  # no larger window matches half of the zone: the stored map
                continue
            # Heights only in a window around the band that holds the smoothing's support.
            reach = int(np.ceil(4 * window)) + 2
            box = grown_box(band, reach, reach) or (slice(0, 0), slice(0, 0))
            if _highpass_noise(height_map(new[box], known[box], camera, plane,
                                          origin=(origin[0] + box[0].start, origin[1] + box[1].start)),
                               (band & got)[box], window) <= limit:
                return crop, zone, new[zone], window
        # no window matches the defect cleanly (a dark, noisy pair): the stored, smoothed
        # map is the better measurement there.
        return crop, zone, None, 0

    out = disparity.copy()
    windows = np.zeros(disparity.shape, np.uint8)
    zones = np.zeros(disparity.shape, bool)
    # The regions are matched on both threads (each reads the stored map only) and their
    # zones written in the regions' order, as one after the other would.
    for crop, zone, values, window in map_on_threads(zone_disparity, list(zip(regions, depths))):
        windows[crop][zone] = window
        zones[crop] |= zone
        if values is not None:
            out[crop][zone] = values
    return out, windows, zones


def _highpass_noise(height: np.ndarray, zone: np.ndarray, window: int) -> float:
    """Robust spread (1.4826 MAD, metres) over ``zone`` (flat road) of the heights minus
    their Gaussian smoothing over a window (sigma ``window`` pixels, normalised by the
    smoothed ``zone``): the matching noise; inf when nothing is measured.  The arrays may
    be a window of the map that holds ``zone`` grown by the smoothing's reach (``4 window``
    pixels) or the image's edge: outside ``zone`` the values weigh nothing.

    The smoothing is made on the arrays shrunk by ``window // 4`` (pixel areas averaged),
    then enlarged back (bilinear): a smoothing that wide has nothing finer to lose, and a
    full-size Gaussian of sigma 9 to 25 px cost more than the re-match's own matching."""
    keep = zone & np.isfinite(height)  # a re-match at d <= 0 has no height
    if keep.sum() < 10:
        return np.inf
    values = np.where(keep, height, 0.0).astype(np.float32)
    h, w = values.shape
    factor = max(1, window // 4)
    if factor > 1 and min(h, w) >= 4 * factor:
        size = (max(1, round(w / factor)), max(1, round(h / factor)))

        def smoothed(a):
            small = cv2.GaussianBlur(cv2.resize(a, size, interpolation=cv2.INTER_AREA), (0, 0), window / factor)
            return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    else:
        def smoothed(a):
            return cv2.GaussianBlur(a, (0, 0), window)
    smooth = smoothed(values) / np.maximum(smoothed(keep.astype(np.float32)), 1e-6)
    resid = (values - smooth)[keep]
    return 1.4826 * float(np.median(np.abs(resid - np.median(resid))))


def write_defects_csv(out: Path, pair_dirs, *, frame_spacing_m: float = 0.0) -> Path | None:
    """``OUT/defects.csv``: every defect of every pair folder with a defects.json, and
    ``OUT/road_survey.json`` (:func:`d3cli.road.severity.survey_summary` of those pairs);
    None if none has one."""
    rows = []
    per_pair = {}
    seen = False
    for pair_dir in pair_dirs:
        path = Path(pair_dir) / DEFECTS_JSON
        if not path.is_file():
            continue
        seen = True
        per_pair[Path(pair_dir).name] = json.loads(path.read_text(encoding="utf-8")).get("defects", [])
        for d in per_pair[Path(pair_dir).name]:
            rows.append({"pair": Path(pair_dir).name, "id": d["id"], "kind": d["kind"],
                         "u": round(d["centroid_px"][0], 1), "v": round(d["centroid_px"][1], 1),
                         "x_m": round(d["centroid_m"][0], 4), "y_m": round(d["centroid_m"][1], 4),
                         "z_m": round(d["centroid_m"][2], 4), "area_m2": round(d["area_m2"], 5),
                         "max_depth_mm": round(d["max_depth_mm"], 1), "mean_depth_mm": round(d["mean_depth_mm"], 1),
                         "volume_l": round(d["volume_l"], 3), "decided_share": round(d["decided_share"], 3),
                         "low_confidence": d["low_confidence"],
                         "confidence": d.get("confidence", "low" if d["low_confidence"] else "ok"),
                         "flags": ";".join(d.get("flags", [])), "diameter_mm": d.get("diameter_mm", ""),
                         "severity": d.get("severity") or "", "equivalent_potholes": d.get("equivalent_potholes", "")})
    if not seen:
        return None
    buf = _io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=CSV_FIELDS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    text = buf.getvalue()
    _write_json(Path(out) / SURVEY_JSON, survey_summary(per_pair, frame_spacing_m=frame_spacing_m))
    return atomic_write(Path(out) / DEFECTS_CSV, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def survey_line(out: Path) -> str | None:
    """One line for the terminal after a ``--road-report`` batch: what the road report found.

    ``road: 12 frames, 7 potholes (low 2, medium 4, high 1), 1 bump; deepest 62 mm
    (synth-0011-wet-cement #2); 3 defects flagged (weak match on little texture 2, at the image
    border 1)``,
    from ``OUT/defects.csv`` and ``OUT/road_survey.json``; where the frames have positions it
    ends with the map's counts (``; 5 defects on the map (7 sightings merged), 1 frame
    unplaced``, :mod:`d3cli.survey`).  Potholes are counted per ASTM
    D6433 severity (:mod:`d3cli.road.severity`); those too shallow or narrow for a severity
    are counted as "too small to grade".  The deepest is the deepest pothole, with its
    reasons when it is flagged (:mod:`d3cli.road.confidence`); a defect can have several.

    Parameters
    ----------
    out : Path
        The batch's output folder.

    Returns
    -------
    str or None
        None when the batch wrote no defects.csv (no pair has road outputs) or it cannot
        be read.
    """
    path = Path(out) / DEFECTS_CSV
    try:
        with path.open(encoding="utf-8", newline="") as f:
            rows = [{**r, "max_depth_mm": float(r["max_depth_mm"])} for r in csv.DictReader(f)]
    except (OSError, ValueError, KeyError, TypeError, csv.Error):
        return None  # no road outputs, or a file that is not d3stereo's: no line, never a failed run
    try:
        survey = json.loads((Path(out) / SURVEY_JSON).read_text(encoding="utf-8"))
        frames = int(survey["frames"])
    except (OSError, ValueError, KeyError, TypeError):
        survey, frames = {}, len({r.get("pair") for r in rows})
    on_map = _on_map(survey)
    pits = [r for r in rows if r.get("kind") == "pothole"]
    n_bumps = sum(r.get("kind") == "bump" for r in rows)
    flagged = sum(r.get("low_confidence") == "True" for r in rows)
    no_road = _frames_without_road(Path(out))
    line = f"road: {plural(frames, 'frame')}" + (f" ({no_road} without a road surface), " if no_road else ", ")
    if pits:
        counts = [f"{level} {sum(r.get('severity') == level for r in pits)}" for level in ("low", "medium", "high")]
        ungraded = sum(not r.get("severity") for r in pits)
        if ungraded:
            counts.append(f"{ungraded} too small to grade")
        line += f"{plural(len(pits), 'pothole')} ({', '.join(counts)}), {plural(n_bumps, 'bump')}"
        deepest = max(pits, key=lambda r: r["max_depth_mm"])
        low = f", flagged: {_reasons_of(deepest)}" if deepest.get("low_confidence") == "True" else ""
        line += f"; deepest {deepest['max_depth_mm']:.0f} mm ({deepest.get('pair')} #{deepest.get('id')}{low})"
    else:
        line += f"no potholes, {plural(n_bumps, 'bump')}"
    if not flagged:
        return line + "; none flagged" + on_map
    reasons: dict = {}
    for r in rows:
        for code in (r.get("flags") or "").split(";") if r.get("low_confidence") == "True" else ():
            if code:
                reasons[code] = reasons.get(code, 0) + 1
    why = ", ".join(f"{REASONS.get(code, code)} {n}" for code, n in sorted(reasons.items(), key=lambda kv: -kv[1]))
    return line + f"; {plural(flagged, 'defect')} flagged" + (f" ({why})" if why else "") + on_map


def _on_map(survey) -> str:
    """``; 5 defects on the map (7 sightings merged), 1 frame unplaced`` from road_survey.json's
    ``map`` (:mod:`d3cli.survey.outputs`); "" without one."""
    try:
        m = survey["map"]
        text = (f"; {plural(int(m['defects']), 'defect')} on the map ({plural(int(m['merged']), 'sighting')} merged)"
                f", {plural(int(m['frames_unplaced']), 'frame')} unplaced")
    except (KeyError, TypeError, ValueError):
        return ""
    return text


def _reasons_of(row: dict) -> str:
    """The reasons of a defects.csv row in words (``low confidence`` for rows without flags)."""
    codes = [c for c in (row.get("flags") or "").split(";") if c]
    return describe(codes) if codes else "low confidence"


def _frames_without_road(out: Path) -> int:
    """Pairs of ``out`` whose defects.json says the frame is not a road surface (PT fell back)."""
    count = 0
    for path in out.glob(f"*/{DEFECTS_JSON}"):
        try:
            count += json.loads(path.read_text(encoding="utf-8")).get("road_like") is False
        except (OSError, ValueError, AttributeError):
            continue  # a damaged file: it is the pair's own business, the line stays a summary
    return count
