"""Banded cost volumes: the index helpers, and every driver on bands against the same
driver on the full-range volume whose missing cells hold +inf.

A cell outside a pixel's band "does not exist" (``cost_or_inf`` gives inf), so every
decision on a banded volume must equal the decision on the full-range volume with those
cells set to +inf: inf never wins a minimum, never vetoes a local-minimum test, and the
parabola of the sub-pixel step is skipped next to it.  The full-range drivers are checked
against the references of tests/reference.py in test_cpu.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.volumes import DIFFUSION_SETTINGS, banded, random_volume, sparse_map

from d3cli.kernels import cpu
from d3cli.kernels.volume import Volume, banded_index, dense_index, is_dense, to_dense


def random_bands(rng, h, w, n_disp):
    """Bands [lo, hi) per pixel: random, some full, some a single disparity."""
    lo = rng.integers(0, n_disp, (h, w))
    hi = np.minimum(n_disp, lo + rng.integers(1, n_disp + 1, (h, w)))
    full = rng.random((h, w)) < 0.2
    lo[full], hi[full] = 0, n_disp
    return lo, hi


def test_dense_index_is_the_hwd_layout():
    index = dense_index(3, 4, 5)
    assert index.dtype == np.int32 and index.shape == (3, 4, 3)
    cube = np.arange(60, dtype=np.float32).reshape(3, 4, 5)
    np.testing.assert_array_equal(to_dense(cube.ravel(), index, 5), cube)
    assert is_dense(index, 5) and not is_dense(index, 6)


def test_banded_index_packs_bands_and_to_dense_restores_them():
    rng = np.random.default_rng(0)
    cube = rng.random((5, 7, 6)).astype(np.float32)
    lo, hi = random_bands(rng, 5, 7, 6)
    vol = banded(cube, lo, hi)
    assert vol.cost.size == int((hi - lo).sum()) and not np.isnan(vol.cost).any()
    back = to_dense(vol.cost, vol.index, 6)
    inside = (np.arange(6) >= lo[..., None]) & (np.arange(6) < hi[..., None])
    np.testing.assert_array_equal(back[inside], cube[inside])
    assert np.isnan(back[~inside]).all()


def test_an_oversized_volume_is_refused():
    with pytest.raises(MemoryError):
        dense_index(50000, 50000, 2)


@pytest.fixture(params=[0, 1, 2])
def case(request):
    rng = np.random.default_rng(100 + request.param)
    h, w, n_disp = [(9, 11, 6), (13, 8, 9), (1, 12, 5)][request.param]
    cube = random_volume(rng, h, w, n_disp)
    lo, hi = random_bands(rng, h, w, n_disp)
    vol = banded(cube, lo, hi)
    inside = (np.arange(n_disp) >= lo[..., None]) & (np.arange(n_disp) < hi[..., None])
    with_inf = np.where(inside, cube, np.float32(np.inf)).astype(np.float32)
    return rng, vol, with_inf


def test_banded_min_cost_equals_the_full_range_with_inf(case):
    _, vol, with_inf = case
    np.testing.assert_array_equal(cpu.min_cost(vol), cpu.min_cost(with_inf))


@pytest.mark.parametrize("exclusion", [0, 1])
def test_banded_seeds_equal_the_full_range_with_inf(case, exclusion):
    _, vol, with_inf = case
    got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, exclusion)
    np.testing.assert_array_equal(got, cpu.decisive_seeds(with_inf, 1.05, 1e-3, 1, exclusion))


def test_seeds_skip_the_pixels_already_decided(case):
    rng, vol, _ = case
    full = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, 0)
    skip = sparse_map(rng, vol.shape, vol.n_disp, share=0.5)
    got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, 0, skip=skip)
    np.testing.assert_array_equal(got, np.where(skip >= 0, -1, full))


def test_right_view_wta_table_of_a_row_equals_the_scan_of_each_column(case):
    """The seeds' row table (one pass over the cells) against pixel.right_wta,
    which scans the disparities of one right pixel; ties and columns without a cell included."""
    _, vol, _ = case
    flat, index, n_disp = vol.cost, vol.index, vol.n_disp
    flat = np.round(flat * 4) / 4  # coarse values: many ties
    h, w = vol.shape
    for v in range(h):
        want = [cpu.ops.right_wta(flat, index, n_disp, v, x) for x in range(w)]
        np.testing.assert_array_equal(cpu._right_wta_row(flat, index, v), want)


@pytest.mark.parametrize("share", [0.0, 0.5, 0.95])
def test_seeds_with_few_or_many_candidates_per_row_equal_the_reference(case, share):
    """Rows with many candidate seeds take the right view's WTA from the row table, rows
    with few scan it per candidate: both give the per-pixel seed_at's seeds."""
    rng, vol, _ = case
    skip = sparse_map(rng, vol.shape, vol.n_disp, share=share)
    h, w = vol.shape
    for exclusion in (0, 1):
        want = np.array([[-1 if skip[v, u] >= 0 else
                          cpu.ops.seed_at(vol.cost, vol.index, vol.n_disp, v, u, 1.05, 1e-3, 1, exclusion)
                          for u in range(w)] for v in range(h)])
        got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, exclusion, skip=skip)
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS)
def test_banded_diffusion_equals_the_full_range_with_inf(case, settings):
    rng, vol, with_inf = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.2)
    disp[disp >= 0] = np.clip(disp[disp >= 0], 0, vol.n_disp - 1)
    got, sweeps = cpu.diffuse(vol, disp, cpu.min_cost(vol), max_sweeps=1000, **settings)
    want, want_sweeps = cpu.diffuse(with_inf, disp, cpu.min_cost(with_inf), max_sweeps=1000, **settings)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS)
def test_banded_diffusion_finding_the_least_costs_itself_equals_them_given(case, settings):
    # min_cost None: pixel.diffuse_at finds the least cost over the band where it needs it
    rng, vol, _ = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.2)
    disp[disp >= 0] = np.clip(disp[disp >= 0], 0, vol.n_disp - 1)
    got, sweeps = cpu.diffuse(vol, disp, None, max_sweeps=1000, **settings)
    want, want_sweeps = cpu.diffuse(vol, disp, cpu.min_cost(vol), max_sweeps=1000, **settings)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps


@pytest.mark.parametrize("prc", [True, False])
def test_banded_inheritance_equals_the_full_range_with_inf(case, prc):
    rng, vol, with_inf = case
    h, w = vol.shape
    coarse = sparse_map(rng, ((h + 1) // 2, (w + 1) // 2), (vol.n_disp + 1) // 2, share=0.8)
    got = cpu.inherit(vol, coarse, prc, 1.05, 1e-3)
    np.testing.assert_array_equal(got, cpu.inherit(with_inf, coarse, prc, 1.05, 1e-3))


def test_banded_subpixel_equals_the_full_range_with_inf(case):
    rng, vol, with_inf = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.9)
    lo, hi = vol.index[:, :, 1], vol.index[:, :, 2]
    disp = np.where(disp >= 0, np.clip(disp, lo, hi - 1), -1).astype(np.int32)  # decided inside the band
    got = cpu.subpixel(vol, disp)
    np.testing.assert_array_equal(got, cpu.subpixel(with_inf, disp))
    # next to a band end the integer disparity is kept, as at the ends of the range
    at_end = (disp >= 0) & ((disp == lo) | (disp == hi - 1))
    np.testing.assert_array_equal(got[at_end], disp[at_end].astype(np.float32))


def test_banded_invalidation_sets_only_out_of_view_cells(case):
    _, vol, _ = case
    flat = vol.cost.copy()
    cpu.invalidate_out_of_view(Volume(flat, vol.index, vol.n_disp))
    before = to_dense(vol.cost, vol.index, vol.n_disp)
    after = to_dense(flat, vol.index, vol.n_disp)
    u = np.arange(vol.shape[1])[None, :, None]
    d = np.arange(vol.n_disp)[None, None, :]
    exists = ~np.isnan(before)
    np.testing.assert_array_equal(after[exists & (d > u)], 1.0)
    np.testing.assert_array_equal(after[exists & (d <= u)], before[exists & (d <= u)])


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
    row_start, max_row = cpu._row_layout(vol.index)
    covered = cpu._covered_bands(vol.index)
    one_by_one = flat.copy()
    for _ in range(t_max):
        cpu._rbf_passes(one_by_one, vol.index, covered, weights, row_start, 1, max_row, 1)
    blocked = flat.copy()
    cpu._rbf_passes(blocked, vol.index, covered, weights, row_start, n_tasks, max_row, t_max)
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
        np.testing.assert_array_equal(cpu._covered_bands(index), _covered_reference(index))
    lo = np.full(shape, 1)
    index, _ = banded_index(lo, lo + 2)
    assert (cpu._covered_bands(index) == 2).all()


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
    covered = cpu._covered_bands(vol.index)
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
    row_start, max_row = cpu._row_layout(vol.index)
    sizes = (vol.index[:, :, 2] - vol.index[:, :, 1]).sum(axis=1)
    np.testing.assert_array_equal(row_start, np.concatenate([[0], np.cumsum(sizes)]))
    assert max_row == max(1, int(sizes.max()))
    assert row_start[-1] == vol.cost.size
