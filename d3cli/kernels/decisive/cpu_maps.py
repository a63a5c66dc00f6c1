"""CPU drivers over decided maps: the least cost per pixel, the sub-pixel fit,
merging two maps and counting decided pixels.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import cache as _cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import _unpack, ops
from ..intrinsics import _prefetch


_band_min = ops.band_min


_subpixel_at = ops.subpixel_at


def min_cost(cost):
    """Least cost of every pixel over its band; float32 (H, W) (1 for an empty band)."""
    flat, index, _, _ = _unpack(cost)
    return _min_cost(flat, index)


@njit(parallel=True, cache=True, error_model="numpy")
def _min_cost(cost, index):
    h, w, _ = index.shape
    out = np.empty((h, w), np.float32)
    for v in prange(h):
        for u in range(w):
            # pixel.band_min, as the diffusion finds it for itself (CPU) and CUDA's min_cost
            out[v, u] = _band_min(cost, index, v, u) if index[v, u, 2] > index[v, u, 1] else np.float32(1.0)
    return out


# ----------------------------------------------------------------------------- sub-pixel (step 8)
def subpixel(cost, disp, equiangular=False):
    """Sub-pixel refinement (docs/design.md, step 8): the parabola, or with ``equiangular``
    the equiangular line fit (``pixel.subpixel_at``); float32 (H, W), inf where undecided."""
    flat, index, _, _ = _unpack(cost)
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
                _prefetch(cost, index[v, q, 0] + disp[v, q])
            out[v, u] = _subpixel_at(cost, index, disp, v, u, equiangular)
    return out


@njit(parallel=True, cache=True, error_model="numpy")
def merge_sparse(primary, fallback):
    """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new map."""
    h, w = primary.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = primary[v, u] if primary[v, u] >= 0 else fallback[v, u]
    return out


def count_decided(disparity) -> int:
    """Number of decided pixels (>= 0) of an integer disparity map."""
    return int(np.count_nonzero(np.asarray(disparity) >= 0))
