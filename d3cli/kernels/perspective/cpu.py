"""CPU drivers of the perspective transformation: the warp of the right image and
the restore of full-range disparities.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops


# ----------------------------------------------------------------------------- perspective transformation
_pt_shift = ops.pt_shift


_bilinear_at = ops.bilinear_at


_pt_restore_at = ops.pt_restore_at


@njit(parallel=True, cache=True, error_model="numpy")
def pt_warp(right, a0, b1, b2, delta):
    """Right image warped by the road model (docs/design.md, step 6): ``R'(x, v) = R(x - s(x, v), v)``.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_warp`.
    """
    h, w = right.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for x in range(w):
            out[v, x] = _bilinear_at(right, v, x - _pt_shift(a0, b1, b2, delta, v, x))
    return out


@njit(parallel=True, cache=True, error_model="numpy")
def pt_restore(disp, a0, b1, b2, delta):
    """Full-range disparity from the disparity against the warped right image.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.pt_restore`.
    """
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = _pt_restore_at(disp[v, u], a0, b1, b2, delta, v, u)
    return out
