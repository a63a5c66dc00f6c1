"""Band search: which disparities a finer pyramid level computes (docs/design.md, 'Pyramid and bands').

The paper searches the full range at every level.  Below the coarsest level the coarser
map already says where the answer lies: a fine pixel whose coarse pixel decided ``dc``
needs about ``2 dc``.  Per tile of ``tile`` x ``tile`` pixels

    ``[2 min(dc) - margin, 2 max(dc) + margin]``

over the decided coarse pixels under the tile, or the full range where the coarser
level left the whole tile undecided; the tile searches the hull of that over itself and
the eight tiles around it.  Every later step sees exactly that *visible* band.

Why the ring of tiles: the coarse map misses thin structures (leaves, pipes, poles)
that its neighbourhood saw.  With each tile's own coarse values only (tile 32, margin
4) the Middlebury mean EPE is 1.690 against 1.583 at full range (jadeplant 7.64 against
6.06, pipes 2.65 against 1.84).  With the ring, margin 2: tile 16 1.593, tile 32 1.566, tile
64 1.547 (the band also keeps some wild outliers out).  Cells at full resolution, share
of the full range (Middlebury adirondack / a 1280x720 road pair at full range): tile 32
44 % / 17 %, tile 64 66 % / 27 % (tile 16 with margin 4: 38 % / 15 %).  Full range wherever any coarse pixel is undecided gives back
exactly 1.583 but leaves nearly every tile at the full range.  Defaults: tile 32,
margin 2.  Measured with ``scripts/benchmark.py DATA --family middlebury -c
middlebury --methods d3 --set pyramid.band_tile=... --set
pyramid.band_margin=...``.

Exactness.  Aggregation (RBF, ``t_max`` passes of a 3x3 kernel, or a plain bilateral
filter of radius ``kappa_a``) mixes a cell with the same disparity of neighbours up to
``halo`` pixels away.  So the volume *stores*, at each pixel, the hull of the visible
bands of every tile within ``halo`` pixels of it: every cell (p, d) of p's visible band
then has all its neighbours' cells (q, d) computed, and holds exactly the full-range
value (tests/method/test_band.py checks this against the full-range volume).  The
stored extra cells are scratch of the filter and are never read afterwards.

On the CPU the indexes are built by compiled loops (0.15 s as NumPy array code at
1280x720, a few ms compiled); the CUDA backend builds them on the device from the coarser
map it holds (``band_cuda.py``).  The band arithmetic is written once
(``band_pixel.py``) and compiled for both.  The pipeline reaches them through the backend
(``backend.band_indexes``); :func:`band_indexes` is also in :mod:`d3cli.kernels.host`.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..intrinsics import store_fence, store_nt
from ..pixel import UINT
from ..volume import MAX_CELLS
from .band_pixel import build

_px = build(njit(cache=True, error_model="numpy"))
_own_band = _px.own_band
_tiles_within = _px.tiles_within
_hull = _px.hull


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
        col_tx0[u], col_tx1[u] = _tiles_within(u, tile, halo, ntx)
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
            own_lo[ty, tx], own_hi[ty, tx] = _own_band(t_min[tx], t_max[tx], n_disp, margin)
    return own_lo, own_hi


@njit(cache=True, error_model="numpy")
def _neighbour_hulls(own_lo, own_hi):
    """Each tile's visible band: the hull over itself and the eight tiles around it."""
    nty, ntx = own_lo.shape
    t_lo = own_lo.copy()
    t_hi = own_hi.copy()
    for ty in range(nty):
        for tx in range(ntx):
            t_lo[ty, tx], t_hi[ty, tx] = _hull(own_lo, own_hi, max(ty - 1, 0), min(ty + 1, nty - 1),
                                               max(tx - 1, 0), min(tx + 1, ntx - 1), own_lo[ty, tx], own_hi[ty, tx])
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
        ty0, ty1 = _tiles_within(v, tile, halo, nty)
        ty = v // tile
        total = 0
        for k in range(n_seg):
            u = seg[k]
            tx = col_tx[u]
            s_lo, s_hi = _hull(t_lo, t_hi, ty0, ty1, col_tx0[u], col_tx1[u], t_lo[ty, tx], t_hi[ty, tx])
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
    cells packed pixel after pixel).  The visible bands with streaming stores (store_nt):
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
                store_nt(vf, UINT(3 * u), o)
                store_nt(vf, UINT(3 * u + 1), v_lo)
                store_nt(vf, UINT(3 * u + 2), v_hi)
            base += size * (u1 - u0)
        store_fence()
    return store, visible


def band_indexes(coarse, shape, *, n_disp: int, margin: int, tile: int, halo: int):
    """Indexes of the stored and of the visible volume of a finer level (host side, any backend).

    Per tile ``[2 min dc - margin, 2 max dc + margin]`` over the decided coarse pixels
    under it (the full range when none is); visible per pixel the hull of that over its
    tile and the eight around it; stored per pixel the hull of the visible bands of the
    tiles within ``halo`` (this module's docstring says why).

    Parameters
    ----------
    coarse : ndarray, int32, (Hc, Wc)
        Integer disparity map of the coarser level (-1 undecided), host array.
    shape : (int, int)
        ``(H, W)`` of the finer level.
    n_disp : int
        The finer level's range: disparities 0 .. n_disp - 1.
    margin : int
        Disparities added on each side of ``2 dc``.
    tile : int
        Tile size in fine pixels.
    halo : int
        Reach of the aggregation in pixels (RBF passes, or the bilateral radius).

    Returns
    -------
    store : ndarray, int32, (H, W, 3)
        ``[off, lo, hi]`` of the cells to compute and aggregate.
    visible : ndarray, int32, (H, W, 3)
        The same offsets with each pixel's own tile band: what the later steps read.
    n_cells : int
        Length of the flat cost array.

    Raises
    ------
    MemoryError
        When the volume would have more than :data:`~d3cli.kernels.volume.MAX_CELLS` cells.
    """
    coarse = np.ascontiguousarray(coarse, np.int32)
    h, w = (int(x) for x in shape)
    n_disp, margin, tile, halo = int(n_disp), int(margin), int(tile), int(halo)
    ch, cw = coarse.shape
    nty = (h + tile - 1) // tile
    ntx = (w + tile - 1) // tile
    col_cu, col_tx, col_tx0, col_tx1 = _column_tables(w, tile, halo, cw, ntx)
    own_lo, own_hi = _tile_bands(coarse, h, w, n_disp, margin, tile, nty, ntx, col_cu, col_tx)
    t_lo, t_hi = _neighbour_hulls(own_lo, own_hi)
    seg, n_seg = _column_runs(w, col_tx, col_tx0, col_tx1)
    seg_lo, seg_hi, row_cells = _stored_runs(h, tile, halo, nty, seg, n_seg, col_tx, col_tx0, col_tx1, t_lo, t_hi)
    store, visible = _write_indexes(h, w, tile, seg, n_seg, col_tx, t_lo, t_hi, seg_lo, seg_hi, row_cells)
    n_cells = int(row_cells[h])
    if n_cells > MAX_CELLS:
        raise MemoryError(f"a banded cost volume of {n_cells} cells has more than 2^31 cells")
    return store, visible, n_cells
