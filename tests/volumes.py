"""Random inputs for the kernel tests (CPU against the references, CUDA against the CPU)."""

from __future__ import annotations

import numpy as np
from d3cli.kernels.volume import Volume, banded_index

#: Diffusion parameters every diffusion test runs: paper defaults, no adversarial update,
#: the near-optimality gap, a wider neighbourhood, a wider tolerance.
DIFFUSION_SETTINGS = [
    dict(max_gap=-1.0, tau=1, kappa_d=1, adversarial=True),
    dict(max_gap=-1.0, tau=1, kappa_d=1, adversarial=False),
    dict(max_gap=0.05, tau=1, kappa_d=1, adversarial=True),
    dict(max_gap=0.2, tau=0, kappa_d=2, adversarial=True),
    dict(max_gap=-1.0, tau=2, kappa_d=1, adversarial=True),
]


def random_images(rng, shape):
    """Two float32 (H, W) images of uniform grey levels on the 0-255 scale."""
    return (
        rng.uniform(0, 255, shape).astype(np.float32),
        rng.uniform(0, 255, shape).astype(np.float32),
    )


def mark_missing_cells(cost):
    """Cells whose right pixel u - d is outside the image hold 1 (the volume convention)."""
    for u in range(cost.shape[1]):
        cost[:, u, u + 1:] = 1.0
    return cost


def random_volume(rng, h, w, n_disp, *, share_of_ones=0.1, levels=None):
    """Costs uniform in [0, 1), some cells = 1; ``levels`` quantises them to force ties."""
    cost = rng.random((h, w, n_disp))
    if levels:
        cost = np.floor(cost * levels) / levels
    cost[rng.random(cost.shape) < share_of_ones] = 1.0
    return mark_missing_cells(cost.astype(np.float32))


def structured_volume(rng, true_disp, n_disp, *, noise=0.05, slope=0.15, floor=0.1):
    """Cost curves with a clear minimum at ``true_disp`` (H, W), plus noise."""
    d = np.arange(n_disp)[None, None, :]
    cost = floor + slope * np.abs(d - true_disp[:, :, None]) + noise * rng.random(true_disp.shape + (n_disp,))
    return mark_missing_cells(np.clip(cost, 0, 0.999).astype(np.float32))


def sparse_map(rng, shape, n_disp, share=0.15):
    """int32 map with random disparities on ``share`` of the pixels, -1 elsewhere."""
    disp = rng.integers(0, n_disp, shape).astype(np.int32)
    disp[rng.random(shape) >= share] = -1
    return disp


def banded(dense_cost, lo, hi):
    """The Volume holding the cells of ``dense_cost`` inside the bands ``lo <= d < hi``."""
    index, n_cells = banded_index(lo, hi)
    flat = np.full(n_cells, np.nan, np.float32)
    h, w, n_disp = dense_cost.shape
    for v in range(h):
        for u in range(w):
            off = index[v, u, 0]
            flat[off + lo[v, u]:off + hi[v, u]] = dense_cost[v, u, lo[v, u]:hi[v, u]]
    return Volume(flat, index, n_disp)
