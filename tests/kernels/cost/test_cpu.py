"""The CPU matching cost (NCC, integral images, bands) against the slow references of
tests/reference/steps.py: costs to 1e-5 on small random inputs, known answers by hand."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import random_images

from d3cli.kernels import cpu
from d3cli.kernels.cost.cpu import NCC_NARROW, grid_bits
from d3cli.kernels.cpu_common import ops
from d3cli.kernels.volume import banded_index, to_dense

COST_ATOL = 1e-5
SHAPES = [(7, 9), (13, 11), (1, 12), (12, 1), (1, 1), (5, 6)]


# ----------------------------------------------------------------------------- NCC cost
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("window", [1, 3, 5, 7])
def test_ncc_cost_volume_matches_reference(shape, window):
    rng = np.random.default_rng(hash((shape, window)) % 2**32)
    left, right = random_images(rng, shape)
    for max_disparity in (0, 3, 6):
        got = cpu.ncc_cost_volume(left, right, max_disparity, window, 1e-2)
        want = ref.ref_ncc_cost_volume(left, right, max_disparity, window, 1e-2)
        assert got.shape == shape + (max_disparity + 1,) and got.dtype == np.float32
        np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("window", [3, 9, 25])
def test_ncc_cost_volume_running_row_sums_match_reference_across_row_blocks(window):
    # 75 rows: the kernel's running row sums restart every 32 rows and add/subtract the
    # rows entering/leaving the window in between; every row must still equal the
    # float64 per-window reference, windows taller than a block included.
    rng = np.random.default_rng(window)
    left, right = random_images(rng, (75, 40))
    got = cpu.ncc_cost_volume(left, right, 12, window, 1e-2)
    want = ref.ref_ncc_cost_volume(left, right, 12, window, 1e-2)
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)


def test_grid_bits():
    img = np.full((3, 4), 17.0, np.float32)
    assert grid_bits(img) == 6
    img[2, 3] = 255.0 - 2.0**-6
    assert grid_bits(img) == 6
    img[1, 1] = 3.0 + 2.0**-7
    assert grid_bits(img) == 20
    img[0, 0] = -2.0**-20
    assert grid_bits(img) == 20
    for bad in (2.0**-21, 256.0, -256.0, np.nan, np.inf):
        off = img.copy()
        off[2, 0] = bad
        assert grid_bits(off) == 64


@pytest.mark.parametrize("window", [5, 25])
def test_ncc_cost_volume_on_grid_images_does_not_depend_on_row_blocks(window):
    # 8-bit left and 2^-20-grid right images (a warped right image): the driver's sums
    # are exact, and it takes taller row blocks, as many as the threads allow; the
    # costs must be the same bits whatever the blocks (one thread: other blocks than
    # with all threads), and still match the reference.
    rng = np.random.default_rng(window)
    h, w = 300, 40
    left = rng.integers(0, 256, (h, w)).astype(np.float32)
    right = (rng.integers(0, 255 * 2**20, (h, w)) / 2.0**20).astype(np.float32)
    assert grid_bits(left) == 6 and grid_bits(right) == 20
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = cpu.ncc_cost_volume(left, right, 12, window, 1e-2)
    finally:
        numba.set_num_threads(threads)
    got = cpu.ncc_cost_volume(left, right, 12, window, 1e-2)
    assert np.array_equal(one.view(np.uint32), got.view(np.uint32))
    want = ref.ref_ncc_cost_volume(left, right, 12, window, 1e-2)
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)


def test_ncc_cost_volume_with_flat_regions_matches_reference():
    rng = np.random.default_rng(3)
    left, right = random_images(rng, (13, 11))
    left[2:9, 1:6] = 117.0  # flat windows inside: cost 1
    right[5:, 6:] = 40.0
    got = cpu.ncc_cost_volume(left, right, 5, 3, 0.5)
    want = ref.ref_ncc_cost_volume(left, right, 5, 3, 0.5)
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)
    assert (got[4:7, 2:5, :] == 1.0).all()


@pytest.mark.parametrize("window", [3, 9])
def test_banded_ncc_cost_volume_matches_reference(window):
    # Bands constant over runs of columns (as the tiles of d3cli.kernels.cost.band make them),
    # narrow (<= NCC_NARROW unclipped cells: the row's one-loop slide) and wide (two
    # loops) in turn along a row, empty ones, and bands clipped at both image borders:
    # every stored cell equals the per-window reference.
    rng = np.random.default_rng(window)
    h, w, n_disp = 40, 70, 31
    left, right = random_images(rng, (h, w))
    lo = np.zeros((h, w), np.int64)
    hi = np.zeros((h, w), np.int64)
    for v in range(h):
        u = 0
        while u < w:
            run = int(rng.integers(1, 12))
            a = int(rng.integers(0, n_disp))
            width = int(rng.choice([0, 1, 3, NCC_NARROW, NCC_NARROW + 1, 20]))
            lo[v, u:u + run] = a
            hi[v, u:u + run] = min(a + width, n_disp)
            u += run
    index, _ = banded_index(lo, hi)
    got = cpu.ncc_cost_volume(left, right, n_disp - 1, window, 1e-2, index=index)
    want = ref.ref_ncc_cost_volume(left, right, n_disp - 1, window, 1e-2)
    dense = to_dense(got.cost, got.index, n_disp)
    band = np.arange(n_disp)[None, None, :]
    inside = (band >= lo[:, :, None]) & (band < hi[:, :, None])
    assert np.isnan(dense[~inside]).all()
    np.testing.assert_allclose(dense[inside], want[inside], rtol=0, atol=COST_ATOL)


def test_ncc_identical_windows_cost_zero():
    rng = np.random.default_rng(4)
    left = rng.uniform(0, 255, (9, 15)).astype(np.float32)
    shift = 3
    right = rng.uniform(0, 255, left.shape).astype(np.float32)
    right[:, : 15 - shift] = left[:, shift:]  # right (x) = left (x + shift)
    cost = cpu.ncc_cost_volume(left, right, 5, 5, 1e-2)
    np.testing.assert_allclose(cost[:, shift:, shift], 0.0, atol=COST_ATOL)


def test_ncc_negated_windows_cost_one_and_missing_cells_one():
    rng = np.random.default_rng(5)
    left = rng.uniform(0, 255, (7, 12)).astype(np.float32)
    right = 255.0 - left
    cost = cpu.ncc_cost_volume(left, right, 4, 3, 1e-2)
    np.testing.assert_allclose(cost[:, :, 0], 1.0, atol=COST_ATOL)
    for u in range(4):  # u - d < 0: no right pixel
        assert (cost[:, u, u + 1:] == 1.0).all()


def test_ncc_affine_intensity_change_is_free():
    rng = np.random.default_rng(6)
    left = rng.uniform(0, 200, (7, 9)).astype(np.float32)
    cost = cpu.ncc_cost_volume(left, 0.5 * left + 30.0, 2, 5, 1e-2)
    np.testing.assert_allclose(cost[:, :, 0], 0.0, atol=COST_ATOL)


def test_ncc_flat_window_costs_one():
    rng = np.random.default_rng(7)
    left = np.full((7, 9), 80.0, np.float32)
    right = rng.uniform(0, 255, (7, 9)).astype(np.float32)
    assert (cpu.ncc_cost_volume(left, right, 3, 5, 1e-2) == 1.0).all()
    assert (cpu.ncc_cost_volume(right, left, 3, 5, 1e-2) == 1.0).all()


@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("min_variance", [1e-2, 0.0, 40.0])
def test_ncc_cost_volume_is_the_per_cell_formula_bit_for_bit(window, min_variance):
    # Integer grey levels: every window sum is an exact integer in float64, whatever the
    # order of the additions, so the driver's costs must be those of the per-cell formula
    # (ops.ncc_cost) of the same sums, bit for bit: flat windows (left, right, and
    # variances at the min_variance threshold) and clipped windows at the borders included.
    rng = np.random.default_rng(window + int(min_variance))
    h, w, n_disp = 11, 19, 7
    left = rng.integers(0, 256, (h, w)).astype(np.float32)
    right = rng.integers(0, 256, (h, w)).astype(np.float32)
    left[2:7, 3:9] = 90.0
    right[5:, 10:16] = 31.0
    right[0:4, 0:5] = rng.integers(0, 2, (4, 5))  # a variance near the threshold
    got = cpu.ncc_cost_volume(left, right, n_disp - 1, window, min_variance)
    lf, rf = left.astype(np.float64), right.astype(np.float64)
    r = window // 2
    want = np.ones((h, w, n_disp), np.float32)
    for v in range(h):
        rows = slice(max(0, v - r), min(h, v + r + 1))
        for u in range(w):
            for d in range(min(n_disp, u + 1)):
                c0, c1 = max(u - r, d), min(u + r, w - 1)  # the right window at c - d stays inside
                wl, wr = lf[rows, c0:c1 + 1], rf[rows, c0 - d:c1 - d + 1]
                want[v, u, d] = ops.ncc_cost(wl.size, wl.sum(), (wl * wl).sum(), wr.sum(), (wr * wr).sum(),
                                                 (wl * wr).sum(), min_variance)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def test_ncc_finish_is_the_float64_formula_to_float32_rounding():
    # The square root and the division run in float32 (both targets, ops.ncc_finish):
    # within 2 ulp of 1.0 of the float64 formula rounded to float32, clipped to [0, 1].
    rng = np.random.default_rng(11)
    den = rng.uniform(1e-4, 3e8, 20000) ** rng.choice([1.0, 0.5], 20000)
    num = np.sqrt(den) * rng.uniform(-1.2, 1.2, 20000)  # NCC beyond +-1 too (rounding)
    got = np.array([ops.ncc_finish(a, b) for a, b in zip(num, den)])
    want = 0.5 * (1.0 - np.clip(num / np.sqrt(den), -1.0, 1.0))
    assert np.array_equal(got.astype(np.float32), got) and (got >= 0).all() and (got <= 1).all()
    np.testing.assert_allclose(got, want, rtol=0, atol=2 * np.finfo(np.float32).eps)


def test_ncc_finish_of_a_variance_product_below_float32_is_no_nan():
    # A product of variances this small (min_variance 0) flushes to 0 in float32: without
    # the floor at float32's least normal it was 0 / 0, a NaN cost.
    assert ops.ncc_finish(0.0, 1e-300) == 0.5
    assert ops.ncc_finish(1.0, 1e-300) == 0.0
    assert ops.ncc_finish(-1.0, 1e-300) == 1.0
