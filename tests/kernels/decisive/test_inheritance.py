"""Inheritance candidate sets (``inheritance.candidates``): symmetric and the paper's.

``paper`` reads eq. 6-7 of the paper literally: a pixel of the 2x2 patch tests the
disparities of its two co-row partners in the other view's patch, and the PRC compares
with the two pixels just beside that patch.  The CPU driver is compared with the NumPy
reference (tests/reference/steps.py) on random volumes; hand-made volumes with one true
disparity pin which disparities each mode can inherit.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import banded, mark_missing_cells, random_volume, structured_volume

from d3cli.kernels import cpu
from d3cli.kernels.ops import build_ops

PAPER = 1
SYMMETRIC = 0


def identity(func):
    return func


def test_candidate_sets_of_every_patch_position():
    # Pure-Python build of the per-pixel functions: the sets themselves, by hand from
    # the patch geometry (u0 even, x0 = u0 - d even, d = 2 dc).
    ops = build_ops(identity)
    d = 6
    u0 = 10
    x0 = u0 - d
    # left pixel in column 0 meets right columns x0, x0 + 1: disparities d, d - 1
    assert ops.candidate_range(u0, d, False, PAPER) == (d - 1, d + 1)
    # left pixel in column 1 meets x0, x0 + 1: disparities d + 1, d
    assert ops.candidate_range(u0 + 1, d, False, PAPER) == (d, d + 2)
    # right pixel in column 0 meets left columns u0, u0 + 1: disparities d, d + 1
    assert ops.candidate_range(x0, d, True, PAPER) == (d, d + 2)
    # right pixel in column 1: d - 1, d
    assert ops.candidate_range(x0 + 1, d, True, PAPER) == (d - 1, d + 1)
    for x in (u0, u0 + 1, x0, x0 + 1, -1, -2):
        for right in (False, True):
            assert ops.candidate_range(x, d, right, SYMMETRIC) == (d - 1, d + 2)
    # the reference agrees, outside sets included
    assert ref.ref_candidates(u0, d, False, "paper") == ((d - 1, d), (d - 2, d + 1))
    assert ref.ref_candidates(u0 + 1, d, False, "paper") == ((d, d + 1), (d - 1, d + 2))
    assert ref.ref_candidates(x0, d, True, "paper") == ((d, d + 1), (d - 1, d + 2))
    assert ref.ref_candidates(x0 + 1, d, True, "paper") == ((d - 1, d), (d - 2, d + 1))


def outside_of(literal, x, d, right_view, candidates, n_disp=20):
    """The outside disparities ``outside_cost`` reads, found with one-hot volumes."""
    found = []
    for s in range(n_disp):
        cost = np.ones((1, 40, n_disp), np.float32)
        cost[0, :, s] = 0.25
        flat = cost.ravel()
        index = np.zeros((1, 40, 3), np.int32)
        index[0, :, 0] = np.arange(40) * n_disp
        index[0, :, 2] = n_disp
        if literal.outside_cost(flat, index, 0, x, d, right_view, candidates) == np.float32(0.25):
            found.append(s)
    return found


@pytest.mark.parametrize("candidates, want", [
    (SYMMETRIC, {(14, False): [4, 8], (15, False): [4, 8], (8, True): [4, 8], (9, True): [4, 8]}),
    (PAPER, {(14, False): [4, 7], (15, False): [5, 8], (8, True): [5, 8], (9, True): [4, 7]}),
])
def test_outside_disparities(candidates, want):
    literal = ref.build_literal(identity, build_ops(identity))
    for (x, right_view), disparities in want.items():
        assert outside_of(literal, x, 6, right_view, candidates) == disparities, (x, right_view)


@pytest.mark.parametrize("prc", [True, False])
def test_paper_candidates_match_reference(prc):
    rng = np.random.default_rng(30 + prc)
    for h, w in [(7, 9), (13, 11), (2, 12), (12, 2), (6, 6)]:
        for n_disp in (3, 5, 7):
            for _ in range(3):
                cost = random_volume(rng, h, w, n_disp, levels=8)
                coarse = rng.integers(0, (n_disp + 1) // 2, (h // 2, w // 2)).astype(np.int32)
                coarse[rng.random(coarse.shape) >= 0.7] = -1
                got = cpu.inherit(cost, coarse, prc, 1.05, 1e-3, PAPER)
                want = ref.ref_inherit(cost, coarse, prc, 1.05, 1e-3, "paper")
                np.testing.assert_array_equal(got, want)


def sharp_volume(true, n_disp):
    """Cost 0.05 at the true disparity, 0.9 elsewhere, 1 where the right pixel is missing."""
    cost = np.full(true.shape + (n_disp,), 0.9, np.float32)
    v, u = np.indices(true.shape)
    cost[v, u, true] = 0.05
    return mark_missing_cells(cost)


H, W, N_DISP = 8, 32, 14
DC = 3  # coarse disparity: d = 2 dc = 6


def inherit_constant(true_disp, prc, candidates):
    true = np.full((H, W), true_disp)
    coarse = np.full((H // 2, W // 2), DC, np.int32)
    got = cpu.inherit(sharp_volume(true, N_DISP), coarse, prc, 1.05, 1e-3, candidates)
    want = ref.ref_inherit(sharp_volume(true, N_DISP), coarse, prc, 1.05, 1e-3,
                           "paper" if candidates == PAPER else "symmetric")
    np.testing.assert_array_equal(got, want)
    return got[:, 10:W - 4]  # columns whose patches and outside pixels lie in the image


@pytest.mark.parametrize("candidates", [SYMMETRIC, PAPER])
@pytest.mark.parametrize("prc", [True, False])
def test_true_disparity_2dc_is_inherited_by_both(prc, candidates):
    assert (inherit_constant(2 * DC, prc, candidates) == 2 * DC).all()


@pytest.mark.parametrize("offset", [-1, 1])
def test_odd_disparity_symmetric_inherits_everywhere(offset):
    assert (inherit_constant(2 * DC + offset, True, SYMMETRIC) == 2 * DC + offset).all()


@pytest.mark.parametrize("offset", [-1, 1])
def test_odd_disparity_paper_prc_rejects_the_patch(offset):
    # 2 dc + 1 is an in-patch partner of column 1 only; for column 0 it is an outside
    # disparity (cost 0.05), so the PRC mean (0.475) is not below the outside minimum.
    assert (inherit_constant(2 * DC + offset, True, PAPER) == -1).all()


def test_odd_disparity_paper_dfm_inherits_the_columns_that_can_reach_it():
    # Without the PRC (DFM-style PKRN in the patch): 2 dc + 1 is a candidate of the odd
    # columns only (their right partner x0 tests {d, d + 1}); the even columns see two
    # equal costs (PKRN 1 < 1.05) and stay undecided.  2 dc - 1 is the mirror case.
    got = inherit_constant(2 * DC + 1, False, PAPER)
    u = np.arange(10, W - 4)
    np.testing.assert_array_equal(got[:, u % 2 == 1], 2 * DC + 1)
    np.testing.assert_array_equal(got[:, u % 2 == 0], -1)
    got = inherit_constant(2 * DC - 1, False, PAPER)
    np.testing.assert_array_equal(got[:, u % 2 == 0], 2 * DC - 1)
    np.testing.assert_array_equal(got[:, u % 2 == 1], -1)


def test_symmetric_is_the_default_of_the_driver():
    rng = np.random.default_rng(5)
    cost = random_volume(rng, 9, 13, 6, levels=8)
    coarse = rng.integers(0, 3, (4, 6)).astype(np.int32)
    np.testing.assert_array_equal(cpu.inherit(cost, coarse, True, 1.05, 1e-3),
                                  cpu.inherit(cost, coarse, True, 1.05, 1e-3, SYMMETRIC))
    np.testing.assert_array_equal(cpu.inherit(cost, coarse, True, 1.05, 1e-3),
                                  ref.ref_inherit(cost, coarse, True, 1.05, 1e-3))


# ----------------------------------------------------------------------------- fast form
def narrow_banded_volume(rng, h, w, n_disp, *, levels=None):
    """A Volume with bands 1-7 disparities wide around a random true disparity (the fine
    levels' bands; patch windows d-2..d+2 often cross a band end), cost curves with a
    noisy minimum there; ``levels`` quantises the costs to force ties.  Returns the
    volume and the true disparities."""
    blocks = rng.integers(0, n_disp, (h // 4 + 1, w // 6 + 1))  # constant over 4x6 blocks
    true = np.minimum(np.repeat(np.repeat(blocks, 4, 0), 6, 1)[:h, :w], np.arange(w)[None, :])
    cube = structured_volume(rng, true, n_disp, noise=0.15)
    if levels:
        cube = (np.floor(cube * levels) / levels).astype(np.float32)
    lo = np.clip(true - rng.integers(0, 4, (h, w)), 0, n_disp - 1)
    hi = np.clip(true + rng.integers(1, 5, (h, w)), lo + 1, n_disp)
    return banded(cube, lo, hi), true


def test_windows_hold_the_cells_of_cost_or_inf():
    ops = build_ops(identity)
    rng = np.random.default_rng(41)
    vol, _ = narrow_banded_volume(rng, 5, 9, 8)
    for v in range(-1, 6):
        for x in range(-3, 12):
            for d in range(-1, 10):
                want = [ops.cost_or_inf(vol.cost, vol.index, v, x, d - 2 + k) for k in range(5)]
                assert list(ops.window5(vol.cost, vol.index, v, x, d)) == want
                want = [ops.right_cost_or_inf(vol.cost, vol.index, v, x, d - 2 + k) for k in range(5)]
                assert list(ops.right_window5(vol.cost, vol.index, v, x, d)) == want


@pytest.mark.parametrize("candidates", [SYMMETRIC, PAPER])
@pytest.mark.parametrize("prc", [True, False])
def test_driver_equals_the_per_pixel_functions_on_banded_volumes(prc, candidates):
    """The drivers' per-patch form (``inherit_quad``: each cell read once) decides as the
    per-pixel composition ``inherit_at`` of eq. 6-8 (best_of_three, outside_cost, ...)."""
    ops = build_ops(identity)
    literal = ref.build_literal(identity, ops)
    rng = np.random.default_rng(50 + 2 * prc + candidates)
    n_decided = 0
    for h, w, n_disp in [(10, 17, 9), (7, 12, 6), (12, 9, 13)]:
        for levels in (None, 6):
            vol, true = narrow_banded_volume(rng, h, w, n_disp, levels=levels)
            # coarse disparities near the true ones: many patches reach the pixel test
            coarse = np.clip(true[::2, ::2] // 2 + rng.integers(-1, 2, true[::2, ::2].shape), 0, None)
            coarse = coarse.astype(np.int32)
            coarse[rng.random(coarse.shape) < 0.1] = -1
            got = cpu.inherit(vol, coarse, prc, 1.05, 1e-3, candidates)
            want = np.array([[literal.inherit_at(vol.cost, vol.index, coarse, v, u, prc, 1.05, 1e-3, candidates)
                              for u in range(w)] for v in range(h)], np.int32)
            np.testing.assert_array_equal(got, want)
            n_decided += int((want >= 0).sum())
    assert n_decided > 20  # the comparison covers decided pixels, not only -1


@pytest.mark.parametrize("candidates", [SYMMETRIC, PAPER])
def test_prc_driver_shares_right_windows_along_runs_of_one_coarse_disparity(candidates):
    """The CPU driver with PRC (``cpu_inheritance.inherit_row_prc``) takes a patch's right windows
    x0 - 1, x0 from the patch before it when their coarse disparities are equal: coarse
    maps in runs (no noise), cut by undecided pixels and steps, decide as ``inherit_at``."""
    ops = build_ops(identity)
    literal = ref.build_literal(identity, ops)
    rng = np.random.default_rng(70 + candidates)
    n_decided = 0
    for h, w, n_disp in [(10, 23, 9), (9, 30, 13)]:
        for levels in (None, 6):
            vol, true = narrow_banded_volume(rng, h, w, n_disp, levels=levels)
            coarse = (true[::2, ::2] // 2).astype(np.int32)
            coarse[rng.random(coarse.shape) < 0.05] = -1
            got = cpu.inherit(vol, coarse, True, 1.05, 1e-3, candidates)
            want = np.array([[literal.inherit_at(vol.cost, vol.index, coarse, v, u, True, 1.05, 1e-3, candidates)
                              for u in range(w)] for v in range(h)], np.int32)
            np.testing.assert_array_equal(got, want)
            n_decided += int((want >= 0).sum())
    assert n_decided > 20
