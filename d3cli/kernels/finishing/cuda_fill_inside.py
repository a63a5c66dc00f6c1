"""CUDA driver of the filling inside surfaces (``refine.fill_inside``: the filling of
``refinement.fill_holes`` with the occluded pixels), without its median: the column and row
bodies of the CPU (``pixel_fill_inside.py``, ``pixel_fill.py`` built with
``numba.cuda.jit(device=True)``), so the values are the CPU's.

Three launches: a thread per column (the nearest usable values above and below), a thread
per row (the usable pixels, the row's nearest values left and right, the fill), a thread
per row (rows without a usable pixel copy the nearest row that has one).  The 5x5 median of
the filled pixels: ``backend.median_of_holes``.  The contract:
:meth:`d3cli.kernels.backend.Backend.fill_inside`.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import grid_1d, on_device
from .pixel_fill import build as build_fill
from .pixel_fill_inside import build as build_inside

_inside = build_inside(cuda.jit(device=True))
_nearest_columns = _inside.nearest_columns
_fill_inside_row = _inside.fill_inside_row
_fill = build_fill(cuda.jit(device=True))
_usable_row = _fill.usable_row
_copy_nearest_row = _fill.copy_nearest_row


@cuda.jit(cache=True)
def _nearest_columns_kernel(disp, valid, up, down):
    u = cuda.grid(1)
    if u < disp.shape[1]:
        last = cuda.local.array(1, np.float32)
        _nearest_columns(disp, valid, up, down, u, u + 1, last)


@cuda.jit(cache=True)
def _fill_inside_kernel(disp, valid, occluded, up, down, use, out, left, right, row_has):
    y = cuda.grid(1)
    if y < disp.shape[0]:
        row_has[y] = _usable_row(disp, valid, use, y) > 0
        _fill_inside_row(disp, use, occluded, up, down, out, left[y], right[y], y)


@cuda.jit(cache=True)
def _copy_inside_rows_kernel(filled, row_has):
    y = cuda.grid(1)
    if y < filled.shape[0]:
        _copy_nearest_row(filled, row_has, y)


def fill_inside(disparity, valid, occluded):
    """The filling inside surfaces on the device (the CPU's ``usable``,
    ``nearest_along_columns``, ``fill_inside`` and ``copy_nearest_rows``).

    Returns
    -------
    filled : device array, float32, (H, W)
    use : device array, bool, (H, W)
        ``valid & isfinite(disparity)``: the pixels filled from.
    """
    d_disp, d_valid, d_occluded = on_device(disparity), on_device(valid), on_device(occluded)
    h, w = d_disp.shape
    use = cuda.device_array((h, w), np.bool_)
    filled = cuda.device_array((h, w), np.float32)
    up = cuda.device_array((h, w), np.float32)
    down = cuda.device_array((h, w), np.float32)
    # each row's own buffers of its nearest values left and right
    left = cuda.device_array((h, max(w, 1)), np.float32)
    right = cuda.device_array((h, max(w, 1)), np.float32)
    row_has = cuda.device_array(max(h, 1), np.bool_)
    blocks, threads = grid_1d(w)
    _nearest_columns_kernel[blocks, threads](d_disp, d_valid, up, down)
    blocks, threads = grid_1d(h)
    _fill_inside_kernel[blocks, threads](d_disp, d_valid, d_occluded, up, down, use, filled, left, right, row_has)
    _copy_inside_rows_kernel[blocks, threads](filled, row_has)
    return filled, use
