"""The Numba CPU kernels against the slow references of tests/reference/steps.py: what no
single step owns (the pyramid and hole filling the kernels feed, every driver with one
thread and with all threads).  Each step's own tests live in its room
(tests/kernels/cost/, aggregation/, sgm/, decisive/, perspective/).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import random_images

from d3cli.kernels import cpu
from d3cli.method.pyramid import build_pyramid, downsample, level_max_disparity
from d3cli.method.refinement import fill_holes


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
            np.testing.assert_array_equal(got, ref.ref_fill_holes(disp, valid, smooth=False), err_msg=f"{shape} {share}")


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
