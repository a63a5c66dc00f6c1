"""CUDA drivers of the finishing's row-wise steps: one thread per row, the row bodies of
the CPU (``pixel_occlusion.py`` built with ``numba.cuda.jit(device=True)``), so integer
and bool results are the CPU's.  Results stay on the device; counts are left in a slot of
a device pool (:mod:`d3cli.kernels.device_counts`).  The contract:
:mod:`d3cli.kernels.backend`.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import grid_1d, is_device, on_device
from ..device_counts import DeviceCount, next_slot
from .pixel_occlusion import build as build_rows

_rows = build_rows(cuda.jit(device=True))
_uniqueness_row = _rows.uniqueness_row
_out_of_view_row = _rows.out_of_view_row
_drop_occluded_row = _rows.drop_occluded_row


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


def drop_occluded(disparity, valid, tolerance, start, out=None):
    """Both occlusion tests, their holes and the masked map, one thread per row
    (:func:`d3cli.kernels.finishing.drop_occluded`): ``valid`` updated in place (a host
    map through an upload and a download), ``out`` (a new device map when None; may be ``disparity``) masked.

    Returns
    -------
    occluded : device array, bool, (H, W)
    count : DeviceCount
        Occluded pixels, left on the device.
    out : device array, float32, (H, W)
    """
    d_disp = on_device(disparity)
    d_valid = on_device(valid)
    h, w = d_disp.shape
    if out is None:
        out = cuda.device_array((h, w), np.float32)
    occluded = cuda.device_array((h, w), np.bool_)
    best, target = _row_buffers(h, w)
    pool, slot = next_slot()
    blocks, threads = grid_1d(h)
    _drop_occluded_kernel[blocks, threads](d_disp, d_valid, np.float64(tolerance), np.int64(start), best, target,
                                           out, occluded, pool.array, slot)
    if not is_device(valid):  # a host map: updated in place as the contract says
        d_valid.copy_to_host(valid)
    return occluded, DeviceCount(pool, slot), out
