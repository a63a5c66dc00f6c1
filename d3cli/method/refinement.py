"""Step 8: sub-pixel refinement and the finishing (docs/design.md, 'Finishing').

The occlusion tests, the speckle filter, the filling and the smoothing of this module run
on the host, as numba kernels (:mod:`d3cli.kernels.finishing`) that give the values of a
NumPy/OpenCV formulation bit for bit (that formulation is the reference in
``tests/reference/finishing.py``).  On a device backend ``D3Stereo._finish`` runs the
occlusion tests, the speckle filter and the filling on the device instead
(``backend.drop_occluded``, ``backend.drop_speckles``, ``backend.fill_rows`` or
``backend.fill_inside``, ``backend.median_of_holes``: the same row bodies, the same
values; the speckles those of ``cv2.filterSpeckles``).
"""

from __future__ import annotations

import cv2
import numpy as np

from ..kernels import host
from ..kernels.backend import Backend


def _as_map(disparity) -> np.ndarray:
    """C-contiguous float32 (H, W) copy or view of a disparity map."""
    disp = np.ascontiguousarray(disparity, dtype=np.float32)
    if disp.ndim != 2:
        raise ValueError(f"a disparity map is 2-D (H, W), got shape {disp.shape}")
    return disp


def _like(array, disp: np.ndarray, dtype) -> np.ndarray:
    """``array`` broadcast to the map's shape, C-contiguous (the kernels index it per pixel;
    a ValueError names both shapes when it does not fit)."""
    return np.ascontiguousarray(np.broadcast_to(np.asarray(array, dtype=dtype), disp.shape))


def _check_updatable(valid: np.ndarray, disp: np.ndarray) -> None:
    """``valid`` is updated in place by the fused hole-making passes: it must be a
    C-contiguous bool map of the disparity's shape."""
    if valid.shape != disp.shape or valid.dtype != np.bool_ or not valid.flags.c_contiguous:
        raise ValueError("valid must be a C-contiguous bool map of the disparity's shape (updated in place)")


def refine_subpixel(cost, disparity, *, backend: Backend, equiangular: bool = False):
    """Sub-pixel refinement at full resolution (docs/design.md, 'Finishing', step 8).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    disparity : ndarray, int32, (H, W)
        Integer disparities, -1 undecided.
    backend : Backend
    equiangular : bool, keyword-only
        Fit two lines of equal and opposite slope (equiangular line fitting) instead of the
        paper's parabola: the better model of a V-shaped minimum, as the semi-global
        smoothing's linear penalties make (:attr:`d3cli.config.Config.equiangular_subpixel`).

    Returns
    -------
    ndarray, float32, (H, W)
        d + offset clamped to [-0.5, 0.5]; inf where undecided.  Parabola:
        offset = (C(d-1) - C(d+1)) / (2 (C(d-1) + C(d+1) - 2 C(d))); lines:
        offset = (C(d-1) - C(d+1)) / (2 (max(C(d-1), C(d+1)) - C(d))).
    """
    return backend.subpixel(cost, disparity, equiangular)


def occluded_by_uniqueness(disparity: np.ndarray, valid: np.ndarray, *, tolerance: float = 1.0) -> np.ndarray:
    """Pixels whose match in the right image is claimed by a nearer (larger-d) pixel.

    Each valid left pixel (u, v) maps to the right pixel round(u - d); when several map
    to the same right pixel, only the largest disparity can be visible there, and the
    others (smaller by more than ``tolerance``) are occluded in the right view: their
    estimate has no true match.  This is the classic uniqueness/occlusion test; in
    D3Stereo it catches diffusion that leaked foreground or random disparities into
    half-occluded regions and into the left border strip, which filling then gives the
    background disparity.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
    tolerance : float, keyword-only

    Returns
    -------
    ndarray, bool, (H, W)
        True where the pixel is judged occluded.
    """
    disp = _as_map(disparity)
    return host.uniqueness_occluded(disp, _like(valid, disp, bool), float(tolerance))


def out_of_view(disparity: np.ndarray, valid: np.ndarray, *, max_disparity: int) -> np.ndarray:
    """Pixels of the left border strip whose estimate is suspect: their true match may
    lie left of the right image.

    In each row, ``b`` is the first valid disparity at or right of column
    ``min(max_disparity, W - 1)`` (the nearest surface that is surely inside the view).  A
    strip pixel u < b with a decided disparity below b - 1 most likely sees that same
    surface, whose match is outside the right image, so its own estimate cannot be
    right; it becomes a hole and filling gives it b.

    Returns
    -------
    ndarray, bool, (H, W)
    """
    disp = _as_map(disparity)
    w = disp.shape[1]
    start = min(int(max_disparity), w - 1)
    if start < 0:  # a slice start, as valid[:, start:] read it
        start = max(start + w, 0)
    return host.out_of_view_mask(disp, _like(valid, disp, bool), start)


def drop_occluded(disparity: np.ndarray, valid: np.ndarray, *, max_disparity: int, tolerance: float = 1.0,
                  out: np.ndarray | None = None) -> tuple[np.ndarray, int, np.ndarray]:
    """Both occlusion tests at once, their pixels made holes: what ``D3Stereo._finish`` runs.

    ``occluded = occluded_by_uniqueness(...) | out_of_view(...)`` on the incoming
    ``valid``, which is then updated in place (``valid &= ~occluded``), and ``out`` gets
    ``np.where(valid, disparity, inf)``: one pass over the rows instead of six over the
    map.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), C-contiguous; updated in place
    max_disparity : int, keyword-only
    tolerance : float, keyword-only
    out : ndarray, float32, (H, W), optional, keyword-only
        Receives the masked map (may be ``disparity``); a new map when omitted, returned
        as the third value.

    Returns
    -------
    occluded : ndarray, bool, (H, W)
    count : int
        Occluded pixels.
    out : ndarray, float32, (H, W)
    """
    disp = _as_map(disparity)
    _check_updatable(valid, disp)
    w = disp.shape[1]
    start = min(int(max_disparity), w - 1)
    if start < 0:  # a slice start, as out_of_view reads it
        start = max(start + w, 0)
    if out is None:
        out = np.empty(disp.shape, np.float32)
    occluded, count = host.drop_occluded(disp, valid, float(tolerance), start, out)
    return occluded, count, out


def speckles(disparity: np.ndarray, valid: np.ndarray, *, max_size: int, max_diff: float) -> np.ndarray:
    """Small isolated regions of estimates: the speckle filter (an addition to the paper's
    step 8; docs/design.md, 'Finishing').

    Decided pixels are joined into regions through their 4-neighbours whose disparity
    differs by at most ``max_diff``; a region of at most ``max_size`` pixels is a speckle.
    A wrong local minimum of the cost spreads (diffusion, tau = 1) into a small patch
    that no smooth surface continues; a true surface, even a thin one, is mostly larger.
    Disparities are compared in 1/16 px fixed point (``cv2.filterSpeckles``).

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
        Values of non-valid pixels are ignored.
    valid : ndarray, bool, (H, W)
    max_size : int, keyword-only
        Largest speckle, pixels; 0 returns no speckle.
    max_diff : float, keyword-only
        Largest disparity step between two neighbours of a region, pixels.

    Returns
    -------
    ndarray, bool, (H, W)
        True on valid pixels that belong to a speckle.
    """
    disp = _as_map(disparity)
    valid = _like(valid, disp, bool) & np.isfinite(disp)
    if max_size <= 0 or not valid.any():
        return np.zeros(disp.shape, bool)
    # 1/16 px fixed point as OpenCV's own disparities; -1 marks the holes, which
    # filterSpeckles leaves out of every region (its newVal)
    fixed = host.fixed_point_16(disp, valid)
    cv2.filterSpeckles(fixed, -1, int(max_size), max(1, int(round(float(max_diff) * 16.0))))
    return valid & (fixed == -1)


def drop_speckles(disparity: np.ndarray, valid: np.ndarray, *, max_size: int, max_diff: float,
                  out: np.ndarray | None = None) -> tuple[int, np.ndarray]:
    """:func:`speckles` made holes: ``valid &= ~speck`` in place and ``out = np.where(valid,
    disparity, inf)`` (``out`` may be ``disparity``; a new map when omitted, returned as
    the second value); two passes around ``cv2.filterSpeckles`` instead of seven.

    Returns
    -------
    count : int
        Speckle pixels.
    out : ndarray, float32, (H, W)
    """
    disp = _as_map(disparity)
    _check_updatable(valid, disp)
    if out is None:
        out = np.empty(disp.shape, np.float32)
    fixed, n_valid = host.fixed_point_16_finite(disp, valid)
    if max_size <= 0 or n_valid == 0:
        fixed = np.zeros(disp.shape, np.int16)  # no speckle: nothing marked -1
    else:
        cv2.filterSpeckles(fixed, -1, int(max_size), max(1, int(round(float(max_diff) * 16.0))))
    return host.drop_marked(disp, valid, fixed, out), out


def fill_holes(
    disparity: np.ndarray, valid: np.ndarray, *, smooth: bool = True, occluded: np.ndarray | None = None
) -> np.ndarray:
    """Fill undecided pixels: row-wise nearest valid neighbours, the smaller of the two.

    Holes are mostly occlusions, whose true disparity is the background's (the smaller
    one).  Rows without any valid pixel take the nearest filled row.  With ``smooth`` a
    5x5 median over the filled pixels only (decided pixels keep their values) removes the
    streaks of row-wise filling while keeping edges.  When nothing is valid the result is
    all inf: there is nothing to fill from.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
    smooth : bool, keyword-only

    Returns
    -------
    ndarray, float32, (H, W)
    """
    disp = _as_map(disparity)
    # the usable pixels, their rows and their count in one pass (instead of four)
    valid, row_has, n_valid = host.usable(disp, _like(valid, disp, bool))
    if n_valid == 0:
        return np.full(disp.shape, np.inf, np.float32)
    if n_valid == disp.size:
        return disp.copy()
    if occluded is None:
        filled, row_has = host.fill_rows_smaller_side(disp, valid)
    else:
        # Holes that are not occlusions (undecided: weak texture, rejected matches) lie
        # inside a surface: the median of the nearest valid values in the four directions
        # estimates it better than the background side (the row neighbours are found in
        # the filling pass itself).
        up, down = host.nearest_along_columns(disp, valid)
        filled = host.fill_inside(disp, valid, _like(occluded, disp, bool), up, down)
    if not row_has.all():
        host.copy_nearest_rows(filled, row_has)
    if smooth and min(disp.shape) >= 5:
        host.keep_valid(filled, valid, cv2.medianBlur(filled, 5))
    return filled


def smooth_disparity(
    disparity: np.ndarray,
    valid: np.ndarray | None,
    *,
    radius: int,
    sigma: float,
    plane: np.ndarray | None = None,
    kernel: str = "gaussian",
    non_negative: bool = False,
) -> np.ndarray:
    """Edge-preserving smoothing of a disparity map (addition to step 8, measured).

    A bilateral filter with a box spatial kernel of radius ``radius`` and a Gaussian range
    kernel of ``sigma`` on the residual ``r = d - plane``: every finite pixel p becomes
    ``plane_p + sum_q w_q r_q / sum_q w_q`` over the valid q in its box, with
    ``w_q = exp(-(r_q - r_p)^2 / (2 sigma^2))``.  Noise in the estimates (spatially
    correlated over about a matching window) is averaged away, while steps larger than a
    few ``sigma`` (kerbs, pothole rims, object edges) keep their sides apart.  With PT the
    plane is the road model, so the residual of a road is about flat; a symmetric box
    also keeps any linear ramp, so ``plane=None`` works on slanted surfaces too.

    It is computed as a piecewise-linear bilateral filter (Durand and Dorsey 2002):
    range levels ``sigma`` apart (wider when there would be more than 256), per level two
    box sums, the result linearly interpolated between the two levels that bracket
    ``r_p``; levels no pixel interpolates from are skipped.  The box sums are those of
    ``cv2.boxFilter(..., normalize=False, borderType=cv2.BORDER_CONSTANT)``, bit for bit,
    and the range weights NumPy's float32 ``exp``: one pass per group of levels
    (:func:`d3cli.kernels.finishing.smoothing.smooth_groups`, a group per task) computes the
    weights of each entering row, its box sums and each pixel's shares of its two levels.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
        Disparity in pixels; non-finite = no estimate (stays as it is, never used).
    valid : ndarray, bool, (H, W), or None
        Pixels whose values may be averaged into others; None: every finite pixel (what
        the pipeline passes, without building ``np.isfinite(disparity)``).
    radius : int, keyword-only
        Box radius in pixels (window ``2 radius + 1``); 0 returns a copy.
    sigma : float, keyword-only
        Range sigma in disparity pixels (> 0).
    plane : ndarray, float, (H, W), optional, keyword-only
        Reference disparity subtracted before and added after filtering (road model).
    kernel : {"gaussian", "box"}, keyword-only
        Range kernel.  ``box``: every finite pixel takes the plain mean of the
        valid residuals in its box that lie within ``sigma`` of its own
        (:func:`d3cli.kernels.finishing.range_box.box_range_smooth`, direct sums, no ``exp``): the
        same KITTI accuracy as the Gaussian at radius 4, about ten times faster.
    non_negative : bool, keyword-only
        Negative results become 0 (NaN and -0 stay; what ``D3Stereo._finish`` wants:
        averaging residuals to a plane that dips below zero can end a hair below 0), in
        the pass that adds the plane back (one pass less than
        :func:`d3cli.kernels.finishing.smoothing.clamp_negative` after it).

    Returns
    -------
    ndarray, float32, (H, W)
    """
    disp = _as_map(disparity)
    valid = None if valid is None else _like(valid, disp, bool)
    if radius <= 0 or disp.size == 0:
        return host.unsmoothed(disp, non_negative)
    base = None if plane is None else _like(plane, disp, np.float32)
    return host.range_kernel_smooth(disp, valid, base, int(radius), float(sigma), kernel, non_negative)
