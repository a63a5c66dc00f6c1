"""Potholes (below the road) and bumps (above it) from a height map, measured in 3-D.

Definitions (what the numbers in defects.json mean):

* ``height`` h: signed distance of the reconstructed point from the robust road plane
  (:mod:`d3cli.road.plane`), metres, + up.
* A candidate region is a connected set of pixels whose median-filtered height is below
  ``-min_depth`` (pothole) or above ``+min_height`` (bump).
* **Depth** is measured against the *surrounding surface*, not the global plane alone:
  the reference is the median height of a ring of road pixels (``ring_px`` wide) around
  the region grown down its walls to their foot (:func:`_with_walls`), so a gently
  cambered or sloping road does not add to or take from a pothole.  ``depth = reference - h`` (bumps: ``h - reference``).
* ``area_m2``: the area of the road plane covered by the region's pixels (each pixel's
  footprint on the plane, :func:`d3cli.road.plane.plane_footprint`), i.e. the opening of
  the pothole in square metres, independent of the image scale and of the viewing angle.
* ``max_depth_mm``: the mean of the 9 deepest pixels of the median-filtered depth over the
  region's decided pixels (all its pixels when fewer than 9 are decided; robust to
  single-pixel spikes without the bias of a percentile on a bowl).  Joined potholes are split at a depth saddle, a terrace or a neck of
  their outline (:func:`d3cli.road.splitting.split_parts`).  A region must also be
  deeper than ``noise_k`` times the height noise expected at its distance, and its mean
  depth must exceed ``mean_noise_k`` standard errors of a mean of spatially correlated
  stereo noise (``noise_cell_px`` pixels per independent error).
* ``volume_l``: sum over the region grown by the ring of ``footprint * max(depth, 0)``,
  litres (1 l = 1e-3 m^3): the material needed to fill it up to the surrounding surface.
* ``decided_share``: share of the region's pixels (and of the pixels without an estimate
  that it encloses) whose disparity the method decided itself (valid.png), not filled.
* ``at_border``: the region reaches the image border (what lies beyond is unmeasured:
  area and volume are lower bounds).
* ``confidence``: ``ok``, or ``low`` with the reasons in ``flags`` and the numbers they
  were decided from in ``evidence`` (:mod:`d3cli.road.confidence`); ``low_confidence`` is
  ``confidence == "low"``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from ..config import RoadConfig
from .confidence import ConfidenceRules, deep_at_border, depressions, flags_of, spikiness
from .plane import RoadPlane, plane_footprint
from .pointcloud import Camera
from .compiled import band_medians, label_boxes, median, noise_terms
from .morphology import dilate_near, fill_holes, grown_box
from .splitting import smoothed_depth, split_component
from .threads import map_on_threads

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Defect:
    """One pothole or bump; see the module docstring for the definitions."""

    id: int
    kind: str  # "pothole" | "bump"
    centroid_px: tuple[float, float]  # [u, v]
    bbox_px: tuple[int, int, int, int]  # [u0, v0, u1, v1], inclusive
    centroid_m: tuple[float, float, float]  # [x, y, z], left camera frame
    area_m2: float
    max_depth_mm: float  # bumps: max height above the surrounding surface
    mean_depth_mm: float
    volume_l: float
    decided_share: float
    low_confidence: bool
    # The region reaches the image border: the part beyond is unmeasured, so depth, area
    # and volume are lower bounds (and a mismatched far field often ends there).
    at_border: bool = False
    # Exterior outline of each connected part of the region: polygons of (u, v) pixel
    # vertices (cv2.approxPolyDP, 1 px), largest part first.
    outline_px: tuple = ()
    # "ok", or "low" with the reasons in ``flags`` (codes of d3cli.road.confidence.REASONS)
    # and the numbers they were decided from in ``evidence``; low_confidence is "low".
    confidence: str = "ok"
    flags: tuple = ()
    evidence: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Plain dict of every field (tuples as lists), as written to defects.json."""
        out = {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}
        out["outline_px"] = [[list(p) for p in poly] for poly in self.outline_px]
        return out


def median_filled(height: np.ndarray, size: int, fill: float | None = None) -> tuple[np.ndarray, float]:
    """(median filter of a float map with inf holes, holes staying inf; the value the holes
    stood in the filter as: ``fill``, by default the median of the finite heights)."""
    finite = np.isfinite(height)
    if not finite.any():
        return height.copy(), 0.0 if fill is None else fill
    fill = float(median(height[finite])) if fill is None else fill
    med = cv2.medianBlur(np.where(finite, height, fill).astype(np.float32), size)
    return np.where(finite, med, np.inf).astype(np.float32), fill


def median_patched(smooth: np.ndarray, height: np.ndarray, zones: np.ndarray, size: int, fill: float) -> np.ndarray:
    """``smooth`` (the :func:`median_filled` of a map) with the pixels whose filter reads a
    pixel of ``zones`` recomputed from ``height``, a map that differs from that one only
    inside ``zones``: the same values as filtering all of ``height`` (holes standing as
    ``fill``), at the cost of the zones' bounding box."""
    out = smooth.copy()
    r = size // 2
    # the box read (its edge: the map's, or 2 r beyond the zones) and the box written
    # (r beyond the zones: every pixel whose filter window reaches a zone)
    read, written = grown_box(zones, 2 * r, 2 * r), grown_box(zones, r, r)
    if read is None:
        return out
    med, _ = median_filled(height[read], size, fill)
    out[written] = med[tuple(slice(w.start - b.start, w.stop - b.start) for w, b in zip(written, read))]
    return out


@dataclass(frozen=True)
class DefectTuning:
    """Tuning of :func:`find_defects` that no configuration key exposes.

    The thresholds people set (depth, height, area, ring, confidence, splitting) are
    :class:`~d3cli.config.RoadConfig`'s; these are fixed by measurement and changed in
    tests and experiments only.

    Attributes
    ----------
    median_px : int
        Odd median filter size against disparity noise before thresholding (3 or 5).
    noise_k : float
        A defect's peak depth must exceed ``noise_k`` times the height noise expected at
        its distance (the disparity noise of :func:`prepare_scene`).
    mean_noise_k, noise_cell_px : float
        A defect's mean depth must exceed ``mean_noise_k`` standard errors of a mean over
        its pixels.  Stereo noise is spatially correlated over the matching support, so a
        region of ``n`` pixels averages only ``max(1, n / noise_cell_px)`` independent
        errors: ``se = sigma_h sqrt(noise_cell_px / max(n, noise_cell_px))``.
        ``noise_cell_px`` is the correlation area of the disparity error: its integral
        ``sum rho`` measured 670-940 px on the sun/dusk synth pairs (cost window 25,
        smoothing radius 15 of configs/road.yaml).  5 standard errors: the map holds
        ~10^3 such cells per kind, and the errors of the noisy pairs have heavier tails
        than a Gaussian (the usual 5-sigma allowance for looking everywhere).
    split_smooth_px : float
        Gaussian smoothing of the depth for the saddles of :func:`d3cli.road.splitting.split_parts`, pixels (about
        one noise cell: ``0.4 sqrt(noise_cell_px)``).
    split_terrace : bool
        Cut terraces too (a shallow pothole whose floor runs into a deeper one's wall, cue 3
        of :func:`d3cli.road.splitting.split_parts`); the shelf must lie ``max(min_depth_mm, 3 sigma_h)`` above the pit.
    local_noise_px : int
        Outer radius of the annulus around a region whose robust height spread (1.4826
        MAD of all its heights) replaces sigma_h in both significance tests where it is
        larger.
    peak_px, peak_share : int, float
        A defect's depth is the mean of its deepest decided pixels (median-filtered): the
        ``peak_share`` of them, at least ``peak_px``.  A fixed handful of pixels reads the
        extremes of the map, not the floor: on wet floors the specular mismatches and on
        dark ones the noise, both deep (on the 126 tuning pairs of docs/road.md the 9
        deepest read wet potholes 13 % deep in the median and 44 % of them more than 20 %
        off; 2 % of the region: 1 %, 14 %; dusk 7 % -> 2 %, sun unchanged within 20 %).
        Pointed floors pay for it: a cone reads about 6 % shallow.
    gap_px : int
        Radius of the disc a region is grown by before its reference ring starts (the ring
        keeps off the wall's last pixels).
    wall_step_px : int
        Width of the bands :func:`_with_walls` follows a wall down in.
    """

    median_px: int = 5
    noise_k: float = 3.0
    mean_noise_k: float = 5.0
    noise_cell_px: float = 900.0
    split_smooth_px: float = 12.0
    split_terrace: bool = True
    local_noise_px: int = 80
    peak_px: int = 9
    peak_share: float = 0.02
    gap_px: int = 2
    wall_step_px: int = 2


@dataclass(frozen=True)
class _Scene:
    """What every region of one height map is measured against (computed once per map)."""

    height: np.ndarray
    decided: np.ndarray
    camera: Camera
    plane: RoadPlane
    road: RoadConfig
    tuning: DefectTuning
    finite: np.ndarray
    smooth: np.ndarray
    footprint: np.ndarray
    v_all: np.ndarray
    u_all: np.ndarray
    kernel_ring: np.ndarray
    kernel_gap: np.ndarray
    kernel_local: np.ndarray
    map_decided: float
    sigma_d: float
    split_noise: float
    #: the whole map's shape, and where this scene's arrays start in it (a region's working
    #: window, :func:`_window`; the whole map: (0, 0))
    full_shape: tuple = (0, 0)
    origin: tuple = (0, 0)
    rules: ConfidenceRules = ConfidenceRules()
    #: the value that stands in for pixels without a height in the median filter of ``smooth``
    fill: float = 0.0
    #: measure only what tells a defect from none and its depth (:func:`candidate_regions`)
    brief: bool = False
    #: only the components with a pixel in this mask (the whole map's) are measured
    #: (:func:`remeasure`); None: every one
    only: np.ndarray | None = None


def find_defects(
    height: np.ndarray,
    decided: np.ndarray,
    camera: Camera,
    plane: RoadPlane,
    road: RoadConfig | None = None,
    tuning: DefectTuning | None = None,
    *,
    return_regions: bool = False,
    rules: ConfidenceRules | None = None,
):
    """Potholes and bumps of one height map.

    Parameters
    ----------
    height : ndarray, float32, (H, W)
        :func:`d3cli.road.plane.height_map`, metres, inf where no estimate.
    decided : ndarray, bool, (H, W)
        Pixels the method decided itself (valid.png).
    camera : Camera
    plane : RoadPlane
    road : RoadConfig, optional
        The thresholds (defaults: ``RoadConfig()``): ``min_depth_mm``, ``min_height_mm``
        and ``min_area_m2`` of a pothole (depth below the surrounding surface), a bump
        (height above it) and of both (area on the road plane); ``ring_px``, the width of
        the ring of surrounding road that gives the reference height, pixels;
        ``min_decided_share``, below which share of decided pixels a defect is
        ``low_confidence``; ``split_prominence_mm``, ``split_neck`` and
        ``split_min_area_m2``, the splitting of joined potholes (:func:`d3cli.road.splitting.split_parts`):
        depth-saddle prominence (at least the map's ``noise_k`` sigma_h too), neck ratio
        (1: no neck split) and smallest part (plane area); ``min_region_decided_share``:
        a region with a smaller share of decided pixels is dropped (measured on the hole
        filling's extrapolation), unless the map's own decided share is below
        ``min_decided_share`` (then every defect is kept, low confidence).
    tuning : DefectTuning, optional
        The rest of the tuning (defaults: ``DefectTuning()``).
    return_regions : bool, keyword-only
        Also return each defect's pixel mask (bool (H, W)), same order.
    rules : ConfidenceRules, optional, keyword-only
        The thresholds of the confidence flags (:mod:`d3cli.road.confidence`).

    Returns
    -------
    list of Defect
        Potholes first (deepest first), then bumps; ids 1..N in that order.
    """
    road = RoadConfig() if road is None else road
    scene = replace(prepare_scene(height, decided, camera, plane, road, DefectTuning() if tuning is None else tuning),
                    rules=ConfidenceRules() if rules is None else rules)
    return _defects_of(scene, return_regions)


@dataclass(frozen=True)
class Candidates:
    """The first pass of a report that measures its defects on a re-matched map
    (:func:`candidate_regions`): the stored map's scene and its defects, briefly measured."""

    scene: _Scene
    defects: list  # of Defect: kind, bbox_px, area_m2, max_depth_mm, decided_share, at_border
    regions: list  # of bool (H, W) masks, the defects' order


def candidate_regions(height: np.ndarray, decided: np.ndarray, camera: Camera, plane: RoadPlane,
                      road: RoadConfig | None = None, tuning: DefectTuning | None = None, *,
                      rules: ConfidenceRules | None = None) -> Candidates:
    """The first pass of a report that measures its defects on a re-matched map: the
    defects of the stored map, found and split as by :func:`find_defects` but measured only
    as far as telling a defect from none and its depth go (``kind``, ``bbox_px``,
    ``area_m2``, ``max_depth_mm``, ``decided_share`` and ``at_border``; the centroids, mean
    depth, volume, outline and evidence left at zero or empty): the re-match
    (:mod:`d3cli.road.rematch`) needs where they are, and :func:`remeasure` their depths.

    Parameters
    ----------
    height, decided, camera, plane, road, tuning
        As :func:`find_defects`.
    rules : ConfidenceRules, optional, keyword-only
        As :func:`find_defects`; :func:`remeasure` keeps them unless given others.

    Returns
    -------
    Candidates
        The stored map's scene (heights, footprints, the map's noise), its defects and
        their regions (bool (H, W) each).
    """
    road = RoadConfig() if road is None else road
    scene = replace(prepare_scene(height, decided, camera, plane, road, DefectTuning() if tuning is None else tuning),
                    brief=True, rules=ConfidenceRules() if rules is None else rules)
    defects, regions = _defects_of(scene, True)
    return Candidates(scene, defects, regions)


def remeasure(stored: Candidates, height: np.ndarray, zones: np.ndarray, *, rules: ConfidenceRules | None = None,
              return_regions: bool = False):
    """:func:`find_defects` on ``height``, a map that differs from the one of
    :func:`candidate_regions` (``stored``) only inside ``zones``.

    Only the candidate components with a pixel in ``zones`` (or within the median filter's
    reach of them) are measured: the others have the heights that the first pass found no
    defect in.  The map's noise (``sigma_d``), the footprints and the median filter's
    stand-in for missing heights are the stored map's.  Each defect's
    ``evidence["rematch_change"]`` is the relative change of its depth against the stored
    defect of its kind that overlaps it most (0 where none does; :mod:`d3cli.road.confidence`):
    a piece that reads far shallower than the stored defect it lies in is often a shelf or
    a fragment of a deeper pothole, one far deeper a floor the re-match misread.

    Parameters
    ----------
    stored : Candidates
        :func:`candidate_regions`' result.
    height : ndarray, float32, (H, W)
        The height map after the re-match.
    zones : ndarray, bool, (H, W)
        The pixels the re-match may have changed (every re-matched zone).
    rules : ConfidenceRules, optional, keyword-only
        As :func:`find_defects`; by default the first pass's.
    return_regions : bool, keyword-only
        As :func:`find_defects`.
    """
    first = stored.scene
    height = np.where(first.footprint > 0, height, np.inf).astype(np.float32)
    size = first.tuning.median_px
    smooth = median_patched(first.smooth, height, zones, size, first.fill)
    # the filtered heights changed within the filter's reach of the zones
    reach = dilate_near(zones, np.ones((size, size), np.uint8))
    scene = replace(first, height=height, finite=np.isfinite(height), smooth=smooth, brief=False, only=reach,
                    rules=first.rules if rules is None else rules)
    defects, regions = _defects_of(scene, True)
    pairs = list(zip(stored.defects, stored.regions))
    defects = [with_flags(d, scene.road, scene.rules, rematch_change=_rematch_change(d, r, pairs))
               for d, r in zip(defects, regions)]
    return (defects, regions) if return_regions else defects


def _rematch_change(defect: Defect, region: np.ndarray, stored: list) -> float:
    """Relative change of ``defect``'s depth by the re-match: against the defect of the
    stored map (``stored``: (defect, region) pairs) that overlaps ``region`` most, of the
    same kind; 0 when none overlaps (nothing to compare)."""
    best, overlap = None, 0
    u0, v0, u1, v1 = defect.bbox_px
    for other, other_region in stored:
        a0, b0, a1, b1 = other.bbox_px
        if other.kind != defect.kind or a0 > u1 or a1 < u0 or b0 > v1 or b1 < v0:
            continue  # no pixel in common: the masks need not be compared
        box = (slice(max(v0, b0), min(v1, b1) + 1), slice(max(u0, a0), min(u1, a1) + 1))
        n = int(np.count_nonzero(other_region[box] & region[box]))
        if n > overlap:
            best, overlap = other, n
    if best is None or best.max_depth_mm <= 0:
        return 0.0
    return round(defect.max_depth_mm / best.max_depth_mm - 1.0, 3)


def _kinds(road: RoadConfig) -> tuple:
    """(kind, sign of the height, threshold in mm) of potholes and bumps."""
    return ("pothole", -1.0, road.min_depth_mm), ("bump", 1.0, road.min_height_mm)


def _defects_of(scene: _Scene, return_regions: bool):
    """The defects of a scene, potholes first (deepest first), then bumps, with their flags."""
    found: list = []
    # pixels of any defect of either kind: what the rings and the wall growth leave out
    road = scene.road
    other = scene.finite & (np.abs(scene.smooth) > min(road.min_depth_mm, road.min_height_mm) * 1e-3)
    for kind, sign, thr_mm in _kinds(road):
        found += _find_kind(scene, kind, sign, thr_mm, other)
    found.sort(key=lambda kd: (kd[0] != "pothole", -kd[2]["max_depth_mm"]))
    defects = [with_flags(Defect(id=i + 1, kind=kind, **d, low_confidence=False), scene.road, scene.rules)
               for i, (kind, _, d) in enumerate(found)]
    return (defects, [r for _, r, _ in found]) if return_regions else defects


def with_flags(defect: Defect, road: RoadConfig, rules: ConfidenceRules | None = None, **evidence) -> Defect:
    """``defect`` with its confidence decided from its evidence (plus ``evidence``):
    ``flags`` (:func:`d3cli.road.confidence.flags_of`), ``confidence`` and ``low_confidence``."""
    merged = {**defect.evidence, **evidence}
    flags = flags_of(merged, min_decided_share=road.min_decided_share, rules=rules)
    return replace(defect, evidence=merged, flags=flags, confidence="low" if flags else "ok",
                   low_confidence=bool(flags))


def prepare_scene(height, decided, camera: Camera, plane: RoadPlane, road: RoadConfig, tuning: DefectTuning) -> _Scene:
    """The per-map quantities of :func:`find_defects`: filtered heights, footprints, noise."""
    shape = height.shape
    footprint = plane_footprint(shape, camera, plane)
    # A pixel whose ray misses the road plane (beyond its horizon: footprint 0) sees no
    # road, so it has no height above the road: a failed map's plane can put a
    # horizon inside the image, and regions there have no plane area or pixel size.
    height = np.where(footprint > 0, height, np.inf).astype(np.float32)
    finite = np.isfinite(height)
    # the holes' stand-in in the median filter: the median height, over every fourth
    # finite pixel (as the noise below)
    known = _every_fourth(height[finite])
    fill = float(median(known)) if known.size else 0.0
    smooth, fill = median_filled(height, tuning.median_px, fill)
    # row and column of every pixel, as read-only views (no two full index arrays per map)
    v_all = np.broadcast_to(np.arange(shape[0])[:, None], shape)
    u_all = np.broadcast_to(np.arange(shape[1])[None, :], shape)
    ring_px, local_noise_px = road.ring_px, tuning.local_noise_px
    kernel_ring = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * ring_px + 1, 2 * ring_px + 1))
    kernel_gap = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * tuning.gap_px + 1, 2 * tuning.gap_px + 1))
    kernel_local = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * local_noise_px + 1, 2 * local_noise_px + 1))
    map_decided = float(decided[finite].mean()) if finite.any() else 0.0
    # Z of every pixel and its disparity residual, in one compiled pass; the medians of the
    # two on both threads.  A disparity error dd moves a road point by dh = c Z / (f B) dd
    # along the normal, so h f B / (c Z) is the residual in disparity pixels; its robust
    # spread over the map (potholes are a minority; real road relief counts in) is the
    # disparity noise, 0 with fewer than 10 residuals.
    z, resid = noise_terms(smooth, float(camera.f), float(camera.baseline), float(camera.cx), float(camera.cy),
                           np.asarray(plane.normal, np.float64), float(plane.offset))
    # Saddle depth that splits a region: half the threshold, but not less than the height
    # noise at the median distance (noisy floors would otherwise split into pieces).  Both
    # medians over every fourth pixel (in image order: an even spread over the map; over
    # 50 000 of a 720p map's cells, where a median moves by a fraction of a percent).
    resid, z = _every_fourth(resid), _every_fourth(z)
    sigma_d, z_med = map_on_threads(lambda task: task(), (
        lambda: _mad_sigma(resid) if resid.size >= 10 else 0.0,
        lambda: float(median(z)) if z.size else 0.0))
    split_noise = tuning.noise_k * plane.offset * z_med / (camera.f * camera.baseline) * sigma_d
    return _Scene(height=height, decided=decided, camera=camera, plane=plane, road=road, tuning=tuning,
                  finite=finite, smooth=smooth, footprint=footprint, v_all=v_all, u_all=u_all,
                  kernel_ring=kernel_ring, kernel_gap=kernel_gap, kernel_local=kernel_local,
                  map_decided=map_decided, sigma_d=sigma_d, split_noise=split_noise, full_shape=shape, fill=fill)


def _every_fourth(values: np.ndarray) -> np.ndarray:
    """Every fourth of a map's values (in image order: an even spread), all of them where
    that would leave fewer than ten: what the map-wide medians of :func:`prepare_scene`
    are taken over."""
    return values[::4] if values.size >= 40 else values


def _find_kind(s: _Scene, kind: str, sign: float, thr_mm: float, other: np.ndarray) -> list:
    """(kind, region mask, measurements) of every pothole (``sign`` -1) or bump (+1);
    ``other``: the pixels of any defect of either kind (:func:`_defects_of`)."""
    road, tuning = s.road, s.tuning
    with np.errstate(invalid="ignore"):
        cand = s.finite & (sign * s.smooth > thr_mm * 1e-3)
    # the labels, then each component's bounding box in one compiled pass
    n, labels = cv2.connectedComponents(cand.astype(np.uint8), connectivity=8)
    stats, areas = label_boxes(labels, n, s.footprint)
    level = max(thr_mm * 1e-3, s.split_noise)

    def smoothed(box):  # the split cue's smoothed depth, on a component's box only
        return sign * smoothed_depth(s.smooth, tuning.split_smooth_px, box)

    def component(item) -> list:
        lab, box = item
        found = []
        # Necks are measured on the outline at a depth the noise cannot make (noise_k sigma_h):
        # below it the outline of a noisy map is drawn by the noise.
        for piece in split_component(labels, lab, box, s.footprint, level=level,
                                     prominence=max(road.split_prominence_mm * 1e-3, s.split_noise),
                                     neck=road.split_neck, min_part_m2=road.split_min_area_m2,
                                     step=level if tuning.split_terrace else np.inf, smoothed=smoothed):
            if s.footprint[box][piece].sum() < road.min_area_m2:
                continue  # its region is a part of it: it cannot pass the area test
            # Measured in a window around the part that holds everything its measurement
            # reads (its walls, rings and noise annulus): the same pixels, the same results,
            # at the cost of the window instead of the map (a noisy 720p map has hundreds of
            # candidate parts; whole-image masks and dilations per part take seconds a map).
            window = _window(s, box, int(piece.sum()))
            local = _crop(s, window)
            comp = np.zeros(local.height.shape, bool)
            comp[tuple(slice(b.start - w.start, b.stop - w.start) for b, w in zip(box, window))] = piece
            measured = measure_region(local, comp, other[window], sign, thr_mm)
            if measured is not None:
                region = np.zeros(s.height.shape, bool)
                region[window] = measured[0]
                found.append((kind, region, measured[1]))
        return found

    # Components are cut and measured independently: on both threads, in their order.  A
    # component smaller than the smallest defect holds none (its parts are parts of it): a
    # noisy map has dozens of such specks, not cut at all (the margin covers the rounding
    # of the sums, so that no component whose part could pass is left out).
    wanted = areas >= road.min_area_m2 * (1 - 1e-6)
    if s.only is not None:  # only the components that reach into s.only (:func:`remeasure`)
        reach = np.zeros(n, bool)
        reach[np.unique(labels[s.only])] = True
        wanted &= reach
    components = [(lab, (slice(y, y + h), slice(x, x + w))) for lab, (x, y, w, h) in enumerate(stats[1:], start=1)
                  if wanted[lab]]
    return [f for found in map_on_threads(component, components) for f in found]


def _window(s: _Scene, box: tuple, n_px: int) -> tuple:
    """Slices of the map around a part's bounding box ``box`` (of ``n_px`` pixels) that hold
    every pixel :func:`measure_region` reads for it: the walls (:func:`_with_walls`, out to
    ``max(4 ring_px, sqrt(n_px / pi))``), the reference ring beyond them (``ring_px``) and
    the noise annulus (``local_noise_px``), with a pixel to spare, so that no mask the
    measurement makes touches the window's edge unless that is the map's edge."""
    ring_px = s.road.ring_px
    margin = max(4 * ring_px, int(np.ceil(np.sqrt(n_px / np.pi)))) + ring_px + 3
    margin = max(margin, s.tuning.local_noise_px + 2)
    h, w = s.height.shape
    return (slice(max(box[0].start - margin, 0), min(box[0].stop + margin, h)),
            slice(max(box[1].start - margin, 0), min(box[1].stop + margin, w)))


def _crop(s: _Scene, window: tuple) -> _Scene:
    """The scene's per-pixel arrays cut to ``window`` (the rest as it is)."""
    return replace(s, height=s.height[window], decided=s.decided[window], finite=s.finite[window],
                   smooth=s.smooth[window], footprint=s.footprint[window], v_all=s.v_all[window],
                   u_all=s.u_all[window], origin=(window[0].start, window[1].start), only=None)


def measure_region(s: _Scene, comp: np.ndarray, other: np.ndarray, sign: float, thr_mm: float):
    """(region, measurements) of one split component, or None when it is no defect."""
    road, tuning, finite, footprint = s.road, s.tuning, s.finite, s.footprint
    if footprint[comp].sum() < road.min_area_m2:
        return None  # the region is a part of comp: it cannot pass the area test
    # The reference ring lies beyond the walls: a ring drawn right outside the part deeper
    # than the threshold sits on a gentle wall (a cone's or a bowl's) and takes the
    # reference, and with it depth, area and volume, millimetres too low.
    whole = _with_walls(s, comp, sign, other)
    grown = dilate_near(whole, s.kernel_gap)
    reach = dilate_near(whole, s.kernel_ring)
    ring = reach & ~grown & finite & ~other
    if ring.sum() < 10:
        ring = reach & ~grown & finite
    if ring.sum() < 10:
        return None
    ref = float(np.median(s.height[ring]))
    with np.errstate(invalid="ignore"):
        depth_s = sign * (s.smooth - ref)
        depth = sign * (s.height - ref)
    region = comp & (depth_s > thr_mm * 1e-3)
    area = float(footprint[region].sum())
    if area < road.min_area_m2 or not region.any():
        return None
    # The deepest pixels where the method decided the disparity itself: a filled pixel's
    # depth is the hole filling's extrapolation (on wet floors it read potholes up to twice
    # as deep), not a measurement.
    measured = region & s.decided
    deepest_of = measured if measured.sum() >= tuning.peak_px else region
    peak = _peak(depth_s[deepest_of], tuning.peak_px, tuning.peak_share)
    # Significance of the peak, and of the mean depth: a small blob of correlated matching
    # noise can peak above noise_k sigma, but a real depression spans many noise cells.
    # Tested against the map's noise at the region's distance first: the local noise
    # (:func:`_local_sigma_h`) is never less, so a region that fails here fails there too,
    # without the dilations by the local-noise disc (most of a noisy map's candidates).
    n_px = int((region & finite).sum())
    mean_raw = float(np.mean(depth[region & finite])) if n_px else 0.0
    cells = np.sqrt(tuning.noise_cell_px / max(n_px, tuning.noise_cell_px))

    def fails(sigma_h):
        return peak < tuning.noise_k * sigma_h or mean_raw < tuning.mean_noise_k * sigma_h * cells

    sigma_h = _map_sigma_h(s, region)
    if fails(sigma_h):
        return None
    sigma_local = _local_sigma_h(s, comp, sigma_h)
    if fails(sigma_local):
        return None
    # Pixels without any estimate that the region encloses are unmeasured parts of it.
    enclosed = fill_holes(region)
    share = float((s.decided & finite)[enclosed].mean())
    if share < road.min_region_decided_share and s.map_decided >= road.min_decided_share:
        return None  # measured on filled pixels: the hole filling's extrapolation, no depth
    vs, us = s.v_all[region], s.u_all[region]
    at_border = bool(vs.min() == 0 or us.min() == 0 or vs.max() == s.full_shape[0] - 1 or us.max() == s.full_shape[1] - 1)
    if s.brief:
        return region, dict(evidence={}, centroid_px=(0.0, 0.0), bbox_px=(int(us.min()), int(vs.min()), int(us.max()),
                                                                          int(vs.max())),
                            centroid_m=(0.0, 0.0, 0.0), area_m2=area, max_depth_mm=peak * 1e3, mean_depth_mm=0.0,
                            volume_l=0.0, decided_share=share, at_border=at_border)
    zone = grown & finite
    vol = float((footprint[zone] * np.clip(depth_s[zone], 0, None)).sum())
    w = footprint[region]
    # 3-D centroid from the measured points of the region (footprint weighted).
    pts = _points_at(s.height[region], us, vs, s.camera, s.plane)
    rules = s.rules
    evidence = {
        "spikiness": round(spikiness(depth_s, deepest_of, peak_px=tuning.peak_px, spike_px=rules.spike_px), 3),
        "snr": round(peak / sigma_local, 1) if sigma_local > 0 else float("inf"),
        "decided_share": round(share, 3),
        "deep_at_border": deep_at_border(depth_s, region, peak, s.origin, s.full_shape),
        "depressions": depressions(depth_s, region, prominence=road.split_prominence_mm * 1e-3,
                                   smooth_px=tuning.split_smooth_px),
    }
    return region, dict(
        evidence=evidence,
        centroid_px=(float(np.average(us, weights=w)), float(np.average(vs, weights=w))),
        bbox_px=(int(us.min()), int(vs.min()), int(us.max()), int(vs.max())),
        centroid_m=tuple(float(x) for x in np.average(pts, axis=0, weights=w)),
        area_m2=area,
        max_depth_mm=peak * 1e3,
        mean_depth_mm=float(np.average(depth[region & finite], weights=footprint[region & finite]) * 1e3),
        volume_l=vol * 1e3,
        decided_share=share,
        at_border=at_border,
        outline_px=outline(region, offset=s.origin),
    )


def _peak(depth: np.ndarray, peak_px: int, share: float = 0.0) -> float:
    """Maximum depth: the mean of the deepest (median-filtered) pixels, the ``share`` of
    them and at least ``peak_px`` (:class:`DefectTuning`)."""
    k = min(max(int(peak_px), int(round(share * depth.size)), 1), depth.size)
    return float(np.mean(np.partition(depth, depth.size - k)[depth.size - k:]))


def _with_walls(s: _Scene, comp: np.ndarray, sign: float, other: np.ndarray, *, tolerance_m: float = 5e-4) -> np.ndarray:
    """``comp`` grown down its walls to their foot: every pixel within ``r`` of it, where
    ``r`` is the first distance at which the median depth of the band of pixels
    ``(r - step_px, r]`` away (other defects left out; ``step_px``: the tuning's
    ``wall_step_px``) comes within ``tolerance_m`` of its
    lowest value out to ``4 ring_px`` or the radius of a disc of ``comp``'s area, whichever
    is more (a cone twice as deep as the threshold has a wall as wide as that radius).

    A wall ends where the surface stops rising: a fixed depth level to grow through ends
    a cone's or a bowl's gentle wall millimetres below the road (2 sigma_h of a dark map is
    more than the threshold), and the reference ring beyond it then sits on the pothole.
    The band medians are taken over whole bands, so the stereo noise does not decide
    where the growth stops; out to the first near-minimum, so a neighbouring pothole
    further out does not pull it on."""
    reach = max(4 * s.road.ring_px, int(np.ceil(np.sqrt(np.count_nonzero(comp) / np.pi))))
    step_px = s.tuning.wall_step_px
    box = grown_box(comp, reach, reach)
    inside = comp[box]
    dist = cv2.distanceTransform((~inside).astype(np.uint8), cv2.DIST_L2, 5)
    use = s.finite[box] & ~other[box] & (dist > 0) & (dist <= reach)
    band = np.ceil(dist[use] / step_px).astype(np.int64)
    with np.errstate(invalid="ignore"):
        depth = sign * s.smooth[box][use]
    # the median of each band (of at least 10 pixels), compiled: one pass groups the bands
    medians = band_medians(band, depth, -(-reach // step_px) + 1, 10)
    out = np.zeros_like(comp)
    out[box] = inside
    if np.isfinite(medians).any():
        foot = int(np.nonzero(medians <= np.nanmin(medians) + tolerance_m)[0][0])
        out[box] |= dist <= foot * step_px
    return out


def _map_sigma_h(s: _Scene, region: np.ndarray) -> float:
    """The map's height noise at a region's distance, metres: sigma_h = c Z / (f B)
    sigma_d, sigma_d measured on this map."""
    camera, plane = s.camera, s.plane
    z_region = float(np.median(_points_at(s.height[region], s.u_all[region], s.v_all[region], camera, plane)[:, 2]))
    return plane.offset * z_region / (camera.f * camera.baseline) * s.sigma_d


def _local_sigma_h(s: _Scene, comp: np.ndarray, sigma_h: float) -> float:
    """Height noise a region's depth is tested against, metres: the map's noise at its
    distance, ``sigma_h`` (:func:`_map_sigma_h`), or the noise around it where that is higher.

    Significance: the peak must stand above the height noise at that distance, not only
    above the fixed threshold: far, noisy road otherwise yields false potholes.
    """
    # The local noise where it is higher: the map's error is not uniform (a dark or far
    # part of the image matches worse), and a blob of that local noise passes a test made
    # with the map's median noise.  Robust spread (1.4826 MAD) of every height in an
    # annulus outside the ring: other defects there are a minority, which the median
    # ignores.  Leaving out the heights beyond the map's noise_k sigma_h instead cuts the
    # spread of a noisy part off at that level: on the dark far field of dusk pairs the
    # estimate comes out too small and blobs of noise pass as defects.
    annulus = dilate_near(comp, s.kernel_local) & ~dilate_near(comp, s.kernel_ring) & s.finite
    if annulus.sum() >= 50:
        local = s.height[annulus]
        sigma_h = max(sigma_h, _mad_sigma(local))
    return sigma_h


def _mad_sigma(values: np.ndarray) -> float:
    """1.4826 MAD of ``values`` (in their type): their standard deviation were they
    normal, which a minority of outliers (potholes, mismatches) does not move."""
    return float(1.4826 * median(np.abs(values - median(values))))


def outline(mask: np.ndarray, *, tolerance_px: float = 1.0, offset: tuple = (0, 0)) -> tuple:
    """Exterior outline polygons of a bool mask's connected parts, largest first.

    ``offset``: (row, column) of the mask's first pixel in the image the vertices refer to.

    Returns
    -------
    tuple of tuple of (int, int)
        ((u, v), ...) vertices per part, simplified to ``tolerance_px`` (Douglas-Peucker).
    """
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE,
                                   offset=(int(offset[1]), int(offset[0])))
    contours = sorted(contours, key=lambda c: -cv2.contourArea(c))
    polys = []
    for c in contours:
        c = cv2.approxPolyDP(c, tolerance_px, True)
        polys.append(tuple((int(p[0][0]), int(p[0][1])) for p in c))
    return tuple(polys)


def _points_at(heights, us, vs, camera: Camera, plane: RoadPlane) -> np.ndarray:
    """3-D points of pixels (us, vs) from their heights ``heights``: the ray meets
    ``n . P + c = h``."""
    n = np.asarray(plane.normal)
    r = np.stack([(us - camera.cx) / camera.f, (vs - camera.cy) / camera.f, np.ones(len(us))], axis=1)
    z = (heights.astype(np.float64) - plane.offset) / (r @ n)
    return r * z[:, None]
