"""The band rule of a finer level's cost volume (docs/design.md, 'Pyramid and bands')
written out pixel by pixel, the reference of :func:`d3cli.kernels.host.band_indexes`."""

from __future__ import annotations

import numpy as np


def ref_band_indexes(coarse, shape, n_disp, margin, tile, halo):
    """The rules of docs/design.md, 'Pyramid and bands', written out pixel by pixel."""
    h, w = shape
    ch, cw = coarse.shape
    nty, ntx = -(-h // tile), -(-w // tile)
    t_lo = np.zeros((nty, ntx), int)
    t_hi = np.full((nty, ntx), n_disp)
    for ty in range(nty):
        for tx in range(ntx):
            dcs = [coarse[min(v // 2, ch - 1), min(u // 2, cw - 1)]
                   for v in range(ty * tile, min(h, ty * tile + tile))
                   for u in range(tx * tile, min(w, tx * tile + tile))]
            dcs = [d for d in dcs if d >= 0]
            if dcs:
                lo = min(max(2 * min(dcs) - margin, 0), n_disp - 1)
                t_lo[ty, tx] = lo
                t_hi[ty, tx] = max(lo + 1, min(max(2 * max(dcs) + margin + 1, 1), n_disp))
    ring_lo, ring_hi = t_lo.copy(), t_hi.copy()
    for ty in range(nty):
        for tx in range(ntx):
            ring_lo[ty, tx] = t_lo[max(ty - 1, 0):ty + 2, max(tx - 1, 0):tx + 2].min()
            ring_hi[ty, tx] = t_hi[max(ty - 1, 0):ty + 2, max(tx - 1, 0):tx + 2].max()
    t_lo, t_hi = ring_lo, ring_hi
    vis = np.zeros((h, w, 2), int)
    store = np.zeros((h, w, 2), int)
    for v in range(h):
        for u in range(w):
            vis[v, u] = t_lo[v // tile, u // tile], t_hi[v // tile, u // tile]
            near = [(ty, tx) for ty in range(nty) for tx in range(ntx)
                    if ty * tile - halo <= v < ty * tile + tile + halo and tx * tile - halo <= u < tx * tile + tile + halo]
            store[v, u] = min(t_lo[t] for t in near), max(t_hi[t] for t in near)
    return store, vis
