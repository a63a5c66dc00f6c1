"""Robust 3-D plane of the road surface and the signed height above it.

The plane is ``n . P + c = 0`` in the left camera frame (x right, y down, z forward,
metres) with ``|n| = 1`` and the sign chosen so that ``c > 0``: the camera centre lies
on the positive side, so ``h(P) = n . P + c`` is the height above the road, + up.

The fit must not be bent by potholes and bumps: RANSAC on a random subset of the
decided points (3-point hypotheses, tolerance growing with the depth error of stereo,
``dZ = Z^2 / (f B) * sigma_d``), then iteratively re-weighted least squares (Tukey
biweight) on the decided points (the first rounds on a sixteenth of them, the last two on
a quarter).  A depression of a few percent of the road is then an
outlier and leaves the plane where the surrounding surface is.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..method.perspective import match_in_right_image
from .compiled import footprint_grid, height_grid, inlier_count, plane_columns, ransac_scores, weighted_scatter
from .pointcloud import Camera
from .threads import halves, map_on_threads

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RoadPlane:
    """``n.P + c = 0``; ``normal`` (3,) unit, ``offset`` c > 0 (camera height, metres)."""

    normal: tuple[float, float, float]
    offset: float
    inlier_share: float

    def height(self, points: np.ndarray) -> np.ndarray:
        """Signed height (metres, + toward the camera side) of (N, 3) points.

        Parameters
        ----------
        points : ndarray
            (N, 3) points in the left camera frame, metres.
        """
        return np.asarray(points, np.float64) @ np.asarray(self.normal) + self.offset

    def to_info(self) -> dict:
        """JSON-ready summary."""
        return {"normal": [float(v) for v in self.normal], "offset_m": float(self.offset),
                "inlier_share": float(self.inlier_share)}


def _plane_from(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Total-least-squares plane of (N, 3) points -> (unit normal, c)."""
    centre = points.sum(0) / len(points)
    d = points - centre
    return _plane_of_scatter(centre, d.T @ d)


def _plane_of_scatter(centre: np.ndarray, scatter: np.ndarray) -> tuple[np.ndarray, float]:
    """Plane through ``centre`` normal to the least-scatter direction -> (unit normal, c > 0)."""
    _, _, vt = np.linalg.svd(scatter)
    n = vt[-1]
    c = -float(n @ centre)
    if c < 0:
        n, c = -n, -c
    return n, c


class _Columns:
    """Every ``step``-th point as the compiled rounds read them: contiguous float64 columns,
    and each point's tolerance ``max(min_tolerance, depth_factor Z^2)`` and its inverse (the
    same in every round: computed once, :func:`~d3cli.road.compiled.plane_columns`)."""

    def __init__(self, points: np.ndarray, step: int, min_tolerance: float, depth_factor: float):
        self.x, self.y, self.z, self.tolerance, self.inverse = plane_columns(points, step, min_tolerance,
                                                                            depth_factor)

    def __len__(self) -> int:
        return len(self.x)

    # One round over a quarter million points takes about a tenth of a millisecond: handing
    # half of it to the report's second thread costs more than it saves.
    def scatter(self, normal, offset) -> tuple:
        """:func:`~d3cli.road.compiled.weighted_scatter` of the points (limit 2)."""
        return weighted_scatter(self.x, self.y, self.z, self.inverse, normal, offset, 2.0)

    def inliers(self, normal, offset) -> int:
        """Points within their tolerance of the plane (:func:`~d3cli.road.compiled.inlier_count`)."""
        return inlier_count(self.x, self.y, self.z, self.tolerance, normal, offset)


def fit_road_plane(
    points: np.ndarray,
    camera: Camera,
    *,
    sigma_disparity: float = 0.5,
    min_tolerance_m: float = 0.01,
    iterations: int = 100,
    sample: int = 20000,
    irls_rounds: int = 8,
    seed: int = 0,
    decimate: int = 16,
    fine_rounds: int = 2,
    fine_decimate: int = 4,
) -> RoadPlane | None:
    """Robust plane of the road points.

    Parameters
    ----------
    points : ndarray, float, (N, 3)
        Decided 3-D points, metres, left camera frame.
    camera : Camera
        For the stereo depth error ``Z^2 / (f B) * sigma_disparity`` in the tolerance.
    sigma_disparity : float, keyword-only
        Disparity noise assumed for the tolerance, pixels.
    min_tolerance_m : float, keyword-only
        Smallest inlier tolerance, metres.
    iterations, sample, irls_rounds, seed : keyword-only
        RANSAC hypotheses, points drawn for RANSAC, IRLS rounds, random seed.  The RANSAC
        plane only starts the IRLS rounds: with half of the points on the road, 100
        hypotheses miss an all-road triple with a probability of 2e-6.
    decimate, fine_rounds, fine_decimate : keyword-only
        The IRLS rounds but the last ``fine_rounds`` use every ``decimate``-th point only,
        the last ones every ``fine_decimate``-th (1: every round on all points).

    Returns
    -------
    RoadPlane or None
        None with fewer than 3 points or no non-degenerate hypothesis.
    """
    # float32 points (disparity_to_points) are read as they are, without a float64 copy
    pts32 = np.ascontiguousarray(points, np.float32 if np.asarray(points).dtype == np.float32 else np.float64)
    if len(pts32) < 3:
        return None
    rng = np.random.default_rng(seed)
    sub = pts32[rng.choice(len(pts32), size=min(sample, len(pts32)), replace=False)].astype(np.float64)

    def tolerance(p):
        return np.maximum(min_tolerance_m, p[:, 2] ** 2 / (camera.f * camera.baseline) * sigma_disparity * 2.0)

    tol_sub = tolerance(sub)
    # The hypotheses drawn at once (a triple that repeats a point is degenerate and scores
    # -1, as a collinear one does), then scored in compiled passes, each half of them on
    # one of the report's threads; the first of the best scores wins.
    triples = rng.integers(0, len(sub), (iterations, 3), dtype=np.int64)
    parts = map_on_threads(lambda part: ransac_scores(sub, triples[part], tol_sub), halves(iterations))
    scores, normals, offsets = (np.concatenate([p[i] for p in parts]) for i in range(3))
    if not len(scores) or scores.max() < 0:
        return None
    best = int(np.argmax(scores))
    n, c = normals[best], float(offsets[best])
    inl = np.abs(sub @ n + c) < tol_sub
    n, c = _plane_from(sub[inl])
    factor = sigma_disparity * 2.0 / (camera.f * camera.baseline)  # tolerance = max(min, factor Z^2)
    # The first rounds on every decimate-th point (in image order: an even spread over the
    # road), the last ``fine_rounds`` on every fine_decimate-th: the fit settles from the
    # RANSAC plane on a sixteenth of the points, and the fine rounds take it to the plane
    # of a quarter of them, an even spread of over 200 000 points at 720p.
    def every(step):  # every step-th point where that leaves at least three
        return step if step > 1 and len(pts32) >= 3 * step else 1

    coarse, fine = (_Columns(pts32, every(step), min_tolerance_m, factor) for step in (decimate, fine_decimate))
    for round_ in range(irls_rounds):
        # Tukey biweight: points beyond 2 tolerances (potholes, kerbs) get weight 0.
        use = coarse if round_ < irls_rounds - fine_rounds else fine
        total, centre, scatter = use.scatter(n, c)
        if total < 3:
            break
        n, c = _plane_of_scatter(centre, scatter)
    share = fine.inliers(n, c) / len(fine)
    return RoadPlane(normal=tuple(float(v) for v in n), offset=float(c), inlier_share=share)


def seen_by_both(disparity: np.ndarray) -> np.ndarray:
    """Pixels with a finite disparity whose match ``u - d`` lies inside the right image,
    bool (H, W): the road model's right-image rule
    (:func:`d3cli.method.perspective.match_in_right_image`, half a pixel of slack).

    Left of that (the left-border strip, ``u < d``) the right camera does not see the
    point: a disparity there is no measurement but the row-wise hole filling's
    extrapolation (horizontal streaks), so the road outputs treat it as no estimate.
    On the dusk-cement synth pairs 99.7 % of that strip is filled, not decided, and
    without this rule it holds a third of the false defects (seed 7: 8 of 25 candidate
    regions).
    """
    return match_in_right_image(disparity, finite=True)


def height_map(disparity: np.ndarray, valid: np.ndarray, camera: Camera, plane: RoadPlane, *,
               origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Signed height above ``plane`` per pixel, float32 (H, W) metres, inf where no estimate.

    Parameters
    ----------
    disparity : ndarray
        float32 (H, W) disparity map, pixels.
    valid : ndarray
        bool (H, W): pixels to back-project.
    camera : Camera
        Focal length, baseline and principal point.
    plane : RoadPlane
        The fitted road plane.
    origin : (int, int), keyword-only
        (row, column) of the arrays' first pixel in the image, when they are a window of it.
    """
    return height_grid(np.asarray(disparity, np.float32), np.asarray(valid, bool), float(camera.f),
                       float(camera.baseline), float(camera.cx), float(camera.cy), float(camera.doffs),
                       np.asarray(plane.normal, np.float64), float(plane.offset), int(origin[0]), int(origin[1]))


def plane_footprint(shape: tuple[int, int], camera: Camera, plane: RoadPlane) -> np.ndarray:
    """Area (m^2) of the road plane seen by each pixel, float64 (H, W); 0 where the ray misses it.

    A pixel's ray ``r = ((u - cx)/f, (v - cy)/f, 1)`` meets the plane at depth
    ``Z = -c / (n . r)``; its footprint there is ``Z^2 / (f^2 |n . r|)`` (solid angle
    ``1 / (f^2 |r|^3)`` times the squared range over the incidence cosine).  Compiled
    (:func:`d3cli.road.compiled.footprint_grid`); the array is read-only and the same
    object for the same shape, camera and plane as the last call.
    """
    key = (tuple(shape), camera, plane)
    if _FOOTPRINT[0] != key:  # the report's two passes over a map share it
        _FOOTPRINT[:] = [key, footprint_grid(int(shape[0]), int(shape[1]), float(camera.f), float(camera.f) ** 2,
                                             float(camera.cx), float(camera.cy),
                                             np.asarray(plane.normal, np.float64), float(plane.offset))]
        _FOOTPRINT[1].flags.writeable = False
    return _FOOTPRINT[1]


_FOOTPRINT: list = [None, None]  # (shape, camera, plane) and its footprint, read-only
