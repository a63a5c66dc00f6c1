"""The CPU aggregation (RBF weights and filter, plain bilateral filter) against the slow
references of tests/reference/steps.py, and the exactness of its fast paths."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import random_volume

from d3cli.kernels import cpu
from d3cli.kernels.aggregation.cpu import grey_scale
from d3cli.kernels.aggregation.cpu_rows import rbf_interior, rbf_normalise_row, rbf_pixel
from d3cli.kernels.intrinsics import store_fence, store_nt
from d3cli.method.pyramid import build_pyramid

COST_ATOL = 1e-5
SHAPES = [(7, 9), (13, 11), (1, 12), (12, 1), (1, 1), (5, 6)]


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
    # rbf_weights writes its output with store_nt (non-temporal stores, then a
    # fence): the same values, cast to the array's dtype, as plain assignments.
    @numba.njit
    def fill(out, vals):
        flat = out.reshape(-1)
        for i in range(vals.size):
            store_nt(flat, np.uint64(i), vals[i])
        store_fence()

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
    assert grey_scale(img) == scale
    other = img.copy()
    other[0, 0] = 0.3  # forces the exp path
    assert grey_scale(other) == 0
    got = cpu.rbf_weights(img, 1.5, 12.0)
    computed = cpu.rbf_weights(other, 1.5, 12.0)
    np.testing.assert_array_equal(got[2:], computed[2:])
    np.testing.assert_array_equal(got[:, 2:], computed[:, 2:])
    np.testing.assert_allclose(got, ref.ref_rbf_weights(img, 1.5, 12.0), rtol=0, atol=1e-6)


def test_grey_scale_of_an_8bit_pyramid():
    from d3cli.method.pyramid import build_pyramid

    img = np.random.default_rng(5).integers(0, 256, (64, 80)).astype(np.float32)
    assert [grey_scale(level) for level in build_pyramid(img, 5)] == [1, 4, 16, 64, 0]
    assert grey_scale(img / 257.0) == 0
    assert grey_scale(img + 256.0) == 0  # above 255


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
        rbf_pixel(exact, up, cur, 0.4, True, True, u)
    stage = np.empty_like(exact)
    assert rbf_interior(stage, up, cur, 0.4, w) == 0
    np.testing.assert_array_equal(stage[:, 1:-1], exact[:, 1:-1])
    # A quotient within a few float64 steps of a float32 rounding boundary (the midpoint
    # 0.5 + 2^-25): uncertain, so the row is redone exactly.
    up = np.zeros((4, 3))
    cur = np.zeros((4, 3))
    cur[2, 1] = 0.75  # slot 7 of pixel 1
    centre = 0.75 / (0.5 + 2.0**-25) - 0.75
    stage = np.empty((9, 3), np.float32)
    assert rbf_interior(stage, up, cur, centre, 3) > 0
    exact = np.empty((9, 3), np.float32)
    for u in range(3):
        rbf_pixel(exact, up, cur, centre, True, True, u)
    out = np.empty((3, 9), np.float32)
    rbf_normalise_row(out, up, cur, centre, True, True, stage)
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
