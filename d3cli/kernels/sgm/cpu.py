"""CPU driver of the semi-global smoothing of a banded volume (four paths, rows and
columns).  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import cache as _cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import _pack, _unpack
from ..intrinsics import _prefetch_cells
from .cpu_vector import _sgm_pixel


# ----------------------------------------------------------------------------- semi-global smoothing
def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs (left, right, down, up) of a volume.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.sgm_smooth`.
    """
    flat, index, n_disp, dense = _unpack(cost)
    # not zeroed in a pass of its own: the row paths write every cell of a band and zero
    # those between the bands (stored, not visible), so every cell is defined
    acc = np.empty_like(flat)
    p1, p2 = np.float32(p1), np.float32(p2)
    _sgm_rows(flat, index, n_disp, p1, p2, acc)
    _sgm_columns(flat, index, n_disp, p1, p2, acc)
    return _pack(acc, index, n_disp, dense)


#: Columns per task of the column paths: each task walks its columns down (then up) row
#: by row, so the cells it reads lie side by side (8, 16 and 64 measured the same on
#: KITTI; the first kernel walked one column at a time, a cache line per pixel).
SGM_COLUMNS = 32


#: The column paths prefetch the cells of the pixel this many rows ahead: each task's
#: rows lie apart in the volume, where the hardware's prefetcher does not follow (2 rows
#: measured best).
SGM_PREFETCH_ROWS = 2


@njit(parallel=True, cache=True)
def _sgm_rows(cost, index, n_disp, p1, p2, acc):
    for v in prange(index.shape[0]):
        _zero_gaps(index, v, acc)
        # two path buffers, inf outside the band (pixel.sgm_step's layout)
        a = np.full(n_disp + 2, np.inf, np.float32)
        b = np.full(n_disp + 2, np.inf, np.float32)
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, 1, 0)  # left to right: the first path stores
        a[:] = np.inf
        b[:] = np.inf
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, -1, 1)  # right to left


@njit(cache=True, inline="always")
def _zero_gaps(index, v, acc):
    """Zero the cells of ``acc`` in no band, from the end of row v - 1's last band to
    that of row v (the last row: to the end); bands packed in pixel order, row after row
    (:mod:`d3cli.kernels.volume`)."""
    h, w = index.shape[0], index.shape[1]
    end = np.int64(0)
    for r in range(v - 1, -1, -1):  # the cell after the last band above (an empty row: the one before)
        u = w - 1
        while u >= 0 and index[r, u, 2] <= index[r, u, 1]:
            u -= 1
        if u >= 0:
            end = np.int64(index[r, u, 0]) + index[r, u, 2]
            break
    for u in range(w):
        lo, hi = index[v, u, 1], index[v, u, 2]
        if hi > lo:
            start = np.int64(index[v, u, 0]) + lo
            for c in range(end, start):
                acc[c] = 0
            end = max(end, start + (hi - lo))
    if v == h - 1:
        for c in range(end, acc.shape[0]):
            acc[c] = 0


@njit(cache=True, inline="always")
def _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, step, mode):
    """One row path (``step`` 1 rightwards, -1 leftwards) along row v; ``a``, ``b`` the
    path buffers (all inf on entry)."""
    w = index.shape[1]
    plo, phi = 0, 0
    pm = np.float32(np.inf)
    for i in range(w):
        u = i if step > 0 else w - 1 - i
        pm = _sgm_pixel(cost, index, v, u, a, 0, plo, phi, pm, b, 0, p1, p2, acc, mode)
        plo, phi = index[v, u, 1], index[v, u, 2]
        a, b = b, a


@njit(parallel=True, cache=True)
def _sgm_columns(cost, index, n_disp, p1, p2, acc):
    w = index.shape[1]
    n_tasks = (w + SGM_COLUMNS - 1) // SGM_COLUMNS
    size = n_disp + 2
    for task in prange(n_tasks):
        u0 = task * SGM_COLUMNS
        u1 = min(w, u0 + SGM_COLUMNS)
        # per column two path buffers, column k's at k size of two arrays
        a = np.full(size * (u1 - u0), np.inf, np.float32)
        b = np.full(size * (u1 - u0), np.inf, np.float32)
        least = np.full(u1 - u0, np.inf, np.float32)  # per column the previous pixel's least path cost
        _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, 1, 1)  # down
        a[:] = np.inf
        b[:] = np.inf
        least[:] = np.inf
        _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, -1, 2)  # up: the last path scales


@njit(cache=True, inline="always")
def _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, step, mode):
    """One column path (``step`` 1 down, -1 up) over columns u0..u1, row by row; column
    k's two path buffers at ``k size`` of ``a`` and ``b`` (all inf on entry), its previous
    pixel's least path cost at ``least[k]`` (inf on entry)."""
    h = index.shape[0]
    for i in range(h):
        v = i if step > 0 else h - 1 - i
        ahead = v + step * SGM_PREFETCH_ROWS
        for u in range(u0, u1):
            if 0 <= ahead < h:
                _prefetch_pixel(cost, acc, index, ahead, u)
            plo, phi = (index[v - step, u, 1], index[v - step, u, 2]) if i > 0 else (0, 0)
            k = (u - u0) * size
            least[u - u0] = _sgm_pixel(cost, index, v, u, a, k, plo, phi, least[u - u0], b, k, p1, p2, acc, mode)
        a, b = b, a


@njit(cache=True, inline="always")
def _prefetch_pixel(cost, acc, index, v, u):
    """Prefetch the band of pixel (v, u) in the volume and in the sums."""
    c0 = index[v, u, 0] + index[v, u, 1]
    c1 = index[v, u, 0] + index[v, u, 2] - 1
    _prefetch_cells(cost, c0, c1)
    _prefetch_cells(acc, c0, c1)
