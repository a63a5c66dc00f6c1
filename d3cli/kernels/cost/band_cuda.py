"""CUDA driver of the band search: the indexes of a finer level built on the device from
the coarser map the device holds (``band.py`` says what the bands are; ``band_pixel.py``
holds the arithmetic both targets compile).

Six launches per level: each tile's own band (one thread per tile), the hull over the
tile and its eight neighbours (per tile), each pixel's stored and visible band (per
pixel), the cells of each row (per row, a running sum along it), the rows' prefix sums (one
thread; it also writes the number of cells into a device count) and each pixel's offset
(per pixel).  The indexes are those of :func:`d3cli.kernels.cost.band.band_indexes`, equal
element for element.

The number of cells stays on the device (a :class:`~d3cli.kernels.device_counts.DeviceCount`,
read with the level's other counts): the cost driver allocates the flat volume at the
level's full-range size (``h * w * n_disp`` cells, :data:`CELLS_BOUND` on the index), so
no copy to the host is needed to size it.  The band saves computation and traffic on
the device, not allocation.  Where the full-range size exceeds
:data:`~d3cli.kernels.volume.MAX_CELLS` the count is read (one small copy) and the volume
allocated at it.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from ..cuda_launch import grid_1d, grid_2d, on_device
from ..device_counts import DeviceCount, next_slot
from ..volume import MAX_CELLS
from .band_pixel import build

_px = build(cuda.jit(device=True))
_own_band = _px.own_band
_tiles_within = _px.tiles_within
_hull = _px.hull

#: Attribute of a device store index: the number of cells to allocate for its volume.
CELLS_BOUND = "d3_cells_bound"

_NO_MIN = np.iinfo(np.int64).max


@cuda.jit(cache=True)
def _tile_bands(coarse, h, w, n_disp, margin, tile, own_lo, own_hi):
    tx, ty = cuda.grid(2)
    if ty < own_lo.shape[0] and tx < own_lo.shape[1]:
        ch = coarse.shape[0]
        cw = coarse.shape[1]
        t_min = _NO_MIN
        t_max = np.int64(-1)
        for v in range(ty * tile, min(h, ty * tile + tile)):
            cv = min(v // 2, ch - 1)
            for u in range(tx * tile, min(w, tx * tile + tile)):
                dc = np.int64(coarse[cv, min(u // 2, cw - 1)])
                if dc >= 0:
                    t_min = min(t_min, dc)
                    t_max = max(t_max, dc)
        lo, hi = _own_band(t_min, t_max, n_disp, margin)
        own_lo[ty, tx] = lo
        own_hi[ty, tx] = hi


@cuda.jit(cache=True)
def _neighbour_hulls(own_lo, own_hi, t_lo, t_hi):
    tx, ty = cuda.grid(2)
    nty, ntx = own_lo.shape
    if ty < nty and tx < ntx:
        lo, hi = _hull(own_lo, own_hi, max(ty - 1, 0), min(ty + 1, nty - 1), max(tx - 1, 0), min(tx + 1, ntx - 1),
                       own_lo[ty, tx], own_hi[ty, tx])
        t_lo[ty, tx] = lo
        t_hi[ty, tx] = hi


@cuda.jit(cache=True)
def _pixel_bands(tile, halo, t_lo, t_hi, store, visible):
    u, v = cuda.grid(2)
    if v < store.shape[0] and u < store.shape[1]:
        nty, ntx = t_lo.shape
        ty0, ty1 = _tiles_within(v, tile, halo, nty)
        tx0, tx1 = _tiles_within(u, tile, halo, ntx)
        ty = v // tile
        tx = u // tile
        lo, hi = _hull(t_lo, t_hi, ty0, ty1, tx0, tx1, t_lo[ty, tx], t_hi[ty, tx])
        store[v, u, 1] = lo
        store[v, u, 2] = hi
        visible[v, u, 1] = t_lo[ty, tx]
        visible[v, u, 2] = t_hi[ty, tx]


@cuda.jit(cache=True)
def _row_cells(store, row_cells):
    v = cuda.grid(1)
    if v < store.shape[0]:
        total = np.int64(0)
        for u in range(store.shape[1]):
            lo = store[v, u, 1]
            store[v, u, 0] = total - lo  # the row's own part of the offset
            total += store[v, u, 2] - lo
        row_cells[v + 1] = total


@cuda.jit(cache=True)
def _row_prefix(row_cells, counts, slot):
    if cuda.grid(1) == 0:
        row_cells[0] = 0
        for v in range(1, row_cells.shape[0]):
            row_cells[v] += row_cells[v - 1]
        counts[slot] = row_cells[row_cells.shape[0] - 1]


@cuda.jit(cache=True)
def _offsets(row_cells, store, visible):
    u, v = cuda.grid(2)
    if v < store.shape[0] and u < store.shape[1]:
        off = row_cells[v] + store[v, u, 0]
        store[v, u, 0] = off
        visible[v, u, 0] = off


def band_indexes(coarse, shape, *, n_disp, margin, tile, halo):
    """Indexes of the stored and of the visible volume of a finer level, built on the device.

    Returns ``(store, visible, n_cells)``: int32 (H, W, 3) device arrays and the number of
    cells as a device count (``int()`` reads it).  ``store`` carries the cells to allocate
    (:data:`CELLS_BOUND`).
    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.band_indexes`.
    """
    d_coarse = on_device(np.ascontiguousarray(coarse, np.int32) if isinstance(coarse, np.ndarray) else coarse)
    h, w = (int(x) for x in shape)
    n_disp, margin, tile, halo = int(n_disp), int(margin), int(tile), int(halo)
    nty = (h + tile - 1) // tile
    ntx = (w + tile - 1) // tile
    own_lo = cuda.device_array((nty, ntx), np.int64)
    own_hi = cuda.device_array((nty, ntx), np.int64)
    blocks, threads = grid_2d(ntx, nty)
    _tile_bands[blocks, threads](d_coarse, np.int64(h), np.int64(w), np.int64(n_disp), np.int64(margin),
                                 np.int64(tile), own_lo, own_hi)
    t_lo = cuda.device_array((nty, ntx), np.int64)
    t_hi = cuda.device_array((nty, ntx), np.int64)
    _neighbour_hulls[blocks, threads](own_lo, own_hi, t_lo, t_hi)
    store = cuda.device_array((h, w, 3), np.int32)
    visible = cuda.device_array((h, w, 3), np.int32)
    blocks, threads = grid_2d(w, h)
    _pixel_bands[blocks, threads](np.int64(tile), np.int64(halo), t_lo, t_hi, store, visible)
    row_cells = cuda.device_array(h + 1, np.int64)
    blocks1, threads1 = grid_1d(h)
    _row_cells[blocks1, threads1](store, row_cells)
    pool, slot = next_slot()
    _row_prefix[1, 1](row_cells, pool.array, slot)
    _offsets[blocks, threads](row_cells, store, visible)
    n_cells = DeviceCount(pool, slot)
    bound = h * w * n_disp
    if bound > MAX_CELLS:
        bound = int(n_cells)  # one small copy: the full-range size is no bound to allocate
        if bound > MAX_CELLS:
            raise MemoryError(f"a banded cost volume of {bound} cells has more than 2^31 cells")
    setattr(store, CELLS_BOUND, bound)
    return store, visible, n_cells
