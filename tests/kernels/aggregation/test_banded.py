"""The aggregation drivers on banded volumes against the same driver on the full-range volume whose
missing cells hold +inf (tests/kernels/test_volume.py says why that must hold)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.banded import random_bands
from tests.volumes import banded

from d3cli.kernels import cpu
from d3cli.kernels.aggregation.cpu import rbf_passes
from d3cli.kernels.aggregation.cpu_rows import covered_bands
from d3cli.kernels.cpu_common import row_layout
from d3cli.kernels.volume import banded_index


@pytest.mark.parametrize("shape", [(23, 17), (5, 9), (1, 6)])
@pytest.mark.parametrize("t_max", [1, 2, 4])
@pytest.mark.parametrize("n_tasks", [1, 2, 3, 7, 40])
def test_blocked_rbf_passes_equal_one_pass_at_a_time(shape, t_max, n_tasks):
    """All passes at once over strips (temporal blocking) give the bits of
    ``t_max`` single passes, on bands of every width and for any number of strips (the
    halo rows each strip recomputes included; 40 strips on 23 rows: one row each)."""
    rng = np.random.default_rng(t_max * 100 + n_tasks + shape[0])
    h, w = shape
    lo, hi = random_bands(rng, h, w, 9)
    vol = banded(rng.uniform(0, 1, (h, w, 9)).astype(np.float32), lo, hi)
    flat = vol.cost
    img = rng.uniform(100, 120, shape).astype(np.float32)  # similar grey levels: the passes mix
    weights = cpu.rbf_weights(img, 1.5, 12.0)
    row_start, max_row = row_layout(vol.index)
    covered = covered_bands(vol.index)
    one_by_one = flat.copy()
    for _ in range(t_max):
        rbf_passes(one_by_one, vol.index, covered, weights, row_start, 1, max_row, 1)
    blocked = flat.copy()
    rbf_passes(blocked, vol.index, covered, weights, row_start, n_tasks, max_row, t_max)
    np.testing.assert_array_equal(blocked, one_by_one)
    assert not np.array_equal(blocked, flat)


def _covered_reference(index):
    """The covered-band map by its definition: 2 where the 3x3 neighbours (clamped) all
    have the pixel's band, 1 where their bands contain it, 0 elsewhere."""
    h, w, _ = index.shape
    out = np.zeros((h, w), np.uint8)
    for v in range(h):
        for u in range(w):
            lo, hi = index[v, u, 1], index[v, u, 2]
            nb = index[max(v - 1, 0):min(v + 1, h - 1) + 1, max(u - 1, 0):min(u + 1, w - 1) + 1]
            if ((nb[:, :, 1] == lo) & (nb[:, :, 2] == hi)).all():
                out[v, u] = 2
            elif ((nb[:, :, 1] <= lo) & (nb[:, :, 2] >= hi)).all():
                out[v, u] = 1
    return out


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (5, 1), (2, 2), (7, 9), (30, 40)])
def test_covered_bands_match_their_definition(shape):
    rng = np.random.default_rng(sum(shape))
    for trial in range(10):
        # few distinct bands, so that runs of equal bands (the map's 2s) occur
        lo, hi = random_bands(rng, *shape, 3)
        index, _ = banded_index(lo, hi)
        np.testing.assert_array_equal(covered_bands(index), _covered_reference(index))
    lo = np.full(shape, 1)
    index, _ = banded_index(lo, lo + 2)
    assert (covered_bands(index) == 2).all()


def _rbf_pass_reference(flat, index, weights):
    """One 3x3 pass over a banded volume by its definition, in float32 with the
    kernel's order of operations (a = 0, then a += w_k q_k for k = 0..8): a neighbour
    (clamped at the border) that lacks a disparity of the pixel's band lends the
    pixel's own cell."""
    h, w, _ = index.shape
    out = flat.copy()
    for v in range(h):
        for u in range(w):
            off, lo, hi = index[v, u]
            for d in range(lo, hi):
                a = np.float32(0.0)
                for k in range(9):
                    y = min(max(v + k // 3 - 1, 0), h - 1)
                    x = min(max(u + k % 3 - 1, 0), w - 1)
                    o, a0, a1 = index[y, x]
                    q = flat[o + d] if a0 <= d < a1 else flat[off + d]
                    a = np.float32(a + np.float32(weights[v, u, k] * q))
                out[off + d] = a
    return out


@pytest.mark.parametrize("n_disp", [7, 20, 100])
def test_rbf_filter_on_bands_is_exact(n_disp):
    """Runs of equal bands between pixels whose neighbours have other bands (covered or
    not), narrow bands to bands of six vectors: the bits of the definition, pass after
    pass."""
    rng = np.random.default_rng(n_disp)
    h, w = 8, 26
    seg_lo = rng.integers(0, n_disp // 3 + 1, (h // 4 + 1, w // 9 + 1))  # blocks of 4 x 9 pixels
    seg_hi = np.minimum(n_disp, seg_lo + rng.integers(n_disp // 2, n_disp + 1, seg_lo.shape))
    rows, cols = np.arange(h)[:, None] // 4, np.arange(w)[None, :] // 9
    lo, hi = seg_lo[rows, cols], seg_hi[rows, cols]
    odd = rng.random((h, w)) < 0.15
    r_lo, r_hi = random_bands(rng, h, w, n_disp)
    lo[odd], hi[odd] = r_lo[odd], r_hi[odd]
    vol = banded(rng.uniform(0, 1, (h, w, n_disp)).astype(np.float32), lo, hi)
    covered = covered_bands(vol.index)
    assert (covered == 0).any() and (covered == 1).any() and (covered == 2).any()
    img = rng.uniform(100, 120, (h, w)).astype(np.float32)
    weights = cpu.rbf_weights(img, 1.5, 12.0)
    expected = vol.cost.copy()
    for t_max in (1, 2, 3, 4):
        expected = _rbf_pass_reference(expected, vol.index, weights)
        got = cpu.rbf_filter(vol, weights, t_max).cost
        np.testing.assert_array_equal(got.view(np.uint32), expected.view(np.uint32))


def test_row_layout_against_numpy():
    rng = np.random.default_rng(5)
    lo, hi = random_bands(rng, 7, 11, 9)
    vol = banded(rng.uniform(0, 1, (7, 11, 9)).astype(np.float32), lo, hi)
    row_start, max_row = row_layout(vol.index)
    sizes = (vol.index[:, :, 2] - vol.index[:, :, 1]).sum(axis=1)
    np.testing.assert_array_equal(row_start, np.concatenate([[0], np.cumsum(sizes)]))
    assert max_row == max(1, int(sizes.max()))
    assert row_start[-1] == vol.cost.size
