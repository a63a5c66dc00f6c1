"""The Gaussian range smoothing (``d3cli.kernels.finishing.smoothing``, through
``d3cli.method.refinement.smooth_disparity``) against the piecewise-linear bilateral filter
with one pair of ``cv2.boxFilter`` calls per range level: box radii 1 and 2 (OpenCV sums 3
and 5 taps directly) and larger, more than 256 range levels (wider level spacing, several
level groups); with the plane map and the clamp of negative values.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from d3cli.kernels import finishing
from d3cli.method.refinement import smooth_disparity

from tests.reference.finishing import (SHAPES, assert_same_bytes, assert_same_smoothing, random_map, ref_shift_plane,
                                       ref_smooth_disparity)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("radius", [1, 2, 3, 7])
def test_smooth_disparity_matches_reference(shape, radius):
    rng = np.random.default_rng(hash((shape, radius)) % 2**32)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    plane = (3.0 + 0.3 * xx + 0.2 * yy).astype(np.float32)
    for share, sigma, with_plane in ((1.0, 1.5, True), (0.8, 0.5, False), (0.5, 2.0, True), (0.0, 1.0, False)):
        disp = (plane + rng.normal(0, 1.5, shape) + 6 * (xx > w // 2)).astype(np.float32)
        valid = rng.random(shape) < share
        disp[rng.random(shape) < 0.1] = np.inf  # no estimate: stays, never averaged
        kw = dict(radius=radius, sigma=sigma, plane=plane if with_plane else None)
        got = smooth_disparity(disp, valid, **kw)
        want = ref_smooth_disparity(disp, valid, **kw)
        assert_same_smoothing(got, want, f"{shape} radius={radius} share={share} sigma={sigma}")


@pytest.mark.parametrize("radius", [2, 15])
def test_smooth_disparity_many_levels_matches_reference(radius):
    """A range of 1000 px at sigma 1: 257 levels spaced wider than sigma, filtered in
    several groups; a few pixels far below the rest (denormal and zero weights)."""
    rng = np.random.default_rng(radius)
    disp = (rng.random((37, 53)) * 1000).astype(np.float32)
    disp[5, 5] = -3000.0
    disp[6, 6] = 1e-30
    valid = rng.random(disp.shape) < 0.9
    got = smooth_disparity(disp, valid, radius=radius, sigma=1.0)
    assert_same_smoothing(got, ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0))


def test_smooth_disparity_on_a_road_like_map_matches_reference():
    """A 96x160 slanted road with noise and a pothole, radius 15, sigma 1.5 (configs/road.yaml)."""
    rng = np.random.default_rng(11)
    yy, xx = np.mgrid[0:96, 0:160]
    plane = (20.0 + 0.4 * yy - 0.05 * xx).astype(np.float32)
    disp = (plane + rng.normal(0, 0.6, plane.shape)).astype(np.float32)
    disp[40:60, 70:100] -= 3.0
    valid = np.isfinite(disp)
    got = smooth_disparity(disp, valid, radius=15, sigma=1.5, plane=plane)
    assert_same_smoothing(got, ref_smooth_disparity(disp, valid, radius=15, sigma=1.5, plane=plane))


def test_range_levels_flags_rows_and_zeroes_the_shares_of_nan_residuals():
    """The levels of the reference's clip(floor(pos)) per row; a NaN residual has none
    (INT32_MIN) and its shares, which no level writes, are set to 0; others untouched."""
    rng = np.random.default_rng(3)
    resid = (rng.random((9, 14)) * 6).astype(np.float32)
    resid[4, 5] = np.nan
    low = np.full(resid.shape, 7.0, np.float32)
    up = low.copy()
    used, row_lower = finishing.range_levels(resid, np.float32(0.5), np.float32(1.5), 5, low, up)
    with np.errstate(invalid="ignore"):
        k0 = np.clip(np.floor((resid - np.float32(0.5)) / np.float32(1.5)), 0, 3).astype(np.int32)
    want = np.zeros((9, 5), bool)
    for y, u in zip(*np.nonzero(~np.isnan(resid))):
        want[y, k0[y, u]] = True
    np.testing.assert_array_equal(row_lower, want)
    np.testing.assert_array_equal(used, want.any(axis=0) | np.r_[False, want.any(axis=0)[:-1]])
    assert low[4, 5] == 0 and up[4, 5] == 0
    assert (np.delete(low.ravel(), 4 * 14 + 5) == 7).all() and (np.delete(up.ravel(), 4 * 14 + 5) == 7).all()


@pytest.mark.parametrize("max_group", [1, 2, 3, 5])
@pytest.mark.parametrize("radius", [1, 2, 6])
def test_smooth_groups_of_any_size_match_the_reference(max_group, radius):
    """Levels grouped one, two (one pair of running sums), three (a pair and a single) or
    five to a task give the reference's bytes; so does every thread count (below)."""
    rng = np.random.default_rng(100 * max_group + radius)
    yy, xx = np.mgrid[0:41, 0:67]
    plane = (5.0 + 0.2 * yy + 0.03 * xx).astype(np.float32)
    disp = (plane + rng.normal(0, 2.0, plane.shape) + 5 * (xx > 30)).astype(np.float32)
    valid = rng.random(disp.shape) < 0.85
    disp[rng.random(disp.shape) < 0.05] = np.inf
    want = ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0, plane=plane)
    base = plane
    grid = _unit_levels(disp, base, valid)
    assert len(grid["levels"]) >= 6
    low, up = grid["low"], grid["up"]
    finishing.smooth_groups(*grid["args"], np.float32(-0.5), radius, low, up, max_group=max_group)
    assert_same_smoothing(finishing.combine_shares(low, up, base, disp), want, f"group {max_group}")


def _unit_levels(disp, base, valid):
    """The steps before :func:`d3cli.kernels.finishing.smoothing.smooth_groups` with range levels 1.0 apart: the
    residuals, the used levels, the share maps (zeroed where no level writes) and the
    arguments of smooth_groups up to ``neg_inv2s2``."""
    resid, use, row_lo, row_hi, _ = finishing.residual_and_range(disp, base, valid)
    lo, hi = float(row_lo.min()), float(row_hi.max())
    n_levels = int(np.floor(hi - lo)) + 2
    low, up = np.empty(disp.shape, np.float32), np.empty(disp.shape, np.float32)
    used, row_lower = finishing.range_levels(resid, np.float32(lo), np.float32(1.0), n_levels, low, up)
    levels = np.flatnonzero(used)
    values = np.array([lo + int(k) * 1.0 for k in levels], np.float64).astype(np.float32)
    args = (resid, use, np.float32(lo), np.float32(1.0), n_levels, levels, values, row_lower)
    return {"levels": levels, "row_lower": row_lower, "low": low, "up": up, "args": args}


@pytest.mark.parametrize("max_group", [1, 2, 4])
@pytest.mark.parametrize("radius", [2, 7, 15])
def test_smooth_groups_stop_each_level_after_its_last_row(max_group, radius):
    """A ramp down the rows: each level is used by a band of rows only, so the levels stop
    at different rows (the running sums of the rows above still count) and rows outside
    a level's band store no share; the tasks' groups split the rows unevenly.  The
    reference's bytes with one thread and with all."""
    rng = np.random.default_rng(radius)
    yy, xx = np.mgrid[0:80, 0:45]
    disp = (2.0 + 0.15 * yy + rng.normal(0, 0.4, yy.shape)).astype(np.float32)
    disp[30:38, 10:20] += 6.0  # a bump: levels used by a few rows in the middle only
    disp[rng.random(disp.shape) < 0.05] = np.inf
    valid = rng.random(disp.shape) < 0.9
    want = ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0)
    base = np.zeros(disp.shape, np.float32)
    grid = _unit_levels(disp, base, valid)
    levels, row_lower, low, up = grid["levels"], grid["row_lower"], grid["low"], grid["up"]
    last = [np.flatnonzero(row_lower[:, k] | (row_lower[:, k - 1] if k else False)).max() for k in levels]
    assert len(levels) >= 6 and min(last) < 40
    before = numba.get_num_threads()
    try:
        for n in sorted({1, before}):
            numba.set_num_threads(n)
            shares = low.copy(), up.copy()  # each run fills copies of the same maps
            finishing.smooth_groups(*grid["args"], np.float32(-0.5), radius, *shares, max_group=max_group)
            got = finishing.combine_shares(*shares, base, disp)
            assert_same_smoothing(got, want, f"group {max_group}, {n} threads")
    finally:
        numba.set_num_threads(before)


@pytest.mark.parametrize("kernel", ["gaussian", "box"])
def test_smoothing_without_a_validity_map_uses_every_finite_pixel(kernel):
    rng = np.random.default_rng(12)
    disp, _ = random_map(rng, (31, 45), spread=10)
    plane = (rng.random(disp.shape) * 4 - 2).astype(np.float32)
    for p in (None, plane):
        want = smooth_disparity(disp, np.isfinite(disp), radius=3, sigma=1.5, plane=p, kernel=kernel)
        assert_same_bytes(smooth_disparity(disp, None, radius=3, sigma=1.5, plane=p, kernel=kernel), want, kernel)


@pytest.mark.parametrize("kernel", ["gaussian", "box"])
def test_smoothing_non_negative_is_the_clamp_after_it(kernel):
    """``non_negative`` clamps in the smoothing's last pass: the bytes of clamp_negative
    after it (a plane below zero, -0, -inf, NaN and holes included)."""
    rng = np.random.default_rng(21)
    disp, valid = random_map(rng, (33, 47), spread=3)
    plane = (rng.random(disp.shape) * 4 - 3).astype(np.float32)
    disp = (disp - 2.5).astype(np.float32)
    disp[rng.random(disp.shape) < 0.05] = -0.0
    disp[rng.random(disp.shape) < 0.03] = -np.inf
    disp[rng.random(disp.shape) < 0.03] = np.nan
    for p in (None, plane):
        plain = smooth_disparity(disp, valid, radius=3, sigma=1.5, plane=p, kernel=kernel)
        assert (plain < 0).any()
        got = smooth_disparity(disp, valid, radius=3, sigma=1.5, plane=p, kernel=kernel, non_negative=True)
        assert_same_bytes(got, finishing.clamp_negative(plain.copy()), kernel)
    got = smooth_disparity(disp, valid, radius=0, sigma=1.5, kernel=kernel, non_negative=True)
    assert_same_bytes(got, finishing.clamp_negative(disp.copy()), "radius 0")


def test_shift_plane_and_clamp_match_the_numpy_formulation():
    for a0, b1, b2 in ((3.25, 0.0137, -0.00211), (-40.1, 0.1, 0.3), (0.0, 1e-7, -1e-9)):
        for margin in (0.0, 8.0):
            want = ref_shift_plane(a0, b1, b2, margin, (31, 47)).astype(np.float32)
            assert_same_bytes(finishing.shift_plane_f32(a0, b1, b2, margin, (31, 47)), want)
    a = np.array([[-1.0, -0.0, 0.0, np.nan, -np.inf, np.inf, 2.5, -1e-30]], np.float32)
    with np.errstate(invalid="ignore"):
        want = np.where(a < 0, np.float32(0.0), a)
    assert_same_bytes(finishing.clamp_negative(a.copy()), want)



@pytest.mark.parametrize("kernel", ["gaussian", "box"])
def test_smooth_map_is_the_pipelines_host_smoothing(kernel):
    """The backends' ``smooth_map`` on the CPU: the bytes of ``smooth_disparity`` with every
    finite pixel, the road plane from ``shift_plane_f32`` (zero margin) and the clamp, as
    ``D3Stereo._finish_on_host`` calls it; radius 0 a clamped copy."""
    rng = np.random.default_rng(5)
    disp, _ = random_map(rng, (23, 31), spread=8)
    disp = (disp - 1.0).astype(np.float32)
    coeffs = (2.4318944124307853, 0.0023954565662561485, 0.03496307423530236)
    for plane in (None, coeffs):
        p = None if plane is None else finishing.shift_plane_f32(*plane, 0.0, disp.shape)
        for radius in (0, 3):
            want = smooth_disparity(disp, None, radius=radius, sigma=1.5, plane=p, kernel=kernel, non_negative=True)
            assert_same_bytes(finishing.smooth_map(disp, radius, 1.5, kernel, plane, True), want, f"{plane} {radius}")
    with pytest.raises(ValueError, match="gaussian or box"):
        finishing.smooth_map(disp, 3, 1.5, "median", None, True)
