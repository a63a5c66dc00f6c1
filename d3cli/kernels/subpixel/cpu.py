"""CPU driver of the sub-pixel refinement.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops, unpack_volume
from ..intrinsics import prefetch_cell


_subpixel_at = ops.subpixel_at


def subpixel(cost, disp, equiangular=False):
    """Sub-pixel refinement (docs/design.md, step 8): the parabola, or with ``equiangular``
    the equiangular line fit (``pixel.subpixel_at``); float32 (H, W), inf where undecided."""
    flat, index, _, _ = unpack_volume(cost)
    return _subpixel(flat, index, disp, bool(equiangular))


#: :func:`_subpixel` prefetches the cells of the pixel this many columns ahead.
SUBPIXEL_PREFETCH = 32


@njit(parallel=True, cache=True, error_model="numpy")
def _subpixel(cost, index, disp, equiangular):
    """:func:`pixel.subpixel_at` for every pixel, row by row.

    Each pixel reads the three cells around its disparity, one line of its band: with
    wide bands the lines a row needs lie apart and each waited its own cache miss, so the
    line of the pixel :data:`SUBPIXEL_PREFETCH` columns ahead is prefetched (an undecided
    or out-of-band disparity prefetches a line that is not needed; a prefetch never
    faults).
    """
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            if u + SUBPIXEL_PREFETCH < w:
                q = u + SUBPIXEL_PREFETCH
                prefetch_cell(cost, index[v, q, 0] + disp[v, q])
            out[v, u] = _subpixel_at(cost, index, disp, v, u, equiangular)
    return out
