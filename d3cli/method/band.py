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

The indexes are built on the host by one compiled loop (``kernels.cpu.band_indexes``,
0.15 s as NumPy array code at 1280x720, a few ms compiled) and uploaded for CUDA.
"""

from __future__ import annotations

import numpy as np

from ..kernels.volume import MAX_CELLS


def band_indexes(coarse, shape: tuple[int, int], *, n_disp: int, margin: int, tile: int, halo: int):
    """Indexes of the stored and of the visible volume of a finer level.

    Parameters
    ----------
    coarse : ndarray, int32, (Hc, Wc)
        Integer disparity map of the coarser level (-1 undecided), host array.
    shape : (int, int)
        (H, W) of the finer level; fine pixel (u, v) lies under coarse (u // 2, v // 2)
        (clamped to the coarse map).
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
    """
    from ..kernels import cpu  # host-side construction for every backend

    h, w = shape
    store, visible, n_cells = cpu.band_indexes(np.ascontiguousarray(coarse, np.int32), int(h), int(w), int(n_disp),
                                               int(margin), int(tile), int(halo))
    if n_cells > MAX_CELLS:
        raise MemoryError(f"a banded cost volume of {n_cells} cells has more than 2^31 cells")
    return store, visible, int(n_cells)
