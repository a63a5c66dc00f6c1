"""CUDA driver of the sub-pixel refinement.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import on_device, ops, per_pixel, unpack_volume


_subpixel_at = ops.subpixel_at


@cuda.jit(cache=True)
def _subpixel_kernel(cost, index, disp, equiangular, out):
    u, v = cuda.grid(2)
    if v < disp.shape[0] and u < disp.shape[1]:
        out[v, u] = _subpixel_at(cost, index, disp, v, u, equiangular)


def subpixel(cost, disp, equiangular=False):
    """Sub-pixel refinement (docs/design.md, step 8): the parabola, or with ``equiangular``
    the equiangular line fit (``pixel.subpixel_at``); float32 (H, W), inf where undecided."""
    d_disp = on_device(disp)
    flat, index, _, _ = unpack_volume(cost)
    return per_pixel(_subpixel_kernel, d_disp.shape, np.float32, flat, index, d_disp, bool(equiangular))
