"""What every CPU driver shares: the per-pixel functions compiled with ``numba.njit``
(:data:`ops`, built once by :func:`d3cli.kernels.ops.build_ops`), the volume
unpack/pack of the drivers' arguments, and two index/image passes used by several steps.

Drivers are deterministic and independent of the thread count: parallel loops only write
disjoint cells, reductions run serially, iterative steps are double-buffered (Jacobi).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from .ops import build_ops
from .volume import Volume, dense_index


# error_model="numpy" (here and on every driver): a float division by zero gives inf/nan
# instead of raising, so numba emits no zero test per division and a loop with a
# division can vectorise.  Every division the kernels do has a non-zero divisor (a zero
# one would raise under numba's default "python" model), so the results are the same as
# under that model (scripts/bench_speed.py prints the disparity md5 per case to check it).
ops = build_ops(njit(cache=True, error_model="numpy"))



# ----------------------------------------------------------------------------- volumes
def unpack_volume(cost):
    """``(flat cost, index, n_disp, dense shape or None)`` of a Volume or an (H, W, D) array."""
    if isinstance(cost, Volume):
        return cost.cost, cost.index, int(cost.n_disp), None
    cost = np.ascontiguousarray(cost)
    h, w, n_disp = cost.shape
    return cost.reshape(-1), dense_index(h, w, n_disp), n_disp, cost.shape


def pack_volume(flat, index, n_disp, dense_shape):
    """The result in the caller's kind: a Volume, or an (H, W, D) array."""
    if dense_shape is not None:
        return flat.reshape(dense_shape)
    return Volume(flat, index, n_disp)


@njit(cache=True, error_model="numpy")
def on_grid(img, scale, least):
    """Whether every value of ``img`` lies in [least, 255] and is a multiple of 1 / scale.

    Row by row, branch-free within a row (vectorised), stopping after the first row that fails.
    """
    for v in range(img.shape[0]):
        row = img[v]
        bad = 0
        for u in range(img.shape[1]):
            g = np.float64(row[u]) * scale
            bad += not ((g >= least * scale) & (g <= 255 * scale) & (g == np.floor(g)))
        if bad:
            return False
    return True


@njit(parallel=True, cache=True, error_model="numpy")
def row_layout(index):
    """``(row_start, max_row)`` of a volume for the filter passes: the first cell of
    every row (int64 (H + 1,), cells packed row after row) and the most cells of a row
    (at least 1).  One parallel pass over the index instead of NumPy passes in the
    calling thread."""
    h, w, _ = index.shape
    row_start = np.zeros(h + 1, np.int64)
    for v in prange(h):
        total = 0
        for u in range(w):
            total += np.int64(index[v, u, 2]) - np.int64(index[v, u, 1])
        row_start[v + 1] = total
    max_row = 1
    for v in range(h):
        max_row = max(max_row, row_start[v + 1])
        row_start[v + 1] += row_start[v]
    return row_start, max_row
