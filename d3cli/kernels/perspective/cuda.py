"""CUDA drivers of the perspective warp and restore.  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, on_device, ops, per_pixel


_pt_shift = ops.pt_shift


_bilinear_at = ops.bilinear_at


_pt_restore_at = ops.pt_restore_at


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
