"""Step 8 (``d3cli.method.refinement``): hand-made maps with known answers.

The byte-for-byte comparison of the kernels with the NumPy/OpenCV formulation they
replaced is in ``tests/kernels/test_finishing.py``; these cases pin what the functions
mean, so that both could not share a mistake.
"""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.method.refinement import fill_holes, occluded_by_uniqueness, out_of_view, smooth_disparity

INF = np.inf


def test_uniqueness_keeps_the_nearer_claim_of_a_right_pixel():
    disp = np.full((1, 10), 1.0, np.float32)
    disp[0, 5] = 2.0  # match at column 3
    disp[0, 7] = 4.0  # match at 3 too, nearer (larger d)
    disp[0, 8] = 4.4  # match at round(3.6) = 4, alone there
    valid = np.ones(disp.shape, bool)
    # column 3 is claimed by pixels 4 (d 1), 5 (d 2) and 7 (d 4): 1 and 2 are below 4 - 1
    np.testing.assert_array_equal(np.flatnonzero(occluded_by_uniqueness(disp, valid)), [4, 5])


def test_uniqueness_tolerance_and_half_to_even_rounding():
    disp = np.zeros((1, 8), np.float32)
    valid = np.zeros((1, 8), bool)
    disp[0, 4], valid[0, 4] = 1.5, True  # 2.5 rounds to 2
    disp[0, 5], valid[0, 5] = 3.0, True  # 2
    disp[0, 6], valid[0, 6] = 3.5, True  # 2.5 rounds to 2 as well
    np.testing.assert_array_equal(np.flatnonzero(occluded_by_uniqueness(disp, valid)), [4])
    np.testing.assert_array_equal(np.flatnonzero(occluded_by_uniqueness(disp, valid, tolerance=0.25)), [4, 5])
    np.testing.assert_array_equal(np.flatnonzero(occluded_by_uniqueness(disp, valid, tolerance=2.0)), [])


def test_uniqueness_ignores_invalid_pixels():
    disp = np.array([[0.0, 0.0, 9.0, 1.0]], np.float32)  # pixel 2 would claim column 0 with 9
    valid = np.array([[True, True, False, True]])
    assert not occluded_by_uniqueness(disp, valid).any()


def test_out_of_view_flags_the_left_strip_below_the_first_sure_surface():
    disp = np.array([[1.0, 2.0, 4.5, 6.0, 5.0, 5.0, 5.0, 5.0],
                     [1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]], np.float32)
    valid = np.ones(disp.shape, bool)
    valid[0, 4] = False  # b of row 0 is the first valid value at or right of column 4: 5.0
    got = out_of_view(disp, valid, max_disparity=4)
    want = np.zeros(disp.shape, bool)
    want[0, [0, 1]] = True  # columns < 5 with d < 4; 4.5 and 6.0 stay
    np.testing.assert_array_equal(got, want)


def test_out_of_view_row_without_a_sure_surface_flags_nothing():
    disp = np.array([[1.0, 9.0, 9.0]], np.float32)
    valid = np.array([[True, False, False]])
    assert not out_of_view(disp, valid, max_disparity=1).any()


def test_fill_inside_takes_the_median_of_four_directions_unless_occluded():
    disp = np.full((5, 5), INF, np.float32)
    valid = np.zeros((5, 5), bool)
    for (v, u), value in {(2, 0): 2.0, (2, 4): 8.0, (0, 2): 4.0, (4, 2): 6.0}.items():
        disp[v, u], valid[v, u] = value, True
    occluded = np.zeros((5, 5), bool)
    got = fill_holes(disp, valid, smooth=False, occluded=occluded)
    assert got[2, 2] == 5.0  # median of 2, 8, 4, 6: the mean of the middle two
    assert got[2, 1] == 5.0  # only left 2 and right 8 exist
    assert got[2, 3] == 5.0
    assert got[0, 0] == 3.0  # right 4, down 2
    np.testing.assert_array_equal(got[1], got[0])  # empty row: the nearest row, the upper on a tie
    occluded[2, 2] = True
    assert fill_holes(disp, valid, smooth=False, occluded=occluded)[2, 2] == 2.0  # the smaller row neighbour


def test_fill_holes_known_values_and_median_only_on_filled_pixels():
    disp = np.array([[1.0, INF, INF, 7.0, INF]] * 5, np.float32)
    valid = np.isfinite(disp)
    got = fill_holes(disp, valid, smooth=False)
    np.testing.assert_array_equal(got[0], [1.0, 1.0, 1.0, 7.0, 7.0])
    smoothed = fill_holes(disp, valid, smooth=True)
    np.testing.assert_array_equal(smoothed[valid], disp[valid])  # decided pixels keep their values
    assert np.isfinite(smoothed).all()


def test_smooth_disparity_constant_residual_is_kept_exactly():
    yy, xx = np.mgrid[0:30, 0:40]
    plane = (10.0 + 0.25 * yy).astype(np.float32)
    disp = plane + np.float32(0.5)
    out = smooth_disparity(disp, np.ones(disp.shape, bool), radius=7, sigma=1.0, plane=plane)
    np.testing.assert_array_equal(out, disp)


def test_smooth_disparity_keeps_a_step_and_averages_within_each_side():
    rng = np.random.default_rng(0)
    truth = np.where(np.arange(60)[None, :] < 30, 10.0, 20.0) * np.ones((40, 1))
    noisy = (truth + rng.normal(0, 0.3, truth.shape)).astype(np.float32)
    out = smooth_disparity(noisy, np.ones(truth.shape, bool), radius=5, sigma=1.0)
    inner = (slice(6, -6), np.r_[6:24, 36:54])
    assert np.abs(out - truth)[inner].std() < 0.5 * np.abs(noisy - truth)[inner].std()
    assert np.abs(out - truth)[:, 28:32].max() < 1.5  # no blur across the 10 px step


def test_smooth_disparity_radius_zero_and_nothing_valid_return_a_copy():
    disp = np.array([[1.0, INF], [3.0, 4.0]], np.float32)
    for out in (smooth_disparity(disp, np.ones((2, 2), bool), radius=0, sigma=1.0),
                smooth_disparity(disp, np.zeros((2, 2), bool), radius=3, sigma=1.0)):
        np.testing.assert_array_equal(out, disp)
        assert out is not disp


def test_masks_of_another_shape_raise_instead_of_reading_out_of_bounds():
    disp = np.ones((4, 6), np.float32)
    small = np.ones((3, 6), bool)
    with pytest.raises(ValueError):
        occluded_by_uniqueness(disp, small)
    with pytest.raises(ValueError):
        out_of_view(disp, small, max_disparity=2)
    with pytest.raises(ValueError):
        fill_holes(disp, small)
    with pytest.raises(ValueError):
        fill_holes(disp, np.ones((4, 6), bool) & (np.arange(6) > 2), occluded=small)
    with pytest.raises(ValueError):
        smooth_disparity(disp, small, radius=2, sigma=1.0)
    with pytest.raises(ValueError):
        smooth_disparity(disp, np.ones((4, 6), bool), radius=2, sigma=1.0, plane=np.ones((4, 5), np.float32))
    with pytest.raises(ValueError):
        occluded_by_uniqueness(np.ones(6, np.float32), np.ones(6, bool))
    # a row of a plane broadcasts, as NumPy's arithmetic let it before
    row_plane = np.full((1, 6), 0.5, np.float32)
    out = smooth_disparity(disp, np.ones((4, 6), bool), radius=2, sigma=1.0, plane=row_plane)
    np.testing.assert_array_equal(out, disp)
