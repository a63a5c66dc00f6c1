"""Benchmark figures on small maps whose results are worked out by hand from the benchmarks' code.

KITTI: the devkit (devkit/cpp/io_disp.h ``interpolateBackground``, evaluate_scene_flow.cpp
``disparityErrorsOutlier``) fills the holes of a map (each row's gaps with the smaller
neighbour, the row ends with the first/last estimate, empty top/bottom rows with the nearest
filled row; an empty row between filled rows stays -1), then counts |gt - d| > 3 and
|gt - d| / gt > 5 % over disp_occ (all) and over disp_noc with disp_noc's own values (noc).

Middlebury: the SDK's evaldisp.cpp leaves holes (INFINITY) out of the errors: bad-x =
valid estimates with err > x over all evaluated pixels, invalid = holes over all, avgErr =
mean err over the valid estimates; valid estimates are clipped to [0, maxdisp].
"""

import math

import numpy as np
import pytest

from d3cli.evaluation.metrics import benchmark_metrics, interpolate_background

INF, NAN = np.inf, np.nan

# disp_occ (all): left half at 20 px, right half at 10 px, one pixel at 80 px.
GT_OCC = np.array([
    [20.0, 20.0, 20.0, 10.0, 10.0, 10.0],
    [80.0, 20.0, 20.0, 10.0, 10.0, 10.0],
    [20.0, 20.0, 20.0, 10.0, 10.0, 10.0],
    [20.0, 20.0, 20.0, 10.0, 10.0, 10.0],
])
# disp_noc: occluded (0) at the end of row 0, and its own value 24 at (2, 0) where disp_occ has 20.
GT_NOC = np.array([
    [20.0, 20.0, 20.0, 0.0, 0.0, 0.0],
    [80.0, 20.0, 20.0, 10.0, 10.0, 10.0],
    [24.0, 20.0, 20.0, 10.0, 10.0, 10.0],
    [20.0, 20.0, 20.0, 10.0, 10.0, 10.0],
])

# A sparse map: holes are inf, nan and values <= 0 (0 in KITTI's PNG).
SPARSE = np.array([
    [INF, 20.0, INF, INF, 10.0, -2.0],
    [INF, INF, INF, INF, INF, INF],  # an empty row between filled rows
    [20.0, 0.0, 14.0, NAN, INF, 10.0],
    [INF, INF, INF, INF, INF, INF],  # an empty bottom row
])
# The devkit's fill, by hand:
#   row 0: (0) left of the first estimate -> 20; (2, 3) between 20 and 10 -> min = 10; (5) right of the last -> 10
#   row 1: no estimate, between filled rows: stays -1
#   row 2: (1) between 20 and 14 -> 14; (3, 4) between 14 and 10 -> 10
#   row 3: below the last filled row: a copy of row 2
SPARSE_FILLED = np.array([
    [20.0, 20.0, 10.0, 10.0, 10.0, 10.0],
    [-1.0, -1.0, -1.0, -1.0, -1.0, -1.0],
    [20.0, 14.0, 14.0, 10.0, 10.0, 10.0],
    [20.0, 14.0, 14.0, 10.0, 10.0, 10.0],
])


def test_the_devkit_fill_of_a_sparse_map():
    np.testing.assert_array_equal(interpolate_background(SPARSE), SPARSE_FILLED)


def test_the_devkit_fill_of_rows_above_the_first_filled_row_and_of_an_empty_map():
    pred = np.full((3, 4), INF)
    pred[1, 1], pred[1, 2] = 7.0, 5.0
    # Row 1: (0) -> 7, (3) -> 5; rows 0 and 2 copy row 1.
    np.testing.assert_array_equal(interpolate_background(pred), np.tile([7.0, 7.0, 5.0, 5.0], (3, 1)))
    np.testing.assert_array_equal(interpolate_background(np.full((2, 3), NAN)), np.full((2, 3), -1.0))


def test_kitti_d1_of_a_sparse_map_is_the_devkits():
    r = benchmark_metrics(SPARSE, GT_OCC, noc_mask=GT_NOC > 0, noc_gt=GT_NOC)
    # all (24 pixels of disp_occ), errors |gt - filled|:
    #   row 0: 0 0 10 0 0 0       -> (0, 2): 10 > 3 and 10/20 > 5 %           1 outlier
    #   row 1: 81 21 21 11 11 11  -> d = -1 everywhere                       6
    #   row 2: 0 6 6 0 0 0        -> 6 > 3, 6/20 > 5 %                        2
    #   row 3: 0 6 6 0 0 0                                                    2
    assert r["d1_all"] == pytest.approx(100.0 * 11 / 24)
    # noc (21 pixels of disp_noc > 0, scored against disp_noc's values):
    #   row 0: (0..2) 0 0 10 -> 1; row 1: 6; row 2: |24 - 20| = 4 > 3, 4/24 > 5 % -> 1 + 2 = 3; row 3: 2
    assert r["d1_noc"] == pytest.approx(100.0 * 12 / 21)
    assert (r["n_px_all"], r["n_px_noc"]) == (24, 21)


def test_kitti_d1_of_a_dense_map_is_the_devkits():
    pred = GT_OCC.copy()
    pred[0, 0] = 23.5  # e = 3.5 > 3 and 3.5/20 > 5 %: an outlier
    pred[1, 0] = 76.0  # e = 4 > 3 but 4/80 = 5 %, not more: no outlier
    pred[1, 3] = 13.0  # e = 3, not more than 3: no outlier
    pred[3, 5] = 6.0  # e = 4 > 3 and 40 %: an outlier
    r = benchmark_metrics(pred, GT_OCC, noc_mask=GT_NOC > 0, noc_gt=GT_NOC)
    assert r["d1_all"] == pytest.approx(100.0 * 2 / 24)
    # noc: (0, 0) and (3, 5) as above, and (2, 0): d = 20 against disp_noc's 24 (e = 4, 16.7 %).
    assert r["d1_noc"] == pytest.approx(100.0 * 3 / 21)


def test_kitti_d1_bg_fg_use_the_filled_map():
    obj = np.zeros(GT_OCC.shape, np.uint8)
    obj[2:, :3] = 1  # foreground: rows 2-3, columns 0-2 (errors 0 6 6 in each row)
    r = benchmark_metrics(SPARSE, GT_OCC, object_map=obj)
    assert r["d1_fg"] == pytest.approx(100.0 * 4 / 6)
    assert r["d1_bg"] == pytest.approx(100.0 * 7 / 18)  # row 0: 1, row 1: 6


def test_without_disp_noc_values_the_noc_pixels_are_scored_against_the_ground_truth():
    # A mask (Middlebury mask0nocc) has no values of its own: gt inside the mask.
    r = benchmark_metrics(SPARSE, GT_OCC, noc_mask=GT_NOC > 0)
    assert r["d1_noc"] == pytest.approx(100.0 * 11 / 21)  # (2, 0) scores against 20: no outlier


# Middlebury: one row, gt unknown (inf) at column 4.
MB_GT = np.array([[1.0, 2.0, 3.0, 4.0, INF, 5.0]])
MB_PRED = np.array([[1.25, INF, 5.0, -1.0, 7.0, NAN]])


def test_middlebury_figures_leave_holes_out_as_the_sdk_does():
    r = benchmark_metrics(MB_PRED, MB_GT)
    # n = 5 evaluated (gt known); holes at columns 1 (inf) and 5 (nan): invalid = 2/5.
    # Valid estimates: 1.25 (err 0.25), 5 (err 2), -1 clipped to 0 (err 4).
    assert r["n_px_all"] == 5
    assert r["invalid_all"] == pytest.approx(40.0)
    assert r["bad_0.5_all"] == pytest.approx(40.0)  # 2 and 4, over all 5 pixels
    assert r["bad_1_all"] == pytest.approx(40.0)
    assert r["bad_2_all"] == pytest.approx(20.0)  # 2 is not more than 2
    assert r["bad_4_all"] == pytest.approx(0.0)  # 4 is not more than 4
    assert r["avgerr_all"] == pytest.approx(6.25 / 3)  # over the 3 valid estimates
    assert r["rms_all"] == pytest.approx(math.sqrt((0.0625 + 4 + 16) / 3))
    assert r["a50_all"] == pytest.approx(2.0)  # sorted 0.25 2 4: index ceil(1.5) - 1 = 1
    assert r["a90_all"] == pytest.approx(4.0)
    assert math.isnan(r["bad_2_noc"]) and r["n_px_noc"] == 0


def test_middlebury_maxdisp_clips_valid_estimates():
    r = benchmark_metrics(MB_PRED, MB_GT, max_disparity=3)
    # 5 -> 3 (err 0): bad-0.5 is the 0 px estimate alone.
    assert r["bad_0.5_all"] == pytest.approx(20.0)
    assert r["avgerr_all"] == pytest.approx(4.25 / 3)


def test_middlebury_figures_inside_a_mask_and_without_any_estimate():
    mask = np.array([[1, 1, 0, 1, 1, 0]], bool)  # evaluated: columns 0, 1, 3 (4 has no gt)
    r = benchmark_metrics(MB_PRED, MB_GT, noc_mask=mask)
    assert r["n_px_noc"] == 3
    assert r["invalid_noc"] == pytest.approx(100.0 / 3)
    assert r["bad_2_noc"] == pytest.approx(100.0 / 3)  # err 4 at column 3
    assert r["avgerr_noc"] == pytest.approx(4.25 / 2)
    empty = benchmark_metrics(np.full((1, 6), INF), MB_GT)
    assert empty["invalid_all"] == pytest.approx(100.0) and empty["bad_0.5_all"] == 0.0
    assert math.isnan(empty["avgerr_all"]) and math.isnan(empty["a50_all"])
    # D1 of a map without any estimate: every pixel d = -1, outlier when gt + 1 > 3.
    assert empty["d1_all"] == pytest.approx(100.0 * 3 / 5)  # gt 3, 4, 5
