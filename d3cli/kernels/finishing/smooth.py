"""The smoothing of a map, whole: the Gaussian range smoothing's driver and the backends'
``smooth_map`` on the CPU (docs/design.md, 'Finishing').

:func:`gaussian_smooth` runs the steps of :mod:`d3cli.kernels.finishing.smoothing` (the
residual and its range, the levels, their box-filtered groups, the blend); :func:`range_kernel_smooth`
picks the range kernel for every caller; :func:`smooth_map` is the contract's smoothing of a finished map
(:meth:`d3cli.kernels.backend.Backend.smooth_map`): every finite pixel used, the road
plane from its coefficients (:func:`shift_plane_f32`), the box (:mod:`range_box`) or the
Gaussian range kernel.
"""

from __future__ import annotations

import numpy as np

from .range_box import box_smooth_disparity
from .smoothing import (clamp_negative, combine_shares, range_levels, residual_and_range, shift_plane_f32,
                        smooth_groups)

#: The piecewise-linear bilateral filter needs one pair of box filters per range level;
#: beyond this many levels the level spacing grows instead (wide-range maps without a plane).
MAX_RANGE_LEVELS = 256


def unsmoothed(disp, non_negative):
    """A copy of the map, its negative values 0 with ``non_negative``."""
    out = disp.copy()
    return clamp_negative(out) if non_negative else out


def gaussian_smooth(disp, valid, base, radius, sigma, non_negative):
    """The Gaussian range smoothing of a map, radius > 0 (what
    :func:`d3cli.method.refinement.smooth_disparity` says): the residual and its range,
    the levels ``sigma`` apart (wider beyond :data:`MAX_RANGE_LEVELS`), their box-filtered
    groups and the blend of each pixel's shares.

    Parameters
    ----------
    disp, base : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), or None
        None: every finite pixel.
    radius : int (>= 1)
    sigma : float
    non_negative : bool

    Returns
    -------
    ndarray, float32, (H, W)
    """
    resid, use, row_lo, row_hi, row_use = residual_and_range(disp, base, valid)
    if not row_use.any():
        return unsmoothed(disp, non_negative)
    lo, hi = float(row_lo.min()), float(row_hi.max())
    step = max(float(sigma), (hi - lo) / (MAX_RANGE_LEVELS - 1))
    n_levels = int(np.floor((hi - lo) / step)) + 2
    # the shares of each pixel's lower and upper level: every cell is written, by
    # range_levels (0 where the residual is NaN) or by smooth_groups
    low = np.empty(disp.shape, np.float32)
    up = np.empty(disp.shape, np.float32)
    # NumPy float32 arithmetic with Python floats: the scalars act as float32
    used, row_lower = range_levels(resid, np.float32(lo), np.float32(step), n_levels, low, up)
    neg_inv2s2 = np.float32(-(0.5 / float(sigma) ** 2))
    levels = np.flatnonzero(used)  # levels no pixel interpolates from are skipped
    values = np.array([lo + int(k) * step for k in levels], np.float64).astype(np.float32)
    smooth_groups(resid, use, np.float32(lo), np.float32(step), n_levels, levels, values, row_lower, neg_inv2s2,
                  int(radius), low, up)
    return combine_shares(low, up, base, disp, non_negative)


def range_kernel_smooth(disp, valid, base, radius, sigma, kernel, non_negative):
    """The smoothing of a map with either range kernel, whatever the caller
    (:func:`d3cli.method.refinement.smooth_disparity`, :func:`smooth_map`): a copy for
    ``radius <= 0`` or an empty map, else the box (:func:`box_smooth_disparity`) or the
    Gaussian range kernel (:func:`gaussian_smooth`, a zero plane for ``base`` None).

    Parameters
    ----------
    disp : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), or None
        None: every finite pixel.
    base : ndarray, float32, (H, W), or None
        The plane subtracted before and added after the filter; None: none.
    radius : int
    sigma : float
    kernel : {"box", "gaussian"}
    non_negative : bool

    Raises
    ------
    ValueError
        ``kernel`` is neither (checked where the Gaussian would run).
    """
    if radius <= 0 or disp.size == 0:
        return unsmoothed(disp, non_negative)
    if kernel == "box":
        return box_smooth_disparity(disp, base, valid, int(radius), float(sigma), non_negative)
    if kernel != "gaussian":
        raise ValueError(f"smoothing kernel must be gaussian or box, got {kernel!r}")
    if base is None:
        base = np.zeros(disp.shape, np.float32)
    return gaussian_smooth(disp, valid, base, int(radius), float(sigma), non_negative)


def smooth_map(disparity, radius, sigma, kernel, plane, non_negative):
    """The backends' ``smooth_map`` on the CPU: the smoothing of a finished map, every finite
    pixel used, the road plane from its coefficients.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.smooth_map`.
    """
    disp = np.ascontiguousarray(disparity, dtype=np.float32)
    if kernel not in ("box", "gaussian"):  # the contract checks the name whatever the radius
        raise ValueError(f"smoothing kernel must be gaussian or box, got {kernel!r}")
    base = None
    if plane is not None and int(radius) > 0 and disp.size:
        base = shift_plane_f32(plane[0], plane[1], plane[2], 0.0, disp.shape)
    return range_kernel_smooth(disp, None, base, int(radius), float(sigma), kernel, non_negative)
