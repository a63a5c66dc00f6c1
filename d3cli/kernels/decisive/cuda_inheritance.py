"""CUDA driver of the inter-scale decisive inheritance (pipeline step 7: paper Algorithm 2,
eq. 6-8), one thread per 2x2 patch.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import as_f64, grid_2d, on_device, ops, unpack_volume


_inherit_patch_into = ops.inherit_patch_into


@cuda.jit(cache=True)
def _inherit_kernel(cost, index, coarse, prc, dfm_pkrn_min, epsilon, candidates, out):
    """One thread per 2x2 patch: the patch tests once for its four fine pixels."""
    pu, pv = cuda.grid(2)
    if 2 * pv < index.shape[0] and 2 * pu < index.shape[1]:
        _inherit_patch_into(out, cost, index, coarse, pv, pu, prc, dfm_pkrn_min, epsilon, candidates)


def inherit(cost, coarse, prc, dfm_pkrn_min, epsilon, candidates=0):
    """Inter-scale decisive inheritance (paper Algorithm 2, eq. 6-8).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.inherit`.
    """
    flat, index, _, _ = unpack_volume(cost)
    h, w = int(index.shape[0]), int(index.shape[1])
    out = cuda.device_array((h, w), np.int32)
    blocks, threads = grid_2d((w + 1) // 2, (h + 1) // 2)
    _inherit_kernel[blocks, threads](flat, index, on_device(coarse), bool(prc), as_f64(dfm_pkrn_min), as_f64(epsilon),
                                     np.int32(candidates), out)
    return out
