"""CUDA drivers of the finishing's row-wise steps: one thread per row, the row bodies of
the CPU (``pixel_occlusion.py``, ``pixel_fill.py`` built with
``numba.cuda.jit(device=True)``), so integer, bool and float results are the CPU's.  Results stay on the device; counts are left in a slot of
a device pool (:mod:`d3cli.kernels.device_counts`).  The contract:
:mod:`d3cli.kernels.backend`.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import grid_1d, grid_2d, is_device, on_device
from ..device_counts import DeviceCount, next_slot
from .pixel_fill import build as build_fill
from .pixel_occlusion import build as build_occlusion

_rows = build_occlusion(cuda.jit(device=True))
_uniqueness_row = _rows.uniqueness_row
_out_of_view_row = _rows.out_of_view_row
_drop_occluded_row = _rows.drop_occluded_row
_fill = build_fill(cuda.jit(device=True))
_usable_row = _fill.usable_row
_fill_row = _fill.fill_row
_copy_nearest_row = _fill.copy_nearest_row
_median5_at = _fill.median5_at


@cuda.jit(cache=True)
def _uniqueness_kernel(disparity, valid, tolerance, best, target, out):
    y = cuda.grid(1)
    if y < disparity.shape[0]:
        _uniqueness_row(disparity, valid, tolerance, y, best[y], target[y], out)


@cuda.jit(cache=True)
def _out_of_view_kernel(disparity, valid, start, out):
    y = cuda.grid(1)
    if y < disparity.shape[0]:
        _out_of_view_row(disparity, valid, start, y, out)


@cuda.jit(cache=True)
def _drop_occluded_kernel(disparity, valid, tolerance, start, best, target, out, occluded, counts, slot):
    y = cuda.grid(1)
    if y < disparity.shape[0]:
        n = _drop_occluded_row(disparity, valid, tolerance, start, y, best[y], target[y], out, occluded)
        if n:
            cuda.atomic.add(counts, slot, n)


def _row_buffers(h, w):
    """The rows' own buffers of the uniqueness test: the largest claim of each right column
    (float64) and each pixel's right column (int64), 12 bytes a pixel on the device."""
    return cuda.device_array((h, max(w, 1)), np.float64), cuda.device_array((h, max(w, 1)), np.int64)


def uniqueness_occluded(disparity, valid, tolerance):
    """:func:`d3cli.kernels.finishing.uniqueness_occluded` on the device: bool (H, W)."""
    d_disp, d_valid = on_device(disparity), on_device(valid)
    h, w = d_disp.shape
    out = cuda.device_array((h, w), np.bool_)
    best, target = _row_buffers(h, w)
    blocks, threads = grid_1d(h)
    _uniqueness_kernel[blocks, threads](d_disp, d_valid, np.float64(tolerance), best, target, out)
    return out


def out_of_view_mask(disparity, valid, start):
    """:func:`d3cli.kernels.finishing.out_of_view_mask` on the device: bool (H, W)."""
    d_disp, d_valid = on_device(disparity), on_device(valid)
    h, w = d_disp.shape
    out = cuda.device_array((h, w), np.bool_)
    blocks, threads = grid_1d(h)
    _out_of_view_kernel[blocks, threads](d_disp, d_valid, np.int64(start), out)
    return out


def drop_occluded(disparity, valid, tolerance, start, out):
    """Both occlusion tests, their holes and the masked map, one thread per row
    (:func:`d3cli.kernels.finishing.drop_occluded`): ``valid`` updated in place (a host map
    through an upload and a download), ``out`` (a device map; may be ``disparity``) masked.

    Returns
    -------
    occluded : device array, bool, (H, W)
    count : DeviceCount
        Occluded pixels, left on the device.
    """
    d_disp = on_device(disparity)
    d_valid = on_device(valid)
    h, w = d_disp.shape
    occluded = cuda.device_array((h, w), np.bool_)
    best, target = _row_buffers(h, w)
    pool, slot = next_slot()
    blocks, threads = grid_1d(h)
    _drop_occluded_kernel[blocks, threads](d_disp, d_valid, np.float64(tolerance), np.int64(start), best, target,
                                           out, occluded, pool.array, slot)
    if not is_device(valid):  # a host map: updated in place as the contract says
        d_valid.copy_to_host(valid)
    return occluded, DeviceCount(pool, slot)


@cuda.jit(cache=True)
def _fill_rows_kernel(disp, valid, use, filled, row_has):
    y = cuda.grid(1)
    if y < disp.shape[0]:
        _usable_row(disp, valid, use, y)
        row_has[y] = _fill_row(disp, use, filled, y)


@cuda.jit(cache=True)
def _copy_rows_kernel(filled, row_has):
    y = cuda.grid(1)
    if y < filled.shape[0]:
        _copy_nearest_row(filled, row_has, y)


@cuda.jit(cache=True)
def _median_holes_kernel(filled, use, out):
    u, y = cuda.grid(2)
    if y < filled.shape[0] and u < filled.shape[1]:
        if use[y, u]:
            out[y, u] = filled[y, u]
        else:
            buf = cuda.local.array(25, np.float32)
            out[y, u] = _median5_at(filled, y, u, buf)


def fill_rows(disparity, valid):
    """The row-wise hole filling on the device (the CPU's ``usable``,
    ``fill_rows_smaller_side`` and ``copy_nearest_rows``): two launches, a thread per row.

    Returns
    -------
    filled : device array, float32, (H, W)
    use : device array, bool, (H, W)
        ``valid & isfinite(disparity)``: the pixels filled from.
    """
    d_disp, d_valid = on_device(disparity), on_device(valid)
    h, w = d_disp.shape
    use = cuda.device_array((h, w), np.bool_)
    filled = cuda.device_array((h, w), np.float32)
    row_has = cuda.device_array(max(h, 1), np.bool_)
    blocks, threads = grid_1d(h)
    _fill_rows_kernel[blocks, threads](d_disp, d_valid, use, filled, row_has)
    _copy_rows_kernel[blocks, threads](filled, row_has)
    return filled, use


def median_of_holes(filled, use):
    """``filled`` where ``use``, else the median of its 5x5 window (borders replicated: the
    values of ``cv2.medianBlur(filled, 5)`` on a map without NaN); a new device map, a
    thread per pixel."""
    d_filled, d_use = on_device(filled), on_device(use)
    h, w = d_filled.shape
    out = cuda.device_array((h, w), np.float32)
    blocks, threads = grid_2d(w, h)
    _median_holes_kernel[blocks, threads](d_filled, d_use, out)
    return out
