"""CPU driver of the decisive seeds (pipeline step 4: PKRN plus left-right check), and
the merge of fresh seeds into the inherited map where inheritance left holes.
The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops, unpack_volume
from ..intrinsics import prefetch_band, prefetch_cell
from ..pixel import UNDECIDED


_seed_candidate = ops.seed_candidate


_right_wta = ops.right_wta


# ----------------------------------------------------------------------------- seeds (step 4)
def decisive_seeds(cost, pkrn_min, epsilon, lr_tolerance, exclusion, skip=None):
    """Sparse seed map (docs/design.md, step 4); int32 (H, W), -1 undecided.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.decisive_seeds`.
    """
    flat, index, n_disp, _ = unpack_volume(cost)
    has_skip = skip is not None
    if not has_skip:
        skip = np.empty((1, 1), np.int32)
    return _seeds(flat, index, n_disp, float(pkrn_min), float(epsilon), int(lr_tolerance), int(exclusion),
                  skip, has_skip)


#: :func:`_seeds` prefetches the band of the examined pixel this many ahead, and its
#: index entry twice as far ahead (the band's address is read from it).
SEED_PREFETCH = 16


@njit(parallel=True, cache=True, error_model="numpy")
def _seeds(cost, index, n_disp, pkrn_min, epsilon, lr_tolerance, exclusion, skip, has_skip):
    """:func:`pixel.seed_at` for every pixel, row by row: first test (a) (the PKRN of the
    pixel's own band) for the row's pixels that ``skip`` leaves, then test (b), the right
    view's WTA at u - d1, for the candidates.  Where the candidates are many, (b) reads
    the row's right-view WTA from a table made in one pass over the row's cells
    (:func:`right_wta_row`) instead of scanning ``n_disp`` pixels per candidate; the
    same winners, so the same seeds.

    Test (a) runs over a list of the row's examined pixels and prefetches the band of the
    one :data:`SEED_PREFETCH` further: where inheritance decided many pixels, the bands
    left lie scattered and each waited its own cache misses.
    """
    h, w, _ = index.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        row = out[v]
        todo = np.empty(w, np.int32)  # the row's pixels to examine, in increasing u
        n = 0
        for u in range(w):
            row[u] = UNDECIDED
            todo[n] = u
            n += not (has_skip and skip[v, u] >= 0)
        n_cand = 0
        sparse = n < w  # a full row's bands are one stream: the hardware prefetches it
        for i in range(n):
            if sparse:
                if i + 2 * SEED_PREFETCH < n:
                    prefetch_cell(index, 3 * (v * w + todo[i + 2 * SEED_PREFETCH]))
                if i + SEED_PREFETCH < n:
                    prefetch_band(cost, index, v, todo[i + SEED_PREFETCH])
            u = todo[i]
            d1 = _seed_candidate(cost, index, v, u, pkrn_min, epsilon, exclusion)
            row[u] = d1
            n_cand += d1 != UNDECIDED
        if n_cand == 0:
            continue
        # the row's cells are packed (kernels.volume): its first and last pixel bound them
        n_cells = index[v, w - 1, 0] + index[v, w - 1, 2] - index[v, 0, 0] - index[v, 0, 1]
        if n_cand * n_disp > n_cells:  # the table reads each cell once: cheaper
            wta = right_wta_row(cost, index, v)
            for u in range(w):
                d1 = row[u]
                if d1 != UNDECIDED and abs(wta[u - d1] - d1) > lr_tolerance:
                    row[u] = UNDECIDED
        else:
            for u in range(w):
                d1 = row[u]
                if d1 != UNDECIDED and abs(_right_wta(cost, index, n_disp, v, u - d1) - d1) > lr_tolerance:
                    row[u] = UNDECIDED
    return out


@njit(cache=True, error_model="numpy")
def right_wta_row(cost, index, v):
    """:func:`pixel.right_wta` of every column x of row v: int32 (W,).

    One pass over the row's cells: cell (u, d) is a candidate of the right pixel x = u - d.
    Pixels are taken in increasing u, so each x sees its candidates in increasing d, and
    a strict ``<`` keeps the smallest d on ties, as ``right_wta``'s scan does; x without
    a cell gets 0, as there.  (The per-seed scan read up to ``n_disp`` pixels' index and
    cost per candidate seed.)
    """
    w = index.shape[1]
    best = np.full(w, np.inf, np.float32)
    wta = np.zeros(w, np.int32)
    for u in range(w):
        off = index[v, u, 0]
        lo = index[v, u, 1]
        end = min(index[v, u, 2], u + 1)  # x = u - d >= 0
        n = end - lo
        if n <= 0:
            continue
        # x = u - d runs backwards: reversed slices (non-negative indices: the loop vectorises)
        cells = cost[off + lo:off + end]
        best_x = best[u - end + 1:u - lo + 1]
        wta_x = wta[u - end + 1:u - lo + 1]
        for i in range(n):
            j = n - 1 - i
            c = cells[i]
            better = c < best_x[j]
            best_x[j] = c if better else best_x[j]
            wta_x[j] = lo + i if better else wta_x[j]
    return wta


# ----------------------------------------------------------------------------- merging seeds into a map
@njit(parallel=True, cache=True, error_model="numpy")
def merge_sparse(primary, fallback):
    """``primary`` where decided (>= 0), else ``fallback``; int32 (H, W), a new map."""
    h, w = primary.shape
    out = np.empty((h, w), np.int32)
    for v in prange(h):
        for u in range(w):
            out[v, u] = primary[v, u] if primary[v, u] >= 0 else fallback[v, u]
    return out


# ----------------------------------------------------------------------------- the decided pixels
def decided_mask(disparity):
    """``disparity >= 0``: bool (H, W), a new map."""
    return np.asarray(disparity) >= 0
