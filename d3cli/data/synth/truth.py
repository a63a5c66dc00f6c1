"""Exact ground truth: disparity from each pixel's centre ray, non-occlusion by casting
from the right camera, pothole ids and measurements, and :func:`self_test`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from .render import _OCCLUSION_TOL_M, _centre_hits, visible_from
from .rig import StereoRig
from .potholes import radial_weight
from .terrain import Pothole, _HeightField, _normalised_radius, _pothole_weight


@dataclass
class SynthPair:
    """One rendered stereo pair with exact ground truth.

    Attributes
    ----------
    left, right : ndarray, uint8, (H, W)
        Grey images of the left and right camera.
    disparity : ndarray, float32, (H, W)
        Left-view disparity in pixels, ``u_left - u_right`` of the surface point seen
        by each left pixel's centre ray; ``inf`` where invalid (no road hit).
    nocc : ndarray, bool, (H, W)
        True where that point is visible in the right view (inside the image and not
        occluded).
    calib : dict
        ``f``, ``baseline``, ``cx``, ``cy``, ``width``, ``height``, ``height_m``,
        ``pitch_deg``, ``roll_deg``, ``doffs`` and ``ndisp`` (= ceil(max gt) + 8).
    info : dict
        How the pair was made: seed, variant, material, potholes (world and left-image
        positions, depths), bump, lighting.
    pothole_ids : ndarray, uint8, (H, W) or None
        Defect id (1..N, the order of ``defects_gt``) of the surface point each left
        pixel sees where a pothole lowers the road by more than 1 mm, else 0; nested
        potholes carry their group's id (:func:`pothole_groups`).
    defects_gt : list of dict
        Per pothole: ``id``, ``depth_mm`` (below the surrounding surface), ``area_m2``
        (horizontal area deeper than 10 mm), ``volume_l`` (fill volume up to the
        surrounding surface), ``visible_px`` (pixels of the id mask), ``u``, ``v``, and
        ``members`` (ids of the nested potholes it stands for, itself included) or
        ``part_of`` (the id of the deeper pothole it is part of; no pixels, area 0).
    """

    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    nocc: np.ndarray
    calib: dict
    info: dict = field(default_factory=dict)
    pothole_ids: np.ndarray | None = None
    defects_gt: list = field(default_factory=list)


def _describe_hole(hole: Pothole, rig: StereoRig) -> dict:
    left_c, _ = rig.centres()
    p = rig.rotation() @ (np.array([hole.x, hole.y, -hole.depth]) - left_c)
    return {
        "x": hole.x, "y": hole.y, "depth_m": hole.depth, "shape": hole.shape,
        "diameter_m": 2.0 * hole.semi_a,
        "semi_axes_m": [hole.semi_a, hole.semi_b], "angle_rad": hole.angle,
        "flat_fraction": hole.flat_fraction, "wobble": list(hole.wobble), "water_fill": hole.water_fill,
        "u": float(rig.f * p[0] / p[2] + rig.cx), "v": float(rig.f * p[1] / p[2] + rig.cy),
    }


_OPENING_M = 0.01  # a pothole's opening: where it lowers the road by more than 10 mm
_TRUTH_GRID_M = 2e-3  # the world grid area and volume are integrated on


def _opening_ratio(hole: Pothole, x: float, y: float) -> float:
    """Where world point (x, y) lies in ``hole``: its normalised radius over that of the
    hole's opening (< 1: inside the part deeper than 10 mm)."""
    rho = float(_normalised_radius(hole, x, y))
    w = _OPENING_M / hole.depth
    if w >= 1.0:
        return math.inf
    if hole.shape == "classic":
        # Inverse of the raised-cosine wall of _pothole_weight at weight w.
        rho_open = hole.flat_fraction + (1.0 - hole.flat_fraction) * math.acos(2.0 * w - 1.0) / math.pi
    else:  # the outermost radius where the profile (core left out) is deeper than w
        radii = np.linspace(0.0, 1.0, 2001)
        deep = radii[radial_weight(hole, radii) > w]
        if not deep.size:
            return math.inf
        rho_open = float(deep.max())
    return rho / rho_open


def pothole_groups(holes) -> list[int]:
    """Which potholes form one defect: for each hole, the 0-based index of its group's
    deepest hole.

    Overlapping potholes of the generator merge into one surface (the deepest wins).  Two
    of them are *nested* when the centre (the floor) of one lies inside the other's
    opening (the part deeper than 10 mm, ``min_depth_mm`` of a pothole): a pit inside a
    shallower pothole's outline is a deeper spot of that pothole, and a shallow hole
    centred on a deeper one's wall is a shelf of it; an inspector reports one pothole,
    as deep as its deepest point, as large as the union.  Each hole joins the nearest
    (centre distance) deeper hole it is nested with; chains join (union-find).  Potholes
    that only touch or overlap rim to rim, each floor outside the other's opening, stay
    separate defects (a saddle or a terrace between two pits).

    Parameters
    ----------
    holes : sequence of Pothole

    Returns
    -------
    list of int
        ``len(holes)`` indices into ``holes``.
    """
    parent = list(range(len(holes)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k, hole in enumerate(holes):
        nested = [j for j, other in enumerate(holes)
                  if other.depth > hole.depth or (other.depth == hole.depth and j < k)
                  if _opening_ratio(hole, other.x, other.y) < 1.0 or _opening_ratio(other, hole.x, hole.y) < 1.0]
        if nested:
            j = min(nested, key=lambda j: math.hypot(holes[j].x - hole.x, holes[j].y - hole.y))
            rk, rj = root(k), root(j)
            if rk != rj:
                parent[rk] = rj
    deepest = {}
    for k in range(len(holes)):
        r = root(k)
        if r not in deepest or holes[k].depth > holes[deepest[r]].depth:
            deepest[r] = k
    return [deepest[root(k)] for k in range(len(holes))]


def pothole_truth(holes, rig: StereoRig, points: np.ndarray, field_: _HeightField | None = None
                  ) -> tuple[np.ndarray, list]:
    """Pothole id mask (uint8 (H, W)) and the per-pothole ground truth of defects_gt.json.

    Nested potholes (:func:`pothole_groups`) are one defect: the entry of the group's
    deepest hole describes the whole group (its depth, the area and volume of the union)
    and its id marks the group's pixels; every other member's entry says ``part_of`` that
    id and has no pixels (``visible_px`` 0).  Depth is the nominal depth below the
    surrounding surface (the floor relief of a few mm is not counted); area and volume are
    integrated on a 2 mm world grid of the group's own depth profile (where separate
    defects overlap, the deeper one owns a point, as in the rendered surface).

    Parameters
    ----------
    holes : sequence of Pothole
    rig : StereoRig
    points : ndarray, float64, (H, W, 3)
        World point each left pixel sees (inf/nan where none).
    field_ : _HeightField, optional
        The rendered surface.  Given, depth, area and volume are those of its ``sink``
        (how far the potholes lower the road: profile, floor relief and a water surface
        included), on its grid refined to 2 mm by bilinear interpolation (the surface the
        renderer traces): ``depth_mm`` is then the deepest point of the surface, and
        ``profile_depth_mm`` the nominal depth of the profile.
    """
    h, w = points.shape[:2]
    groups = pothole_groups(holes)
    members = {g: [k for k, gk in enumerate(groups) if gk == g] for g in set(groups)}
    ids = np.zeros((h, w), np.uint8)
    best = np.zeros((h, w))
    xs, ys = points[..., 0], points[..., 1]
    finite = np.isfinite(xs) & np.isfinite(ys)
    xs, ys = np.where(finite, xs, 1e9), np.where(finite, ys, 1e9)
    for k, hole in enumerate(holes):
        sink = hole.depth * _pothole_weight(hole, xs, ys)
        take = finite & (sink > 1e-3) & (sink > best)
        ids[take] = groups[k] + 1
        best = np.where(take, sink, best)
    spacing = _TRUTH_GRID_M
    truth = []
    for k, hole in enumerate(holes):
        desc = _describe_hole(hole, rig)
        if groups[k] != k:
            truth.append({"id": k + 1, "shape": hole.shape, "depth_mm": 1e3 * hole.depth, "area_m2": 0.0, "volume_l": 0.0,
                          "visible_px": 0, "u": desc["u"], "v": desc["v"], "part_of": groups[k] + 1})
            continue
        group = [holes[j] for j in members[k]]
        gx, gy = _group_grid(group, spacing)
        own = np.max([g.depth * _pothole_weight(g, gx, gy) for g in group], axis=0)
        for j, other in enumerate(holes):
            if groups[j] != k:
                own = np.where(other.depth * _pothole_weight(other, gx, gy) > own, 0.0, own)
        entry = {"id": k + 1, "shape": hole.shape, "depth_mm": 1e3 * hole.depth}
        if field_ is not None and field_.sink is not None:
            # Where the group's profiles lower the road, the surface's own sink.
            surface = np.where(own > 0, _sink_at(field_, gx, gy), 0.0)
            entry["profile_depth_mm"], own = 1e3 * hole.depth, surface
            # The traced surface is bilinear between the field's nodes: its deepest point is
            # a node (a cone's apex between nodes is not drawn).
            entry["depth_mm"] = 1e3 * _deepest_node(field_, group, [o for j, o in enumerate(holes) if groups[j] != k])
        truth.append({**entry, "area_m2": float((own > _OPENING_M).sum() * spacing ** 2),
                      "volume_l": float(own.sum() * spacing ** 2 * 1e3),
                      "visible_px": int((ids == k + 1).sum()), "u": desc["u"], "v": desc["v"],
                      "members": [j + 1 for j in members[k]]})
    return ids, truth


def _group_grid(group, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """World x, y (float64 2-D) of the regular grid, ``spacing`` metres, over the boxes
    that hold a group of potholes' profiles; anchored at their edges, so a pothole moved
    by a whole vector keeps its samples."""
    reach = [1.25 * max(g.semi_a, g.semi_b) for g in group]
    return np.meshgrid(
        np.arange(min(g.x - r for g, r in zip(group, reach)), max(g.x + r for g, r in zip(group, reach)), spacing),
        np.arange(min(g.y - r for g, r in zip(group, reach)), max(g.y + r for g, r in zip(group, reach)), spacing))


def _deepest_node(field_: _HeightField, group: list, others: list) -> float:
    """Largest sink (metres) of the field's nodes that ``group``'s profiles lower and no
    other (deeper there) pothole owns."""
    ny, nx = field_.sink.shape
    gx, gy = np.meshgrid(field_.x0 + field_.spacing * np.arange(nx), field_.y0 + field_.spacing * np.arange(ny))
    lo_x = min(g.x - 1.25 * max(g.semi_a, g.semi_b) for g in group)
    hi_x = max(g.x + 1.25 * max(g.semi_a, g.semi_b) for g in group)
    lo_y = min(g.y - 1.25 * max(g.semi_a, g.semi_b) for g in group)
    hi_y = max(g.y + 1.25 * max(g.semi_a, g.semi_b) for g in group)
    box = (gx[0] >= lo_x) & (gx[0] <= hi_x), (gy[:, 0] >= lo_y) & (gy[:, 0] <= hi_y)
    gx, gy, sink = gx[box[1]][:, box[0]], gy[box[1]][:, box[0]], field_.sink[box[1]][:, box[0]]
    own = np.max([g.depth * _pothole_weight(g, gx, gy) for g in group], axis=0)
    for other in others:
        own = np.where(other.depth * _pothole_weight(other, gx, gy) > own, 0.0, own)
    return float(np.where(own > 0, sink, 0.0).max(initial=0.0))


def _sink_at(field_: _HeightField, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """The field's sink at world points (gx, gy) of a regular grid, bilinear (as traced)."""
    fx = np.clip((gx - field_.x0) / field_.spacing, 0.0, field_.sink.shape[1] - 1.0).astype(np.float32)
    fy = np.clip((gy - field_.y0) / field_.spacing, 0.0, field_.sink.shape[0] - 1.0).astype(np.float32)
    return cv2.remap(field_.sink.astype(np.float32), fx, fy, cv2.INTER_LINEAR).astype(np.float64)


def _ground_truth(rig: StereoRig, field_: _HeightField, h_top: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact left disparity (float32, inf invalid), non-occlusion mask (bool) and the
    world points (float64 (H, W, 3)) the left pixels' centre rays hit."""
    rot = rig.rotation()
    left_c, right_c = rig.centres()
    hf = (field_.h, field_.lipschitz, field_.tile, field_.x0, field_.y0, field_.spacing, h_top)
    points = _centre_hits(left_c, rot, rig.f, rig.cx, rig.cy, rig.width, rig.height, *hf)
    in_right = (points - right_c) @ rot.T
    u_right = rig.f * in_right[..., 0] / in_right[..., 2] + rig.cx
    u_left = np.arange(rig.width, dtype=np.float64)[None, :]
    disparity = u_left - u_right
    valid = np.isfinite(disparity) & (disparity > 0)
    visible = visible_from(right_c, points, *hf, _OCCLUSION_TOL_M)
    nocc = valid & visible & (u_right >= 0.0) & (u_right <= rig.width - 1.0)
    return np.where(valid, disparity, np.inf).astype(np.float32), nocc, points


def self_test(pair: SynthPair, *, border: int = 8) -> float:
    """RMS grey-level error of the right view warped into the left by the ground truth.

    Each left pixel (u, v) is compared with the right image at (u - d, v), bilinear,
    over non-occluded pixels at least ``border`` pixels from every edge (of both
    views).  For noise-free ``sun`` pairs it measures rendering consistency (a grey
    level or two); with noise it approaches sqrt(2) x the noise level.

    Returns
    -------
    float
        RMS error on the 0-255 scale (nan when no pixel qualifies).
    """
    left = pair.left.astype(np.float64)
    right = pair.right.astype(np.float64)
    h, w = left.shape
    vv, uu = np.mgrid[0:h, 0:w]
    x = uu - pair.disparity.astype(np.float64)
    usable = pair.nocc & np.isfinite(x) & (x >= border) & (x <= w - 1 - border)
    usable &= (uu >= border) & (uu < w - border) & (vv >= border) & (vv < h - border)
    if not usable.any():
        return float("nan")
    xs = x[usable]
    rows = vv[usable]
    x0 = np.floor(xs).astype(np.int64)
    a = xs - x0
    warped = right[rows, x0] * (1.0 - a) + right[rows, np.minimum(x0 + 1, w - 1)] * a
    return float(np.sqrt(np.mean((warped - left[usable]) ** 2)))
