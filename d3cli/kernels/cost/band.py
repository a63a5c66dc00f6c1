"""Host-side construction of a finer level's banded index (any backend): the rules
of :mod:`d3cli.method.band`, compiled."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import cache as _cache  # noqa: F401  (chooses the numba cache folder first)
from ..intrinsics import _store_fence, _store_nt
from ..pixel import UINT


# ----------------------------------------------------------------------------- band search
# The construction in phases, each one compiled loop; band_indexes (plain Python) runs them
# in turn.  Integer arithmetic only: the phases give the same indexes as one loop nest.
@njit(cache=True, error_model="numpy")
def _column_tables(w, tile, halo, cw, ntx):
    """Per column, once (no integer divisions per pixel): the coarse column, the tile
    column and the first and last tile columns within the halo."""
    col_cu = np.empty(w, np.int64)
    col_tx = np.empty(w, np.int64)
    col_tx0 = np.empty(w, np.int64)
    col_tx1 = np.empty(w, np.int64)
    for u in range(w):
        col_cu[u] = min(u // 2, cw - 1)
        col_tx[u] = u // tile
        col_tx0[u] = min(max((u - halo) // tile, 0), ntx - 1)
        col_tx1[u] = min(max((u + halo) // tile, 0), ntx - 1)
    return col_cu, col_tx, col_tx0, col_tx1


@njit(parallel=True, cache=True, error_model="numpy")
def _tile_bands(coarse, h, w, n_disp, margin, tile, nty, ntx, col_cu, col_tx):
    """Each tile's own band ``[2 min dc - margin, 2 max dc + margin]`` over the decided
    coarse pixels under it (the full range when none is)."""
    ch = coarse.shape[0]
    own_lo = np.zeros((nty, ntx), np.int64)
    own_hi = np.full((nty, ntx), n_disp, np.int64)
    for ty in prange(nty):  # one tile row per task: no two tasks touch a tile
        t_min = np.full(ntx, np.iinfo(np.int64).max, np.int64)
        t_max = np.full(ntx, -1, np.int64)
        last_cv = -1
        for v in range(ty * tile, min(h, ty * tile + tile)):
            cv = min(v // 2, ch - 1)
            if cv == last_cv:
                continue  # the row before read the same coarse row into the same tiles
            last_cv = cv
            last_cu = -1
            last_tx = -1
            for u in range(w):
                cu = col_cu[u]
                tx = col_tx[u]
                if cu == last_cu and tx == last_tx:
                    continue  # the same coarse pixel into the same tile: min/max unchanged
                last_cu = cu
                last_tx = tx
                dc = np.int64(coarse[cv, cu])
                if dc >= 0:
                    t_min[tx] = min(t_min[tx], dc)
                    t_max[tx] = max(t_max[tx], dc)
        for tx in range(ntx):
            if t_max[tx] >= 0:
                lo = min(max(2 * t_min[tx] - margin, 0), n_disp - 1)
                hi = min(max(2 * t_max[tx] + margin + 1, 1), n_disp)
                own_lo[ty, tx] = lo
                own_hi[ty, tx] = max(hi, lo + 1)
    return own_lo, own_hi


@njit(cache=True, error_model="numpy")
def _neighbour_hulls(own_lo, own_hi):
    """Each tile's visible band: the hull over itself and the eight tiles around it."""
    nty, ntx = own_lo.shape
    t_lo = own_lo.copy()
    t_hi = own_hi.copy()
    for ty in range(nty):
        for tx in range(ntx):
            for yy in range(max(ty - 1, 0), min(ty + 1, nty - 1) + 1):
                for xx in range(max(tx - 1, 0), min(tx + 1, ntx - 1) + 1):
                    t_lo[ty, tx] = min(t_lo[ty, tx], own_lo[yy, xx])
                    t_hi[ty, tx] = max(t_hi[ty, tx], own_hi[yy, xx])
    return t_lo, t_hi


@njit(cache=True, error_model="numpy")
def _column_runs(w, col_tx, col_tx0, col_tx1):
    """Runs of columns with the same tiles (own and within the halo), which have the same
    bands in a row: run k is columns seg[k] .. seg[k + 1] - 1; (seg, n_seg)."""
    seg = np.empty(w + 1, np.int64)
    n_seg = 0
    for u in range(w):
        if u == 0 or col_tx0[u] != col_tx0[u - 1] or col_tx1[u] != col_tx1[u - 1] or col_tx[u] != col_tx[u - 1]:
            seg[n_seg] = u
            n_seg += 1
    seg[n_seg] = w
    return seg, n_seg


@njit(parallel=True, cache=True, error_model="numpy")
def _stored_runs(h, tile, halo, nty, seg, n_seg, col_tx, col_tx0, col_tx1, t_lo, t_hi):
    """Per row the stored band of each run (the hull of the visible bands of the tiles
    within ``halo``) and the cells of the rows before it (prefix sums, row_cells[h] the
    total)."""
    seg_lo = np.empty((h, n_seg), np.int64)
    seg_hi = np.empty((h, n_seg), np.int64)
    row_cells = np.zeros(h + 1, np.int64)
    for v in prange(h):
        ty0 = min(max((v - halo) // tile, 0), nty - 1)
        ty1 = min(max((v + halo) // tile, 0), nty - 1)
        ty = v // tile
        total = 0
        for k in range(n_seg):
            u = seg[k]
            tx = col_tx[u]
            s_lo = t_lo[ty, tx]
            s_hi = t_hi[ty, tx]
            for yy in range(ty0, ty1 + 1):
                for xx in range(col_tx0[u], col_tx1[u] + 1):
                    s_lo = min(s_lo, t_lo[yy, xx])
                    s_hi = max(s_hi, t_hi[yy, xx])
            seg_lo[v, k] = s_lo
            seg_hi[v, k] = s_hi
            total += (s_hi - s_lo) * (seg[k + 1] - u)
        row_cells[v + 1] = total
    for v in range(h):
        row_cells[v + 1] += row_cells[v]
    return seg_lo, seg_hi, row_cells


@njit(parallel=True, cache=True, error_model="numpy")
def _write_indexes(h, w, tile, seg, n_seg, col_tx, t_lo, t_hi, seg_lo, seg_hi, row_cells):
    """The stored and visible indexes, the bands and offsets written once per pixel (the
    cells packed pixel after pixel).  The visible bands with streaming stores (_store_nt):
    they are read only after the level's cost and aggregation, which evict them anyway; the
    stored ones go to the NCC next, from the caches."""
    store = np.empty((h, w, 3), np.int32)
    visible = np.empty((h, w, 3), np.int32)
    for v in prange(h):
        ty = v // tile
        base = row_cells[v]
        sv = store[v]
        vf = visible[v].reshape(-1)
        for k in range(n_seg):
            u0 = seg[k]
            u1 = seg[k + 1]
            s_lo = seg_lo[v, k]
            s_hi = seg_hi[v, k]
            tx = col_tx[u0]
            v_lo = t_lo[ty, tx]
            v_hi = t_hi[ty, tx]
            size = s_hi - s_lo
            off = base - s_lo - u0 * size  # pixel u's offset: off + u size
            for u in range(u0, u1):
                o = off + u * size
                sv[u, 0] = o
                sv[u, 1] = s_lo
                sv[u, 2] = s_hi
                _store_nt(vf, UINT(3 * u), o)
                _store_nt(vf, UINT(3 * u + 1), v_lo)
                _store_nt(vf, UINT(3 * u + 2), v_hi)
            base += size * (u1 - u0)
        _store_fence()
    return store, visible


def band_indexes(coarse, h, w, n_disp, margin, tile, halo):
    """Stored and visible indexes of a finer level's banded volume (host side, any backend).

    The rules are those of :mod:`d3cli.method.band` (its docstring explains them; its
    tests hold a NumPy reference): per tile ``[2 min dc - margin, 2 max dc + margin]``
    over the decided coarse pixels under it (the full range when none is); visible per
    pixel the hull of that over its tile and the eight around it; stored per pixel the
    hull of the visible bands of the tiles within ``halo``.

    Returns
    -------
    store, visible : ndarray, int32, (h, w, 3)
    n_cells : int
    """
    ch, cw = coarse.shape
    nty = (h + tile - 1) // tile
    ntx = (w + tile - 1) // tile
    col_cu, col_tx, col_tx0, col_tx1 = _column_tables(w, tile, halo, cw, ntx)
    own_lo, own_hi = _tile_bands(coarse, h, w, n_disp, margin, tile, nty, ntx, col_cu, col_tx)
    t_lo, t_hi = _neighbour_hulls(own_lo, own_hi)
    seg, n_seg = _column_runs(w, col_tx, col_tx0, col_tx1)
    seg_lo, seg_hi, row_cells = _stored_runs(h, tile, halo, nty, seg, n_seg, col_tx, col_tx0, col_tx1, t_lo, t_hi)
    store, visible = _write_indexes(h, w, tile, seg, n_seg, col_tx, t_lo, t_hi, seg_lo, seg_hi, row_cells)
    return store, visible, int(row_cells[h])
