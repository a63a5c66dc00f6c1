"""CUDA drivers of the perspective warp and restore.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, grid_2d, on_device, ops, per_pixel
from ..device_counts import DeviceCount, next_slot


_pt_shift = ops.pt_shift


_bilinear_at = ops.bilinear_at


_pt_restore_at = ops.pt_restore_at


_restore_drops = ops.restore_drops

_F32_INF = np.float32(np.inf)


# ----------------------------------------------------------------------------- perspective transformation (step 6)
@cuda.jit(cache=True)
def _pt_warp_kernel(right, a0, b1, b2, delta, out):
    x, v = cuda.grid(2)
    if v < right.shape[0] and x < right.shape[1]:
        out[v, x] = _bilinear_at(right, v, x - _pt_shift(a0, b1, b2, delta, v, x))


def pt_warp(right, a0, b1, b2, delta):
    """Right image warped by the road model (docs/design.md, step 6): ``R'(x, v) = R(x - s(x, v), v)``.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_warp`.
    """
    d_right = on_device(right)
    return per_pixel(_pt_warp_kernel, d_right.shape, np.float32, d_right, as_f64(a0), as_f64(b1), as_f64(b2), as_f64(delta))


@cuda.jit(cache=True)
def _pt_restore_kernel(disp, a0, b1, b2, delta, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = _pt_restore_at(disp[v, u], a0, b1, b2, delta, v, u)


def pt_restore(disp, a0, b1, b2, delta):
    """Full-range disparity from the disparity against the warped right image.

    ``d = d' (1 - b2) + s(u, v)`` (exact inverse of :func:`pt_warp`); inf stays inf.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_restore`.
    """
    d_disp = on_device(disp)
    return per_pixel(_pt_restore_kernel, d_disp.shape, np.float32, d_disp, as_f64(a0), as_f64(b1), as_f64(b2), as_f64(delta))


# ----------------------------------------------------------------------------- validity after the restore
@cuda.jit(cache=True)
def _pt_validity_kernel(narrow, restored, hi, kept, masked, c0, s0, c1, s1, c2, s2):
    u, v = cuda.grid(2)
    if v < narrow.shape[0] and u < narrow.shape[1]:
        d = narrow[v, u]
        valid = d >= 0
        r = restored[v, u]
        ends, outside, negative = _restore_drops(valid, d, r, np.float32(u), hi)
        keep = valid & (not (ends | outside | negative))
        kept[v, u] = keep
        masked[v, u] = r if keep else _F32_INF
        if ends:
            cuda.atomic.add(c0, s0, 1)
        if outside:
            cuda.atomic.add(c1, s1, 1)
        if negative & (not ends) & (not outside):
            cuda.atomic.add(c2, s2, 1)


def pt_validity(narrow, restored, narrow_range):
    """Validity after the restore of the perspective transformation and the masked map,
    on the device (the road model's rule, ``restore_drops``, at every pixel); the three
    counts left on the device.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_validity`.
    """
    d_narrow = on_device(narrow)
    d_restored = on_device(restored)
    # the type NumPy compares ``narrow >= narrow_range`` in (the CPU's rule)
    hi = np.result_type(d_narrow.dtype, narrow_range).type(narrow_range)
    h, w = d_narrow.shape
    kept = cuda.device_array((h, w), np.bool_)
    masked = cuda.device_array((h, w), np.float32)
    slots = [next_slot() for _ in range(3)]
    blocks, threads = grid_2d(w, h)
    _pt_validity_kernel[blocks, threads](d_narrow, d_restored, hi, kept, masked,
                                         *[x for pool, slot in slots for x in (pool.array, slot)])
    return kept, masked, [DeviceCount(pool, slot) for pool, slot in slots]


@cuda.jit(cache=True)
def _range_ends_kernel(narrow, hi, counts, slot):
    u, v = cuda.grid(2)
    if v < narrow.shape[0] and u < narrow.shape[1]:
        d = narrow[v, u]
        if d == 0 or d >= hi:
            cuda.atomic.add(counts, slot, 1)


def count_range_ends(narrow, narrow_range):
    """Pixels of a narrow-range integer map at ``d' == 0`` or ``d' >= narrow_range``, a
    count left on the device.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.count_range_ends`.
    """
    d_narrow = on_device(narrow)
    h, w = d_narrow.shape
    pool, slot = next_slot()
    blocks, threads = grid_2d(w, h)
    _range_ends_kernel[blocks, threads](d_narrow, np.result_type(d_narrow.dtype, narrow_range).type(narrow_range),
                                        pool.array, slot)
    return DeviceCount(pool, slot)
