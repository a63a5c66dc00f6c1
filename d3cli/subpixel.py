"""Step 8: sub-pixel refinement and hole filling."""

from __future__ import annotations

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


def fill_holes(disparity: np.ndarray, valid: np.ndarray, *, smooth: bool = True) -> np.ndarray:
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
    if valid.all() or not valid.any():
        return disp.copy()
    left_val, right_val = _nearest_along_rows(disp, valid)
    filled = np.where(valid, disp, np.minimum(left_val, right_val)).astype(np.float32)
    empty_rows = ~valid.any(axis=1)
    if empty_rows.any():
        good = np.flatnonzero(~empty_rows)
        for r in np.flatnonzero(empty_rows):
            filled[r] = filled[good[np.argmin(np.abs(good - r))]]
    if smooth and min(disp.shape) >= 5:
        median = cv2.medianBlur(filled, 5)
        filled = np.where(valid, filled, median).astype(np.float32)
    return filled
