"""The Numba CPU kernels against the slow references of tests/reference.py.

Every driver of ``d3cli.kernels.cpu`` is compared with a reference written from the
specification on small random inputs (odd sizes, one-row and one-column images,
1..7 disparities): costs to 1e-5, integer maps exactly.  Hand-made cases with a known
answer pin the behaviour the references could share a mistake about, and every driver
is checked to give bit-identical results with one thread and with all threads.
"""

from __future__ import annotations

import cv2
import numba
import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import DIFFUSION_SETTINGS, mark_missing_cells, random_images, random_volume, sparse_map, structured_volume

from d3cli.kernels import cpu
from d3cli.kernels.volume import banded_index, to_dense
from d3cli.method.pyramid import build_pyramid, downsample, level_max_disparity
from d3cli.method.refinement import fill_holes

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
    assert cpu._grid_bits(img) == 6
    img[2, 3] = 255.0 - 2.0**-6
    assert cpu._grid_bits(img) == 6
    img[1, 1] = 3.0 + 2.0**-7
    assert cpu._grid_bits(img) == 20
    img[0, 0] = -2.0**-20
    assert cpu._grid_bits(img) == 20
    for bad in (2.0**-21, 256.0, -256.0, np.nan, np.inf):
        off = img.copy()
        off[2, 0] = bad
        assert cpu._grid_bits(off) == 64


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
    assert cpu._grid_bits(left) == 6 and cpu._grid_bits(right) == 20
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
    # Bands constant over runs of columns (as the tiles of d3cli.method.band make them),
    # narrow (<= cpu.NCC_NARROW unclipped cells: the row's one-loop slide) and wide (two
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
            width = int(rng.choice([0, 1, 3, cpu.NCC_NARROW, cpu.NCC_NARROW + 1, 20]))
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


# ----------------------------------------------------------------------------- aggregation
@pytest.mark.parametrize("shape", SHAPES)
def test_rbf_weights_match_reference(shape):
    rng = np.random.default_rng(sum(shape))
    img = rng.uniform(0, 255, shape).astype(np.float32)
    got = cpu.rbf_weights(img, 1.5, 12.0)
    np.testing.assert_allclose(got, ref.ref_rbf_weights(img, 1.5, 12.0), rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.sum(axis=2), 1.0, atol=1e-6)
    assert (got[0, :, :3] == 0).all() and (got[:, 0, ::3] == 0).all()  # outside the image



def test_streaming_stores_write_as_assignments():
    # rbf_weights writes its output with cpu._store_nt (non-temporal stores, then a
    # fence): the same values, cast to the array's dtype, as plain assignments.
    @numba.njit
    def fill(out, vals):
        flat = out.reshape(-1)
        for i in range(vals.size):
            cpu._store_nt(flat, np.uint64(i), vals[i])
        cpu._store_fence()

    vals = np.random.default_rng(5).standard_normal(3 * 13) * 1e3
    for dtype in (np.float32, np.float64):
        out = np.zeros((3, 13), dtype)
        fill(out, vals)
        np.testing.assert_array_equal(out.reshape(-1).view(np.uint8), vals.astype(dtype).view(np.uint8))

@pytest.mark.parametrize("scale", [4, 16, 64])
def test_rbf_weights_of_coarse_pyramid_levels_equal_the_computed_kernel(scale):
    # Levels 2-4 of an 8-bit image hold multiples of 1/4, 1/16, 1/64 (2x2 means): their
    # kernel comes from a table of 255 scale + 1 differences when that is smaller than
    # the image, bit for bit the exp per neighbour.
    rng = np.random.default_rng(scale)
    side = 8 * int(np.sqrt(scale)) + 8  # enough pixels for the table to pay
    img = (rng.integers(0, 255 * scale + 1, (side, side + 3)) / scale).astype(np.float32)
    img[0, 0], img[-1, -1] = 0.0, 255.0
    assert cpu._grey_scale(img) == scale
    other = img.copy()
    other[0, 0] = 0.3  # forces the exp path
    assert cpu._grey_scale(other) == 0
    got = cpu.rbf_weights(img, 1.5, 12.0)
    computed = cpu.rbf_weights(other, 1.5, 12.0)
    np.testing.assert_array_equal(got[2:], computed[2:])
    np.testing.assert_array_equal(got[:, 2:], computed[:, 2:])
    np.testing.assert_allclose(got, ref.ref_rbf_weights(img, 1.5, 12.0), rtol=0, atol=1e-6)


def test_grey_scale_of_an_8bit_pyramid():
    from d3cli.method.pyramid import build_pyramid

    img = np.random.default_rng(5).integers(0, 256, (64, 80)).astype(np.float32)
    assert [cpu._grey_scale(level) for level in build_pyramid(img, 5)] == [1, 4, 16, 64, 0]
    assert cpu._grey_scale(img / 257.0) == 0
    assert cpu._grey_scale(img + 256.0) == 0  # above 255


@pytest.mark.parametrize("shape", SHAPES)
def test_rbf_weights_of_8bit_images_equal_the_computed_kernel(shape):
    # Integer grey levels read the kernel from a table; one non-integer pixel makes the
    # whole image take the exp per neighbour.  Away from that pixel both must agree
    # bit for bit, and both match the reference.
    rng = np.random.default_rng(sum(shape) + 1)
    img = rng.integers(0, 256, shape).astype(np.float32)
    img[0, 0] = 0.0
    img[-1, -1] = 255.0  # both ends of the table
    other = img.copy()
    other[0, 0] = 0.3  # not a multiple of 1/64 either
    got = cpu.rbf_weights(img, 1.5, 12.0)
    computed = cpu.rbf_weights(other, 1.5, 12.0)
    np.testing.assert_array_equal(got[2:], computed[2:])
    np.testing.assert_array_equal(got[:, 2:], computed[:, 2:])
    np.testing.assert_allclose(got, ref.ref_rbf_weights(img, 1.5, 12.0), rtol=0, atol=1e-6)


def test_rbf_weights_reciprocal_quotients_equal_the_division():
    # Interior pixels divide by the sum through its reciprocal, checking that the float32
    # result is certain; the border pixels and uncertain rows take the exact division.
    # Both must agree bit for bit, tiny (float32 subnormal or zero) weights included.
    rng = np.random.default_rng(11)
    w = 5000
    up = rng.uniform(0, 1, (4, w))
    cur = rng.uniform(0, 1, (4, w))
    cur[1, ::7] = 10.0 ** rng.uniform(-60, -30, cur[1, ::7].shape)
    cur[2, ::5] = 0.0
    exact = np.empty((9, w), np.float32)
    for u in range(w):
        cpu._rbf_pixel(exact, up, cur, 0.4, True, True, u)
    stage = np.empty_like(exact)
    assert cpu._rbf_interior(stage, up, cur, 0.4, w) == 0
    np.testing.assert_array_equal(stage[:, 1:-1], exact[:, 1:-1])
    # A quotient within a few float64 steps of a float32 rounding boundary (the midpoint
    # 0.5 + 2^-25): uncertain, so the row is redone exactly.
    up = np.zeros((4, 3))
    cur = np.zeros((4, 3))
    cur[2, 1] = 0.75  # slot 7 of pixel 1
    centre = 0.75 / (0.5 + 2.0**-25) - 0.75
    stage = np.empty((9, 3), np.float32)
    assert cpu._rbf_interior(stage, up, cur, centre, 3) > 0
    exact = np.empty((9, 3), np.float32)
    for u in range(3):
        cpu._rbf_pixel(exact, up, cur, centre, True, True, u)
    out = np.empty((3, 9), np.float32)
    cpu._rbf_normalise_row(out, up, cur, centre, True, True, stage)
    np.testing.assert_array_equal(out, exact.T)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("t_max", [0, 1, 3])
def test_rbf_filter_matches_reference(shape, t_max):
    rng = np.random.default_rng(t_max + sum(shape))
    img = rng.uniform(0, 255, shape).astype(np.float32)
    cost = random_volume(rng, *shape, 5)
    before = cost.copy()
    weights = ref.ref_rbf_weights(img, 2.0, 20.0)
    got = cpu.rbf_filter(cost, weights, t_max)
    np.testing.assert_allclose(got, ref.ref_rbf_filter(cost, weights, t_max), rtol=0, atol=COST_ATOL)
    np.testing.assert_array_equal(cost, before)
    assert got is not cost


def rbf_filter_float32(cost, weights, t_max):
    """ref_rbf_filter in float32 with the kernel's order of operations (a = 0, then
    a += w_k q_k for k = 0..8; neighbours outside the image: weight 0, a clamped cell)."""
    cur = np.asarray(cost, np.float32)
    h, w, _ = cur.shape
    for _ in range(t_max):
        nxt = np.zeros_like(cur)
        for k in range(9):
            ys = np.clip(np.arange(h) + k // 3 - 1, 0, h - 1)
            xs = np.clip(np.arange(w) + k % 3 - 1, 0, w - 1)
            nxt += weights[:, :, k, None] * cur[ys][:, xs]
        cur = nxt
    return cur


@pytest.mark.parametrize("n_disp", [1, 2, 3, 4, 5, 6, 8, 9, 10, 11, 15, 16, 17, 24, 25, 32, 33, 40, 41, 48, 50, 64,
                                    65, 96, 97, 130])
def test_rbf_filter_is_exact_for_every_band_width(n_disp):
    # each band width takes its own block in _rbf_run (one to six vectors of 16 cells
    # holding one, two or three pixels, or the plain loop), runs as long as a row and as
    # short as a few pixels, a multiple of the pixels of a block or not (the last pixels
    # of a run take blocks of one pixel, or the plain loop at the row's end):
    # bit-identical to the same sums done in NumPy
    rng = np.random.default_rng(n_disp)
    for shape in [(9, 40), (6, 23), (5, 12), (5, 4), (4, 3)]:
        img = rng.uniform(0, 255, shape).astype(np.float32)
        cost = random_volume(rng, *shape, n_disp)
        weights = cpu.rbf_weights(img, 1.5, 12.0)
        for t_max in (1, 2, 4):
            np.testing.assert_array_equal(cpu.rbf_filter(cost, weights, t_max), rbf_filter_float32(cost, weights, t_max))


@pytest.mark.parametrize("t_max", [0, 1, 2, 3])
def test_rbf_filter_overwriting_its_input_gives_the_same_result(t_max):
    rng = np.random.default_rng(t_max)
    img = rng.uniform(0, 255, (9, 13)).astype(np.float32)
    cost = random_volume(rng, 9, 13, 6)
    weights = cpu.rbf_weights(img, 1.5, 12.0)
    expected = cpu.rbf_filter(cost, weights, t_max)
    np.testing.assert_array_equal(cpu.rbf_filter(cost.copy(), weights, t_max, True), expected)


def test_rbf_filter_keeps_a_constant_volume():
    img = np.random.default_rng(8).uniform(0, 255, (9, 7)).astype(np.float32)
    cost = np.full((9, 7, 4), 0.37, np.float32)
    got = cpu.rbf_filter(cost, cpu.rbf_weights(img, 1.5, 12.0), 4)
    np.testing.assert_allclose(got, 0.37, atol=1e-6)


@pytest.mark.parametrize("shape", [(7, 9), (1, 8), (8, 1), (6, 5)])
@pytest.mark.parametrize("radius", [0, 1, 3])
def test_bilateral_filter_matches_reference(shape, radius):
    rng = np.random.default_rng(radius + 10 * sum(shape))
    img = rng.uniform(0, 255, shape).astype(np.float32)
    cost = random_volume(rng, *shape, 4)
    got = cpu.bilateral_filter(cost, img, radius, 2.0, 15.0)
    want = ref.ref_bilateral_filter(cost, img, radius, 2.0, 15.0)
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)


# ----------------------------------------------------------------------------- seeds
@pytest.mark.parametrize("levels", [None, 8])
def test_seeds_match_reference_on_random_volumes(levels):
    rng = np.random.default_rng(11 if levels else 12)
    for h, w in SHAPES:
        for n_disp in (1, 2, 4, 7):
            cost = random_volume(rng, h, w, n_disp, levels=levels)
            for pkrn_min, exclusion, lr_tol in [(1.0, 0, 1), (1.2, 0, 0), (1.1, 1, 1), (2.0, 2, 2)]:
                got = cpu.decisive_seeds(cost, pkrn_min, 1e-3, lr_tol, exclusion)
                want = ref.ref_decisive_seeds(cost, pkrn_min, 1e-3, lr_tol, exclusion)
                np.testing.assert_array_equal(got, want, err_msg=f"{h}x{w}x{n_disp} {pkrn_min=} {exclusion=}")


def test_seeds_match_reference_on_structured_volumes():
    rng = np.random.default_rng(13)
    true = (np.arange(11)[None, :] // 4 + np.arange(13)[:, None] // 5).astype(np.int64) + 1
    cost = structured_volume(rng, true, 7, noise=0.1)
    for pkrn_min in (1.0, 1.3, 2.0):
        got = cpu.decisive_seeds(cost, pkrn_min, 1e-3, 1, 0)
        np.testing.assert_array_equal(got, ref.ref_decisive_seeds(cost, pkrn_min, 1e-3, 1, 0))
    assert (cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0) >= 0).sum() > 20


def test_seeds_single_clear_minimum():
    h, w, d0 = 5, 9, 3
    cost = np.full((h, w, 6), 0.8, np.float32)
    cost[:, :, d0] = 0.1
    mark_missing_cells(cost)
    seeds = cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)
    want = np.where(np.arange(w)[None, :] >= d0, d0, -1) * np.ones((h, 1), int)
    np.testing.assert_array_equal(seeds, want)
    assert seeds.dtype == np.int32


def test_seeds_reject_ambiguous_and_inconsistent_pixels():
    cost = np.full((1, 8, 4), 0.8, np.float32)
    cost[0, 5, 2] = 0.1  # clear minimum at (5, 0) with d = 2 ...
    cost[0, 6, 3] = 0.05  # ... but right pixel 3 prefers d = 3 (left pixel 6): within tolerance 1
    cost[0, 7, 0] = 0.3
    cost[0, 7, 1] = 0.3  # tie at (7, 0): PKRN = 1 -> no seed
    mark_missing_cells(cost)
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 5] == 2
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 0, 0)[0, 5] == -1  # strict LR check
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 7] == -1
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 1)[0, 7] == 0  # tie is inside the exclusion zone


def test_seed_whose_right_pixel_is_outside_is_rejected():
    cost = np.full((1, 6, 4), 0.9, np.float32)
    cost[0, 0, 2] = 0.1  # an aggregated 'missing' cell that wins: right pixel u - d = -2
    verdicts = set()
    for far_value in (0.5, 0.05):
        cost[0, 4, 0] = far_value  # unrelated pixel that Numba reads through the wrap-around
        verdicts.add(int(cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 0]))
    assert verdicts == {-1}


def _in_order_candidate(cells, lo, u, pkrn_min, epsilon, exclusion):
    """Test (a) of the seeds as the in-order scan with a strict ``<`` (the kernel before
    interleaved lanes): the first disparity of least cost, then the second cost."""
    d1, c1 = lo, cells[0]
    for k in range(1, len(cells)):
        if cells[k] < c1:
            d1, c1 = lo + k, cells[k]
    if c1 >= 1.0:
        return -1
    if exclusion == 0:
        others = [c for k, c in enumerate(cells) if k != d1 - lo]
    else:
        others = [c for k, c in enumerate(cells) if abs(lo + k - d1) > exclusion]
    c2 = min(others, default=np.inf)
    if c2 == np.inf or float(c2) + epsilon < pkrn_min * (float(c1) + epsilon):
        return -1
    return d1 if u - d1 >= 0 else -1


@pytest.mark.parametrize("levels", [None, 3])
def test_seed_candidate_by_lanes_equals_the_in_order_scan(levels):
    """pixel.seed_candidate takes the least and second costs by value in four interleaved
    lanes and d1 as the first disparity holding the least: the same verdicts as
    the in-order scan on bands of 1 to 41 cells (every lane remainder), ties included."""
    rng = np.random.default_rng(21 if levels else 22)
    h, w, n_disp = 6, 60, 48
    lo = rng.integers(0, 8, (h, w))
    hi = np.minimum(n_disp, lo + 1 + np.arange(h * w).reshape(h, w) % 41)
    index, n_cells = banded_index(lo, hi)
    cost = rng.random(n_cells, dtype=np.float32)
    if levels:
        cost = np.round(cost * levels) / levels  # coarse values: many ties, some cost 1
    cost = cost.astype(np.float32)
    for pkrn_min, exclusion in [(1.0, 0), (1.2, 0), (1.1, 1), (1.05, 3)]:
        for v in range(h):
            for u in range(w):
                cells = cost[index[v, u, 0] + lo[v, u]:index[v, u, 0] + hi[v, u]]
                want = _in_order_candidate(cells, lo[v, u], u, pkrn_min, 1e-3, exclusion)
                got = cpu.ops.seed_candidate(cost, index, v, u, pkrn_min, 1e-3, exclusion)
                assert got == want, (v, u, pkrn_min, exclusion)


@pytest.mark.parametrize("curve, pkrn_min, want", [
    ([0.9, 0.2, 0.5, 0.1], 1.9, 3),   # c2 is the minimum the last cell displaced: 0.2 / 0.1
    ([0.9, 0.2, 0.5, 0.1], 2.1, -1),  # (c2 = 0.5 would pass)
    ([0.2, 0.5, 0.2, 0.9], 1.05, -1),  # two equal minima: c2 = c1, PKRN 1
    ([0.5, 0.2, 0.9, 0.9], 2.4, 1),    # c2 = 0.5, ahead of the minimum
    ([0.5, 0.2, 0.9, 0.9], 2.6, -1),
])
def test_seed_pkrn_second_cost_known_answers(curve, pkrn_min, want):
    # Naive PKRN (exclusion 0) keeps c2 in the same pass as the minimum: the
    # second cost is the least of the other cells, wherever it lies.
    cost = np.ones((1, 8, 4), np.float32)
    cost[0, 5] = curve
    assert cpu.decisive_seeds(cost, pkrn_min, 0.0, 0, 0)[0, 5] == want


# ----------------------------------------------------------------------------- min cost
def test_min_cost_matches_reference():
    rng = np.random.default_rng(14)
    cost = random_volume(rng, 7, 9, 5)
    np.testing.assert_array_equal(cpu.min_cost(cost), ref.ref_min_cost(cost))


# ----------------------------------------------------------------------------- diffusion
def run_diffusion(cost, disp, *, max_gap, tau, kappa_d, adversarial, max_sweeps=100000):
    return cpu.diffuse(cost, disp, cpu.min_cost(cost), float(max_gap), tau, kappa_d, adversarial, max_sweeps)


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_matches_whole_image_jacobi_reference(settings):
    rng = np.random.default_rng(15)
    cases = []
    for h, w in SHAPES:
        for n_disp in (1, 3, 7):
            cases.append((random_volume(rng, h, w, n_disp), sparse_map(rng, (h, w), n_disp)))
            cases.append((random_volume(rng, h, w, n_disp, levels=6), sparse_map(rng, (h, w), n_disp)))
    true = (np.arange(11)[None, :] // 5 + np.arange(13)[:, None] // 4).astype(np.int64) + 1
    for noise in (0.02, 0.3):
        cost = structured_volume(rng, true, 7, noise=noise)
        cases.append((cost, sparse_map(rng, true.shape, 7, share=0.05)))  # some seeds wrong
    for cost, disp in cases:
        before = disp.copy()
        got, sweeps = run_diffusion(cost, disp, **settings)
        want, want_sweeps = ref.ref_diffuse(cost, disp, **settings)
        np.testing.assert_array_equal(got, want, err_msg=f"{cost.shape}")
        assert sweeps == want_sweeps
        np.testing.assert_array_equal(disp, before)  # input untouched
        if not settings["adversarial"]:
            assert (got[before >= 0] == before[before >= 0]).all()


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_finding_the_least_costs_itself_matches_reference(settings):
    # min_cost None (the pipeline's call): pixel.diffuse_at finds the least
    # cost of a pixel whose candidate reaches the gap test; the maps of the reference
    rng = np.random.default_rng(27)
    for h, w in SHAPES:
        for n_disp in (1, 3, 7):
            cost = random_volume(rng, h, w, n_disp, levels=6)
            disp = sparse_map(rng, (h, w), n_disp)
            got, sweeps = cpu.diffuse(cost, disp, None, float(settings["max_gap"]), settings["tau"],
                                      settings["kappa_d"], settings["adversarial"], 100000)
            want, want_sweeps = ref.ref_diffuse(cost, disp, **settings)
            np.testing.assert_array_equal(got, want, err_msg=f"{cost.shape}")
            assert sweeps == want_sweeps


def test_diffusion_from_one_seed_fills_the_known_minimum_map():
    rng = np.random.default_rng(16)
    h, w, n_disp = 13, 17, 8
    true = np.broadcast_to((2 + np.arange(h) // 3)[:, None], (h, w)).astype(np.int64)  # road-like: d grows with v
    cost = structured_volume(rng, true, n_disp, noise=0.01)
    seeds = np.full((h, w), -1, np.int32)
    seeds[h // 2, w // 2] = true[h // 2, w // 2]
    got, sweeps = run_diffusion(cost, seeds, max_gap=-1.0, tau=1, kappa_d=1, adversarial=True)
    exists = np.arange(w)[None, :] >= true  # the true cell has a right pixel
    np.testing.assert_array_equal(got[exists], true[exists])
    want, want_sweeps = ref.ref_diffuse(cost, seeds, -1.0, 1, 1, True)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps >= max(h, w) // 2


def test_diffusion_adversarial_update_corrects_a_wrong_seed():
    h, w = 5, 9
    true = np.full((h, w), 2)
    cost = structured_volume(np.random.default_rng(17), true, 6, noise=0.0)
    seeds = np.full((h, w), -1, np.int32)
    seeds[2, 4] = 2
    seeds[2, 6] = 4  # wrong, and a local minimum of nothing: its neighbours will overrule it
    got, _ = run_diffusion(cost, seeds, max_gap=-1.0, tau=2, kappa_d=1, adversarial=True)
    assert got[2, 6] == 2
    kept, _ = run_diffusion(cost, seeds, max_gap=-1.0, tau=2, kappa_d=1, adversarial=False)
    assert kept[2, 6] == 4


def test_diffusion_without_seeds_runs_no_sweep():
    cost = random_volume(np.random.default_rng(18), 5, 7, 3)
    got, sweeps = run_diffusion(cost, np.full((5, 7), -1, np.int32), max_gap=-1.0, tau=1, kappa_d=1, adversarial=True)
    assert sweeps == 0 and (got == -1).all()


def test_diffusion_max_sweeps_safeguard_matches_truncated_reference():
    rng = np.random.default_rng(19)
    true = np.full((9, 11), 3)
    cost = structured_volume(rng, true, 6, noise=0.02)
    seeds = np.full((9, 11), -1, np.int32)
    seeds[4, 5] = 3
    for limit in (1, 2, 3):
        got, sweeps = run_diffusion(cost, seeds, max_gap=-1.0, tau=1, kappa_d=1, adversarial=True, max_sweeps=limit)
        want, _ = ref.ref_diffuse(cost, seeds, -1.0, 1, 1, True, max_sweeps=limit)
        assert sweeps == limit
        np.testing.assert_array_equal(got, want)


_diffuse_at = cpu.ops.diffuse_at


@numba.njit(cache=False)
def whole_image_jacobi(cost, index, disp0, least, max_gap, tau, kappa_d, adversarial):
    """Every pixel every sweep with ``pixel.diffuse_at`` (no frontier, no first-sweep
    special case), sweeps counted as the driver counts them."""
    disp = disp0.copy()
    h, w = disp.shape
    if not (disp >= 0).any():
        return disp, 0
    sweeps = 0
    while True:
        sweeps += 1
        new = disp.copy()
        for v in range(h):
            for u in range(w):
                new[v, u] = _diffuse_at(cost, index, disp, least, max_gap, v, u, tau, kappa_d, adversarial)
        changed = (new != disp).any()
        disp = new
        if not changed:
            return disp, sweeps


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_with_large_frontiers_matches_whole_image_jacobi(settings):
    """Frontiers above ``SERIAL_FRONTIER`` (parallel, in chunks), rows of several 64-pixel
    bitmap words plus a partial one: the frontier driver as whole-image Jacobi sweeps."""
    from d3cli.kernels.volume import dense_index

    rng = np.random.default_rng(23)
    h, w, n_disp = 96, 203, 9
    blocks = rng.integers(1, n_disp, (h // 8 + 1, w // 8 + 1))
    true = np.repeat(np.repeat(blocks, 8, 0), 8, 1)[:h, :w]
    cost = structured_volume(rng, true, n_disp, noise=0.1)
    seeds = sparse_map(rng, (h, w), n_disp, share=0.03)
    seeds[seeds >= 0] = np.where(rng.random((seeds >= 0).sum()) < 0.8, true[seeds >= 0], seeds[seeds >= 0])
    least = cpu.min_cost(cost)
    got, sweeps = cpu.diffuse(cost, seeds, least, max_sweeps=100000, **settings)
    index = dense_index(h, w, n_disp)
    args = (float(settings["max_gap"]), settings["tau"], settings["kappa_d"], settings["adversarial"])
    want, want_sweeps = whole_image_jacobi(cost.ravel(), index, seeds, least, *args)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps > 3
    first, _ = cpu.diffuse(cost, seeds, least, max_sweeps=1, **settings)
    assert (first != seeds).sum() * 3 > cpu.SERIAL_FRONTIER  # a parallel frontier follows


@numba.njit(cache=False)
def one_jacobi_sweep(cost, index, disp, max_gap, tau, kappa_d, adversarial):
    """One sweep of ``pixel.diffuse_at`` over every pixel (least costs found per pixel)."""
    least = np.empty((0, 0), np.float32)
    new = np.empty_like(disp)
    for v in range(disp.shape[0]):
        for u in range(disp.shape[1]):
            new[v, u] = _diffuse_at(cost, index, disp, least, max_gap, v, u, tau, kappa_d, adversarial)
    return new


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_first_sweep_on_plain_neighbourhoods_matches_diffuse_at(settings):
    """The first sweep settles pixels without a decided neighbour and decided pixels in
    a uniform 3x3 block without ``pixel.diffuse_at``: on maps of uniform and
    undecided blocks, over bands (the disparity sometimes outside the band), costs with
    ties and NaN cells, it gives what ``diffuse_at`` gives every pixel."""
    from d3cli.kernels.volume import Volume, banded_index

    rng = np.random.default_rng(29)
    h, w, n_disp = 37, 71, 9
    for trial in range(6):
        size = (2, 3, 5)[trial % 3]
        blocks = rng.integers(-1, n_disp, (h // size + 1, w // size + 1))
        disp = np.repeat(np.repeat(blocks, size, 0), size, 1)[:h, :w].astype(np.int32)
        disp[rng.random((h, w)) < 0.03] = -1
        lo = rng.integers(0, n_disp // 2, (h, w))
        hi = np.minimum(n_disp, lo + rng.integers(1, n_disp + 1, (h, w)))
        index, n_cells = banded_index(lo, hi)
        cost = np.floor(rng.random(n_cells) * 4).astype(np.float32) / 4  # many ties
        cost[rng.random(n_cells) < 0.02] = np.nan
        args = (float(settings["max_gap"]), settings["tau"], settings["kappa_d"], settings["adversarial"])
        got, sweeps = cpu.diffuse(Volume(cost, index, n_disp), disp, None, max_sweeps=1, **settings)
        np.testing.assert_array_equal(got, one_jacobi_sweep(cost, index, disp, *args))
        assert sweeps == 1


# ----------------------------------------------------------------------------- inheritance
def coarse_map_for(rng, shape, n_disp, share=0.7):
    h, w = shape
    coarse = rng.integers(0, (n_disp + 1) // 2, (h // 2, w // 2)).astype(np.int32)
    coarse[rng.random(coarse.shape) >= share] = -1
    return coarse


def test_inheritance_without_prc_matches_reference():
    rng = np.random.default_rng(20)
    for h, w in [(7, 9), (13, 11), (2, 12), (12, 2), (6, 6)]:
        for n_disp in (3, 5, 7):
            for levels in (None, 5):
                cost = random_volume(rng, h, w, n_disp, levels=levels)
                coarse = coarse_map_for(rng, (h, w), n_disp)
                for pkrn in (1.0, 1.05, 1.5):
                    got = cpu.inherit(cost, coarse, False, pkrn, 1e-3)
                    np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, False, pkrn, 1e-3))


def test_inheritance_with_prc_and_zero_disparity_matches_reference():
    # dc = 0: the left and right patches coincide, so this part of the PRC is pinned
    # independently of which patch each view looks at.
    rng = np.random.default_rng(21)
    for h, w in [(7, 9), (13, 11), (2, 12), (6, 6)]:
        for n_disp in (2, 5):
            cost = random_volume(rng, h, w, n_disp, levels=8)
            coarse = np.where(rng.random((h // 2, w // 2)) < 0.8, 0, -1).astype(np.int32)
            got = cpu.inherit(cost, coarse, True, 1.05, 1e-3)
            np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, True, 1.05, 1e-3))


def test_inheritance_with_prc_matches_reference():
    rng = np.random.default_rng(22)
    for h, w in [(7, 9), (13, 11), (2, 12), (12, 2), (6, 6)]:
        for n_disp in (3, 5, 7):
            for _ in range(4):
                cost = random_volume(rng, h, w, n_disp, levels=8)
                coarse = coarse_map_for(rng, (h, w), n_disp)
                got = cpu.inherit(cost, coarse, True, 1.05, 1e-3)
                np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, True, 1.05, 1e-3))


def sharp_volume(true, n_disp):
    """Cost 0.05 at the true disparity, 0.9 elsewhere, 1 where the right pixel is missing."""
    cost = np.full(true.shape + (n_disp,), 0.9, np.float32)
    v, u = np.indices(true.shape)
    cost[v, u, true] = 0.05
    return mark_missing_cells(cost)


def inside_patches(true, coarse_true):
    """Fine pixels whose left patch, right patch and outside cells all lie in the image."""
    h, w = true.shape
    v, u = np.indices((h, w))
    u0 = 2 * (u // 2)
    x0 = u0 - 2 * coarse_true[v // 2, u // 2]
    return (x0 - 2 >= 0) & (u0 + 3 < w) & (v < 2 * (h // 2))


@pytest.mark.parametrize("prc", [True, False])
def test_inheritance_of_a_perfect_coarse_map_constant_disparity(prc):
    # With the bug, columns within 2 dc of either border are dropped: the left-view PRC
    # looks at left pixels u0 - 2dc (missing cells, cost 1) and the right-view PRC at
    # C_R(u0, .) = C_L(u0 + 2dc, .) (outside the image, inf).
    h, w, n_disp = 8, 24, 10
    true = np.full((h, w), 6)
    coarse = np.full((h // 2, w // 2), 3, np.int32)
    got = cpu.inherit(sharp_volume(true, n_disp), coarse, prc, 1.05, 1e-3)
    inside = inside_patches(true, coarse)
    assert inside.sum() > 40
    np.testing.assert_array_equal(got[inside], 6)
    np.testing.assert_array_equal(got, ref.ref_inherit(sharp_volume(true, n_disp), coarse, prc, 1.05, 1e-3))


def test_inheritance_of_a_perfect_coarse_map_rejects_wrong_coarse_disparity():
    true = np.full((8, 24), 6)
    coarse = np.full((4, 12), 1, np.int32)  # 2 dc = 2: the true minimum is far outside {1, 2, 3}
    assert (cpu.inherit(sharp_volume(true, 10), coarse, True, 1.05, 1e-3) == -1).all()


def test_inheritance_of_a_perfect_coarse_map_with_a_disparity_step():
    h, w, n_disp = 6, 40, 12
    true = np.where(np.arange(w)[None, :] < 16, 2, 8) * np.ones((h, 1), int)
    coarse = (true[::2, ::2] // 2).astype(np.int32)
    got = cpu.inherit(sharp_volume(true, n_disp), coarse, True, 1.05, 1e-3)
    # Every pixel of the far plane whose patches lie inside it inherits its disparity,
    # including u in [16, 24) where the right patch u0 - 8 lies over the near plane's columns.
    u = np.broadcast_to(np.arange(w)[None, :], (h, w))
    far = (u >= 16) & (u + 3 < w)
    np.testing.assert_array_equal(got[far], 8)


# ----------------------------------------------------------------------------- sub-pixel
def test_subpixel_matches_reference():
    rng = np.random.default_rng(23)
    for h, w in SHAPES:
        for n_disp in (1, 2, 5):
            cost = random_volume(rng, h, w, n_disp, levels=None if n_disp != 5 else 4)
            disp = sparse_map(rng, (h, w), n_disp, share=0.8)
            got = cpu.subpixel(cost, disp)
            np.testing.assert_allclose(got, ref.ref_subpixel(cost, disp), rtol=0, atol=COST_ATOL)
            assert got.dtype == np.float32 and (np.isinf(got) == (disp < 0)).all()


def parabola_volume(d0, n_disp=8, a=0.02, b=0.1):
    d = np.arange(n_disp, dtype=np.float64)
    return (a * (d - d0) ** 2 + b).astype(np.float32).reshape(1, 1, n_disp)


def test_subpixel_known_answers():
    one = np.array([[3]], np.int32)
    assert cpu.subpixel(parabola_volume(3.0), one)[0, 0] == 3.0  # symmetric: exactly integer
    np.testing.assert_allclose(cpu.subpixel(parabola_volume(3.3), one)[0, 0], 3.3, atol=1e-5)
    np.testing.assert_allclose(cpu.subpixel(parabola_volume(2.75), one)[0, 0], 2.75, atol=1e-5)
    # at d = 2 the parabola through 0.1, 0.2, 0.5 has its vertex 1 px to the left: clamped to -0.5
    steep = np.array([0.9, 0.1, 0.2, 0.5, 0.9], np.float32).reshape(1, 1, 5)
    assert cpu.subpixel(steep, np.array([[2]], np.int32))[0, 0] == 1.5
    concave = np.array([0.2, 0.5, 0.2], np.float32).reshape(1, 1, 3)
    assert cpu.subpixel(concave, np.array([[1]], np.int32))[0, 0] == 1.0
    flat = np.full((1, 1, 3), 0.4, np.float32)
    assert cpu.subpixel(flat, np.array([[1]], np.int32))[0, 0] == 1.0
    ends = parabola_volume(0.3, n_disp=4)
    assert cpu.subpixel(ends, np.array([[0]], np.int32))[0, 0] == 0.0
    assert cpu.subpixel(ends, np.array([[3]], np.int32))[0, 0] == 3.0
    assert np.isinf(cpu.subpixel(ends, np.array([[-1]], np.int32))[0, 0])


# ----------------------------------------------------------------------------- pyramid
@pytest.mark.parametrize("shape", [(7, 9), (8, 8), (13, 2), (2, 13), (1, 5), (3, 3)])
def test_downsample_matches_reference(shape):
    img = np.random.default_rng(sum(shape)).uniform(0, 255, shape).astype(np.float32)
    got = downsample(img)
    assert got.shape == (shape[0] // 2, shape[1] // 2) and got.dtype == np.float32
    np.testing.assert_allclose(got, ref.ref_downsample(img), rtol=1e-6, atol=1e-4)


def test_pyramid_shapes_and_level_ranges():
    pyr = build_pyramid(np.zeros((37, 50), np.uint8), 4)
    assert [p.shape for p in pyr] == [(37, 50), (18, 25), (9, 12), (4, 6)]
    assert all(p.dtype == np.float32 for p in pyr)
    assert [level_max_disparity(37, lv) for lv in range(4)] == [37, 19, 10, 5]
    assert level_max_disparity(1, 3) == 1


# ----------------------------------------------------------------------------- hole filling
def test_fill_holes_without_smoothing_matches_reference():
    rng = np.random.default_rng(24)
    for shape in [(7, 9), (13, 11), (1, 12), (12, 1), (6, 6)]:
        for share in (0.2, 0.6, 0.95):
            disp = rng.uniform(0, 30, shape).astype(np.float32)
            valid = rng.random(shape) < share
            valid[rng.random(shape[0]) < 0.2] = False  # whole empty rows
            disp[~valid & (rng.random(shape) < 0.5)] = np.inf
            got = fill_holes(disp, valid, smooth=False)
            np.testing.assert_array_equal(got, ref.ref_fill_holes(disp, valid), err_msg=f"{shape} {share}")


def test_fill_holes_known_rows():
    inf = np.inf
    disp = np.array([[5, inf, inf, 2, 3], [inf, inf, inf, inf, inf], [inf, 7, inf, inf, inf]], np.float32)
    got = fill_holes(disp, np.isfinite(disp), smooth=False)
    np.testing.assert_array_equal(got, [[5, 2, 2, 2, 3], [5, 2, 2, 2, 3], [7, 7, 7, 7, 7]])


def test_fill_holes_smoothing_keeps_decided_pixels():
    rng = np.random.default_rng(25)
    disp = rng.uniform(0, 30, (12, 15)).astype(np.float32)
    valid = rng.random(disp.shape) < 0.5
    got = fill_holes(disp, valid, smooth=True)
    np.testing.assert_array_equal(got[valid], disp[valid])
    assert np.isfinite(got).all()


def test_fill_holes_with_nothing_valid_is_all_inf():
    got = fill_holes(np.zeros((3, 4), np.float32), np.zeros((3, 4), bool), smooth=False)
    assert np.isinf(got).all()


# ----------------------------------------------------------------------------- realistic volumes
@pytest.fixture(scope="module")
def aggregated_levels():
    """Aggregated NCC volumes of a textured slanted pair at 30x40 and 60x80 (as the pipeline makes).

    Unlike the random volumes above, the cells whose right pixel is outside the image hold
    averages below 1 here, as after RBF in the pipeline.
    """
    rng = np.random.default_rng(27)
    h, w = 60, 80
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h, w + 40)).astype(np.float32), (0, 0), 1.2)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    # d = 3 + 0.04 u + 0.02 v; right pixel x shows the left point u with u - d(u) = x
    source = (u + 3.0 + 0.02 * v) / 0.96
    x0 = np.floor(source).astype(int)
    frac = source - x0
    left = tex[:, :w].copy()
    right = ((1 - frac) * tex[v.astype(int), x0] + frac * tex[v.astype(int), x0 + 1]).astype(np.float32)
    out = []
    for img_l, img_r, dmax in ((left, right, 10), (downsample(left), downsample(right), 5)):
        cost = cpu.ncc_cost_volume(img_l, img_r, dmax, 5, 1e-2)
        out.append(cpu.rbf_filter(cost, cpu.rbf_weights(img_l, 1.5, 12.0), 4))
    return out  # [fine, coarse]


def test_seeds_on_an_aggregated_volume_match_reference(aggregated_levels):
    for cost in aggregated_levels:
        got = cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)
        np.testing.assert_array_equal(got, ref.ref_decisive_seeds(cost, 1.2, 1e-3, 1, 0))


def test_diffusion_and_inheritance_on_aggregated_volumes_match_reference(aggregated_levels):
    fine, coarse = aggregated_levels
    seeds = ref.ref_decisive_seeds(coarse, 1.2, 1e-3, 1, 0)
    assert (seeds >= 0).mean() > 0.5
    for max_gap in (-1.0, 0.05):
        got, sweeps = run_diffusion(coarse, seeds, max_gap=max_gap, tau=1, kappa_d=1, adversarial=True)
        want, want_sweeps = ref.ref_diffuse(coarse, seeds, max_gap, 1, 1, True)
        np.testing.assert_array_equal(got, want)
        assert sweeps == want_sweeps
    assert (got >= 0).mean() > 0.9
    inherited = cpu.inherit(fine, got, False, 1.05, 1e-3)
    np.testing.assert_array_equal(inherited, ref.ref_inherit(fine, got, False, 1.05, 1e-3))
    assert (inherited >= 0).mean() > 0.5
    got_fine, sweeps = run_diffusion(fine, inherited, max_gap=0.05, tau=1, kappa_d=1, adversarial=True)
    want_fine, want_sweeps = ref.ref_diffuse(fine, inherited, 0.05, 1, 1, True)
    np.testing.assert_array_equal(got_fine, want_fine)
    assert sweeps == want_sweeps


def test_inheritance_with_prc_on_an_aggregated_volume_matches_reference(aggregated_levels):
    fine, coarse = aggregated_levels
    seeds = ref.ref_decisive_seeds(coarse, 1.2, 1e-3, 1, 0)
    coarse_map, _ = run_diffusion(coarse, seeds, max_gap=0.05, tau=1, kappa_d=1, adversarial=True)
    got = cpu.inherit(fine, coarse_map, True, 1.05, 1e-3)
    np.testing.assert_array_equal(got, ref.ref_inherit(fine, coarse_map, True, 1.05, 1e-3))


# ----------------------------------------------------------------------------- determinism
def outputs_of_every_driver():
    rng = np.random.default_rng(26)
    left, right = random_images(rng, (48, 64))
    cost = cpu.ncc_cost_volume(left, right, 15, 5, 1e-2)
    weights = cpu.rbf_weights(left, 1.5, 12.0)
    agg = cpu.rbf_filter(cost, weights, 3)
    seeds = cpu.decisive_seeds(agg, 1.05, 1e-3, 1, 0)
    disp, sweeps = cpu.diffuse(agg, seeds, cpu.min_cost(agg), 0.1, 1, 1, True, 100000)
    def upsample(img):
        return np.repeat(np.repeat(img, 2, 0), 2, 1)

    fine = cpu.ncc_cost_volume(upsample(left), upsample(right), 31, 5, 1e-2)
    return {
        "cost": cost,
        "weights": weights,
        "rbf": agg,
        "bilateral": cpu.bilateral_filter(cost, left, 2, 1.5, 12.0),
        "seeds": seeds,
        "diffused": disp,
        "sweeps": np.array(sweeps),
        "inherit_prc": cpu.inherit(fine, disp, True, 1.05, 1e-3),
        "inherit_dfm": cpu.inherit(fine, disp, False, 1.05, 1e-3),
        "subpixel": cpu.subpixel(agg, disp),
    }


def test_drivers_are_bit_identical_with_one_and_all_threads():
    all_threads = numba.config.NUMBA_NUM_THREADS
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = outputs_of_every_driver()
        numba.set_num_threads(all_threads)
        multi = outputs_of_every_driver()
    finally:
        numba.set_num_threads(before)
    assert (single["seeds"] >= 0).sum() > 0 and (single["diffused"] >= 0).sum() > (single["seeds"] >= 0).sum()
    for name in single:
        assert single[name].tobytes() == multi[name].tobytes(), name


# ----------------------------------------------------------------------------- perspective transformation
@pytest.mark.parametrize("model", [(20.0, 0.1, 0.0, 4.0), (35.5, 0.08, -0.004, 8.0), (3.0, 0.02, 0.01, 2.0)])
def test_pt_warp_matches_reference(model):
    rng = np.random.default_rng(11)
    right = (rng.random((23, 41)) * 255).astype(np.float32)
    got = cpu.pt_warp(right, *model)
    np.testing.assert_allclose(got, ref.ref_pt_warp(right, *model), atol=1e-3)


def test_pt_warp_of_an_integer_shift_is_a_translation_with_replicated_border():
    right = np.tile(np.arange(30, dtype=np.float32) * 3, (5, 1))
    got = cpu.pt_warp(right, 7.0, 0.0, 0.0, 2.0)  # s = 5 everywhere
    np.testing.assert_array_equal(got[:, 5:], right[:, :-5])
    np.testing.assert_array_equal(got[:, :5], np.full((5, 5), right[0, 0]))


@pytest.mark.parametrize("model", [(20.0, 0.1, 0.0, 4.0), (35.5, 0.08, -0.004, 8.0)])
def test_pt_restore_matches_reference_and_keeps_inf(model):
    rng = np.random.default_rng(12)
    disp = (rng.random((17, 29)) * 18).astype(np.float32)
    disp[rng.random(disp.shape) < 0.2] = np.inf
    got = cpu.pt_restore(disp, *model)
    np.testing.assert_allclose(got, ref.ref_pt_restore(disp, *model), rtol=1e-6, atol=1e-4)
    np.testing.assert_array_equal(np.isinf(got), np.isinf(disp))
