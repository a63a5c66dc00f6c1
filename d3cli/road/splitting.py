"""Cutting a region of joined potholes into separate potholes: a depth saddle, a terrace
(a shelf around a deeper core) or a neck of the outline.

Used by :func:`d3cli.road.defects.find_defects`.  May import numpy, SciPy's ``ndimage``,
scikit-image, OpenCV, :mod:`d3cli.road.compiled`, :mod:`d3cli.road.morphology` and the
standard library only.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np

from .compiled import dilate, h_maxima, opening, terrace_level
from .morphology import opening_near

log = logging.getLogger(__name__)


def split_parts(labels: np.ndarray, n: int, depth: np.ndarray, footprint: np.ndarray, *, level: float,
           prominence: float, smooth_px: float, neck: float, min_part_m2: float, step: float = np.inf,
           boxes: bool = False):
    """Masks of the components of ``labels``, each cut into separate potholes.

    ``boxes``: yield ``(mask, box)`` instead, the mask cut to its component's bounding box
    ``box`` (a pair of slices): a full-size mask per part costs a pass over the image,
    and a noisy map has hundreds of components.

    Three cues, because overlapping potholes join in three ways (applied in the order 1, 3, 2; a part cut by 3 is not cut by 2):

    1. **Depth saddle**: deepest points of the depth map (Gaussian-smoothed with
       ``smooth_px``, about one noise cell, so a rough or noisy floor does not count) that
       stand ``prominence`` metres above the saddle between them seed a watershed on the
       depth (two pits joined by a shallower dip).
    2. **Neck**: within each part, lobes of the outline whose narrowest passage (the
       distance-transform saddle, half the neck's width) is at most ``neck`` times the
       inscribed radius of the smaller lobe seed a watershed on the distance transform (of
       the part's smoothed depth deeper than ``level``):
       the h-maxima of ``log(1 + dt)`` with ``h = -log(neck)`` are exactly those lobes.  A
       shallow pothole whose rim runs into a deeper one's wall joins it without any depth
       saddle, and the union of the two openings often has a neck.
    3. **Terrace** (:func:`_terrace_pieces`): the floor of a shallow pothole that runs into
       a deeper one's wall is neither a depth minimum nor always behind a neck (the
       union's outline can be nearly convex), but it is a wide flat shelf: between a level
       ``t`` and ``t + step / 2`` the part loses a blob that is much wider than a wall
       (it survives an opening with a disc of half the radius of ``min_part_m2``) and at
       least ``min_part_m2`` large, while at least ``min_part_m2`` of the part lies more
       than ``step`` deeper (the pit is a pothole below the shelf: ``step`` is the
       pothole threshold).  A shelf whose convex hull holds the deepest point is a ledge
       *around* the pit (the pit lies inside the shallower pothole's outline), one
       pothole, as in the ground truth of :func:`d3cli.data.synth.pothole_groups`.

    Parts smaller than ``min_part_m2`` (plane area, ``footprint``) are merged back into the
    neighbour they share the longest border with, and neighbouring parts of which one's
    centre lies inside the other's opening are merged (:func:`_merge_nested`).
    """
    from scipy import ndimage

    def smooth(box):  # the smoothed depth of a component large enough to be cut
        return smoothed_depth(depth, smooth_px, box)

    # each component's bounding box in one pass over the labels (a mask and a scan of the
    # whole image per component cost more than the splitting itself on a noisy map)
    for lab, box in enumerate(ndimage.find_objects(labels, max(n - 1, 0)), start=1):
        if box is None:
            continue
        for piece in split_component(labels, lab, box, footprint, level=level, prominence=prominence, neck=neck,
                                     min_part_m2=min_part_m2, step=step, smoothed=smooth):
            yield _full(piece, box, labels.shape, boxes)


def split_component(labels: np.ndarray, lab: int, box: tuple, footprint: np.ndarray, *, level: float,
                    prominence: float, neck: float, min_part_m2: float, step: float, smoothed) -> list:
    """The parts of component ``lab`` of ``labels`` (:func:`split_parts`), as masks of its
    bounding box ``box``; ``smoothed(box)``: the smoothed depth (:func:`smoothed_depth`) on
    ``box`` (called only when the component is large enough to be cut).  Components are
    cut independently of one another."""
    sub_comp = labels[box] == lab
    if footprint[box][sub_comp].sum() < 2 * min_part_m2:  # too small to hold two parts
        return [sub_comp]
    kernel_open = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    sub_depth = np.where(sub_comp, smoothed(box), 0.0)
    parts = _watershed_parts(-sub_depth, h_maxima(sub_depth, prominence) & sub_comp, sub_comp)
    pieces = []
    for part in parts:
        # Terraces before necks: a terrace is cut along the wall between the two floors
        # (a watershed on the depth); a neck cut follows the outline and would leave part
        # of the deep wall to the shallow pothole (its depth then reads too deep), and
        # the concave cut of a terrace would show necks of its own.
        terraces = _terrace_pieces(part, sub_depth, footprint[box], level=level, step=step, min_part_m2=min_part_m2)
        if len(terraces) > 1:
            pieces += terraces
            continue
        # The outline of the smoothed depth: the noisy map's own outline is ragged at
        # the noise-cell scale and shows necks that are not there.
        opened = opening(part & (sub_depth > level), kernel_open).astype(np.uint8)
        dt = cv2.distanceTransform(np.pad(opened, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
        lobes = h_maxima(np.log1p(dt), -np.log(neck)) & opened.astype(bool) if neck < 1 else np.zeros_like(part)
        pieces += _watershed_parts(-dt, lobes, part)
    return _merge_nested(_merge_small(pieces, footprint[box], min_part_m2), ~sub_comp)


def smoothed_depth(depth: np.ndarray, smooth_px: float, box: tuple | None = None) -> np.ndarray:
    """The depth of :func:`split_parts`' saddles: float32, 0 where not finite, Gaussian-
    smoothed with ``smooth_px`` (none when 0).  Odd in the depth: the map of ``-depth`` is
    exactly minus this one.

    ``box`` (a pair of slices): the values inside it only, computed from the box grown by
    the kernel's reach (the same values as smoothing the whole map: the filter reads
    nothing farther, and where the grown box meets the map's edge both reflect the same
    pixels), at the cost of the box."""
    if box is None:
        box = (slice(0, depth.shape[0]), slice(0, depth.shape[1]))
    if smooth_px <= 0:
        return np.where(np.isfinite(depth[box]), depth[box], 0.0).astype(np.float32)
    size = int(round(smooth_px * 8 + 1)) | 1  # OpenCV's own choice for float maps
    r = size // 2
    grown = tuple(slice(max(b.start - r, 0), min(b.stop + r, n)) for b, n in zip(box, depth.shape))
    part = depth[grown]
    blurred = cv2.GaussianBlur(np.where(np.isfinite(part), part, 0.0).astype(np.float32), (size, size), smooth_px)
    return blurred[tuple(slice(b.start - g.start, b.stop - g.start) for b, g in zip(box, grown))]


def _full(piece: np.ndarray, box: tuple, shape: tuple, boxes: bool):
    """What :func:`split_parts` yields for a part: ``(piece, box)``, or with ``boxes`` false
    the part as a mask of the whole image."""
    if boxes:
        return piece, box
    mask = np.zeros(shape, bool)
    mask[box] = piece
    return mask


def _terrace_pieces(part: np.ndarray, depth: np.ndarray, footprint: np.ndarray, *, level: float, step: float,
                    min_part_m2: float, level_step: float = 2e-3, ledge_share: float = 0.4,
                    _calls_left: int = 3) -> list:
    """``part`` cut at the shallowest terrace, then each piece again (cue 3 of :func:`_split`).

    ``depth``: the smoothed depth (metres, + down) of the part's box; ``footprint``: plane
    area per pixel.  Returns a list of bool masks covering ``part``.
    """
    from skimage.segmentation import watershed

    if not np.isfinite(step) or _calls_left <= 0 or footprint[part].sum() < 2 * min_part_m2:
        return [part]
    deepest = float(np.percentile(depth[part], 98))
    candidates = _terrace_candidates(part, depth, footprint, level=level, step=step, min_part_m2=min_part_m2,
                                     level_step=level_step, deepest=deepest)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    for _, t, core, blobs in candidates[:3]:
        markers = np.zeros(part.shape, np.int32)
        markers[core] = 1
        for i, blob in enumerate(blobs, start=2):
            markers[blob] = i
        basins = watershed(-depth, markers, mask=part)
        if not _keep_shelves(basins, len(blobs), part, cross, ledge_share):
            continue
        log.debug("terrace at %.1f mm: shelves of %s m^2 beside a pit to %.1f mm", t * 1e3,
                  [round(float(footprint[b].sum()), 3) for b in blobs], deepest * 1e3)
        out = []
        for i in range(1, len(blobs) + 2):
            piece = basins == i
            if piece.any():
                out += _terrace_pieces(piece, depth, footprint, level=t + level_step, step=step,
                                       min_part_m2=min_part_m2, level_step=level_step, ledge_share=ledge_share,
                                       _calls_left=_calls_left - 1)
        return out
    return [part]


def _terrace_candidates(part: np.ndarray, depth: np.ndarray, footprint: np.ndarray, *, level: float, step: float,
                        min_part_m2: float, level_step: float, deepest: float) -> list:
    """(shelf area, level t, core mask, shelf blobs) of every level that shows a terrace,
    largest shelf first (:func:`_terrace_pieces`)."""
    # Opening disc: half the radius of the smallest part, in pixels at the part's distance.
    pixel_m = float(np.sqrt(np.median(footprint[part])))
    # A disc wider than the part's box opens it away whatever its size: capping it there
    # changes nothing and bounds the element by the image.
    radius_px = int(np.clip(round(0.5 * np.sqrt(min_part_m2 / np.pi) / max(pixel_m, 1e-9)), 2, max(part.shape)))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    # Candidate levels: the shelf is widest just above a floor (a raised-cosine or any
    # rounded wall is flat where it meets the floor, so the bands above the floor are wide
    # too); the level with the largest shelf is tried first.
    deepest_at = np.unravel_index(np.argmax(np.where(part, depth, -np.inf)), part.shape)
    candidates = []
    part = np.ascontiguousarray(part, bool)
    depth = np.ascontiguousarray(depth)
    footprint = np.ascontiguousarray(footprint, np.float64)
    stack = np.empty((2, part.size), np.int32)
    box = np.array([0, part.shape[0], 0, part.shape[1]], np.int64)  # shrinks with the level
    # One pair of masks for all levels: a level rewrites the box of the one before, outside
    # which both are 0 (fresh masks per level cost more in page faults than the level).
    core, lost = np.zeros(part.shape, bool), np.zeros(part.shape, np.uint8)
    for t in np.arange(level, deepest - step + 1e-9, level_step):
        # The core: the parts deeper than t + step / 2 that hold the pit (the part deeper
        # than t + step); a floor that only dips below t + step / 2 (a shelf's middle) is
        # shelf.  The lost band: deeper than t, outside the core.
        pit_area, n_core, n_below, lost_area = terrace_level(part, depth, footprint, float(t), float(step), core,
                                                             lost, stack, box)
        if pit_area < min_part_m2:
            break  # no pothole left below a shelf at t
        if median_below(depth, core, t + step, counts=(n_core, n_below)):
            continue  # the rest is a floor with relief (up to ~1 cm on broken floors), not a pit below a shelf
        if lost_area < min_part_m2:
            continue  # the shelf is a part of the lost band: no opening can make it large enough
        shelf = opening_near(lost, disc)
        if footprint[shelf].sum() < min_part_m2:
            continue
        # One marker per connected piece of the lost band: the opening can cut one shelf in two.
        labels, k = _label(lost.astype(bool) & dilate(shelf, disc))
        blobs = []
        for i in range(1, k + 1):
            blob = (labels == i) & shelf
            if footprint[blob].sum() < min_part_m2:
                continue
            hull = cv2.convexHull(np.stack(np.nonzero(blob)[::-1], axis=1).astype(np.int32))
            if cv2.pointPolygonTest(hull, (float(deepest_at[1]), float(deepest_at[0])), False) >= 0:
                continue  # a ledge around the pit: the same pothole
            blobs.append(blob)
        if blobs:
            candidates.append((sum(float(footprint[b].sum()) for b in blobs), t, core.copy(), blobs))
    candidates.sort(key=lambda c: -c[0])
    return candidates


def median_below(values: np.ndarray, mask: np.ndarray, x: float, *, counts: tuple | None = None) -> bool:
    """``np.median(values[mask]) < x``, decided by counting the values below ``x`` (two
    passes over the arrays, no copy of the selection); the median itself only when the
    count leaves it open (an even count with exactly half of the values below ``x``).
    ``counts``: ``(n, below)``, the pixels of ``mask`` and those below ``x``, where the
    caller has counted them."""
    if counts is None:
        counts = int(np.count_nonzero(mask)), int(np.count_nonzero(mask & (values < x)))
    n, below = counts
    if 2 * below > n:
        return True  # the middle value, or both middle values, below x
    if 2 * below < n or n == 0:
        return False  # the middle value, or both, at x or above (an empty mask: no median below x)
    return bool(np.median(values[mask]) < x)


def _keep_shelves(basins: np.ndarray, n_blobs: int, part: np.ndarray, cross: np.ndarray, ledge_share: float) -> int:
    """Number of shelf basins (labels 2 ..) kept as pothole pieces; the others are merged
    into the pit's basin (label 1) in ``basins``, in place.

    A shallow pothole beside the pit has an outline of its own: most of its piece's border
    is rim (the part's outside).  A ledge around the pit borders the pit along as much as
    it borders the road.
    """
    kept = 0
    for i in range(2, n_blobs + 2):
        piece = basins == i
        edge = piece & ~cv2.erode(piece.astype(np.uint8), cross, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
        near = cv2.dilate(edge.astype(np.uint8), cross).astype(bool)
        shared = int((near & (basins == 1)).sum())
        rim = int((near & ~part).sum()) + int(edge[0].sum() + edge[-1].sum() + edge[:, 0].sum() + edge[:, -1].sum())
        if shared >= ledge_share * max(shared + rim, 1):
            basins[piece] = 1
        else:
            kept += 1
    return kept


def _watershed_parts(surface: np.ndarray, peaks: np.ndarray, mask: np.ndarray) -> list:
    """Watershed basins of ``surface`` from the connected ``peaks`` inside ``mask``; [mask]
    when there are fewer than two peaks."""
    from skimage.segmentation import watershed

    # h_maxima can return one maximum as pixels a step apart on a plateau: join those.
    peaks = cv2.dilate(peaks.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))).astype(bool) & mask
    markers, k = _label(peaks)
    if k <= 1:
        return [mask]
    basins = watershed(surface, markers, mask=mask)
    return [basins == i for i in range(1, k + 1) if (basins == i).any()]


def _merge_small(parts: list, footprint: np.ndarray, min_m2: float) -> list:
    """Merge the smallest part below ``min_m2`` into the neighbour sharing most border, until none is."""
    parts = list(parts)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    while len(parts) > 1:
        areas = [float(footprint[p].sum()) for p in parts]
        i = int(np.argmin(areas))
        if areas[i] >= min_m2:
            break
        ring = cv2.dilate(parts[i].astype(np.uint8), cross).astype(bool) & ~parts[i]
        shared = [int((ring & p).sum()) if j != i else -1 for j, p in enumerate(parts)]
        j = int(np.argmax(shared))
        parts[j] = parts[j] | parts[i]
        del parts[i]
    return parts


def _merge_nested(parts: list, outside: np.ndarray, share: float = 0.5) -> list:
    """Merge each inner fragment, a part at least ``share`` of whose border it shares with
    other parts (little of its outline is the rim, ``outside``), into the neighbour it
    shares most border with; decided on the parts as cut, so the result does not depend
    on their order.

    The ground truth's rule (:func:`d3cli.data.synth.pothole_groups`): a pit inside a
    shallower pothole's outline is a deeper spot of it.  The cues cut such a union (a
    shelf around a deeper core, deeper blobs on a wet floor) into fragments, each of
    which measures a part of one pothole.
    """
    if len(parts) < 2:
        return list(parts)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    parent = list(range(len(parts)))

    def root(i):
        while parent[i] != i:
            i = parent[i]
        return i

    for i, p in enumerate(parts):
        edge = p & ~cv2.erode(p.astype(np.uint8), cross, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
        near = cv2.dilate(edge.astype(np.uint8), cross).astype(bool)
        shared = [int((near & q).sum()) if j != i else 0 for j, q in enumerate(parts)]
        rim = int((near & outside).sum()) + int(edge[0].sum() + edge[-1].sum() + edge[:, 0].sum() + edge[:, -1].sum())
        if sum(shared) >= share * max(sum(shared) + rim, 1):
            ri, rj = root(i), root(int(np.argmax(shared)))
            if ri != rj:
                parent[ri] = rj
    groups: dict = {}
    for i, p in enumerate(parts):
        groups[root(i)] = groups[root(i)] | p if root(i) in groups else p
    return list(groups.values())


def _label(mask: np.ndarray):
    n, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    return labels, n - 1
