"""Step 8: sub-pixel refinement and hole filling."""

from __future__ import annotations

import warnings

import cv2
import numpy as np


def refine_subpixel(cost, disparity, *, backend):
    """Parabola sub-pixel refinement at full resolution (DESIGN step 8).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    disparity : ndarray, int32, (H, W)
        Integer disparities, -1 undecided.
    backend : module

    Returns
    -------
    ndarray, float32, (H, W)
        d + offset, offset = (C(d-1) - C(d+1)) / (2 (C(d-1) + C(d+1) - 2 C(d))) clamped to
        [-0.5, 0.5]; inf where undecided.
    """
    return backend.subpixel(cost, disparity)


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
    h, w = disparity.shape
    v, u = np.nonzero(valid)
    d = disparity[v, u]
    xr = np.clip(np.rint(u - d).astype(np.int64), 0, w - 1)
    flat = v.astype(np.int64) * w + xr
    best = np.full(h * w, -np.inf)
    np.maximum.at(best, flat, d)
    occluded = np.zeros((h, w), bool)
    occluded[v, u] = d < best[flat] - tolerance
    return occluded


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
    h, w = disparity.shape
    start = min(int(max_disparity), w - 1)
    sub_valid = valid[:, start:]
    has = sub_valid.any(axis=1)
    first = np.argmax(sub_valid, axis=1) + start
    b = np.where(has, disparity[np.arange(h), first], -np.inf)[:, None]
    cols = np.arange(w)[None, :]
    return valid & (cols < b) & (disparity < b - 1)


def _nearest_along_rows(disp: np.ndarray, valid: np.ndarray):
    """Values of the nearest valid pixel to the left and to the right in each row (inf if none)."""
    h, w = disp.shape
    cols = np.broadcast_to(np.arange(w), (h, w))
    left_idx = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    right_idx = np.minimum.accumulate(np.where(valid, cols, w)[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(h)[:, None]
    left_val = np.where(left_idx >= 0, disp[rows, np.clip(left_idx, 0, w - 1)], np.inf)
    right_val = np.where(right_idx < w, disp[rows, np.clip(right_idx, 0, w - 1)], np.inf)
    return left_val, right_val


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
    disp = np.asarray(disparity, dtype=np.float32)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(disp)
    if not valid.any():
        return np.full(disp.shape, np.inf, np.float32)
    if valid.all():
        return disp.copy()
    left_val, right_val = _nearest_along_rows(disp, valid)
    fill_value = np.minimum(left_val, right_val)
    if occluded is not None:
        # Holes that are not occlusions (undecided: weak texture, rejected matches) lie
        # inside a surface: the median of the nearest valid values in the four directions
        # estimates it better than the background side.
        up_val, down_val = (x.T for x in _nearest_along_rows(disp.T, valid.T))
        four = np.stack([left_val, right_val, up_val, down_val])
        four = np.where(np.isfinite(four), four, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: no neighbour
            inside = np.nanmedian(four, axis=0)
        use_inside = ~occluded & np.isfinite(inside)
        fill_value = np.where(use_inside, inside, fill_value)
    filled = np.where(valid, disp, fill_value).astype(np.float32)
    empty_rows = ~valid.any(axis=1)
    if empty_rows.any():
        good = np.flatnonzero(~empty_rows)
        for r in np.flatnonzero(empty_rows):
            filled[r] = filled[good[np.argmin(np.abs(good - r))]]
    if smooth and min(disp.shape) >= 5:
        median = cv2.medianBlur(filled, 5)
        filled = np.where(valid, filled, median).astype(np.float32)
    return filled


# The piecewise-linear bilateral filter needs one pair of box filters per range level;
# beyond this many levels the level spacing grows instead (wide-range maps without a plane).
_MAX_RANGE_LEVELS = 256


def smooth_disparity(
    disparity: np.ndarray,
    valid: np.ndarray,
    *,
    radius: int,
    sigma: float,
    plane: np.ndarray | None = None,
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
    range levels ``sigma`` apart, per level two box filters (cv2.boxFilter), the result
    linearly interpolated between the two levels that bracket ``r_p``.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
        Disparity in pixels; non-finite = no estimate (stays as it is, never used).
    valid : ndarray, bool, (H, W)
        Pixels whose values may be averaged into others.
    radius : int, keyword-only
        Box radius in pixels (window ``2 radius + 1``); 0 returns a copy.
    sigma : float, keyword-only
        Range sigma in disparity pixels (> 0).
    plane : ndarray, float, (H, W), optional, keyword-only
        Reference disparity subtracted before and added after filtering (road model).

    Returns
    -------
    ndarray, float32, (H, W)
    """
    disp = np.asarray(disparity, dtype=np.float32)
    finite = np.isfinite(disp)
    use = np.asarray(valid, dtype=bool) & finite
    if radius <= 0 or not use.any():
        return disp.copy()
    base = np.zeros(disp.shape, np.float32) if plane is None else np.asarray(plane, dtype=np.float32)
    resid = np.where(finite, disp - base, 0.0).astype(np.float32)
    lo, hi = float(resid[finite].min()), float(resid[finite].max())
    step = max(float(sigma), (hi - lo) / (_MAX_RANGE_LEVELS - 1))
    n_levels = int(np.floor((hi - lo) / step)) + 2
    pos = (resid - lo) / step
    k0 = np.clip(np.floor(pos), 0, n_levels - 2).astype(np.int32)
    t = (pos - k0).astype(np.float32)
    weight0 = use.astype(np.float32)
    ksize = (2 * int(radius) + 1, 2 * int(radius) + 1)
    acc = np.zeros(disp.shape, np.float32)
    inv2s2 = 0.5 / float(sigma) ** 2
    for k in range(n_levels):
        lower, upper = k0 == k, k0 + 1 == k
        if not (lower.any() or upper.any()):
            continue  # no pixel interpolates from this level
        level = lo + k * step
        w = weight0 * np.exp(-inv2s2 * (resid - level) ** 2).astype(np.float32)
        num = cv2.boxFilter(w * resid, -1, ksize, normalize=False, borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(w, -1, ksize, normalize=False, borderType=cv2.BORDER_CONSTANT)
        est = np.where(den > 1e-6, num / np.maximum(den, 1e-6), resid)
        acc += np.where(lower, 1.0 - t, 0.0) * est + np.where(upper, t, 0.0) * est
    return np.where(finite, acc + base, disp).astype(np.float32)
