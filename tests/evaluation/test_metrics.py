"""Metrics against hand-computed values on tiny arrays (docs/design.md, 'Metrics')."""

import math

import cv2
import numpy as np
import pytest
from skimage.metrics import mean_squared_error, peak_signal_noise_ratio, structural_similarity

from d3cli.errors import InputError
from d3cli.evaluation.metrics import (
    DISPARITY_KEYS,
    MISSING_COLOUR,
    disparity_errors,
    error_map,
    pep_key,
    photometric_scores,
    warp_right_to_left,
)

INF = np.inf

# 2x3 case.  Evaluated: (0,0) gt 1, (0,1) gt 2, (1,1) gt 4, (1,2) gt 5
# ((0,2) has inf gt, (1,0) has gt 0).  Errors: 0.2, 1.0 (exactly: not > 1),
# missing -> |gt| = 4, 0.6.
GT = np.array([[1.0, 2.0, INF], [0.0, 4.0, 5.0]])
PRED = np.array([[1.2, 3.0, 7.0], [1.0, INF, 5.6]])


def jet_rgb(level):
    """RGB colour of OpenCV's JET map at a 0-255 level."""
    bgr = cv2.applyColorMap(np.array([[level]], np.uint8), cv2.COLORMAP_JET)[0, 0]
    return tuple(int(c) for c in bgr[::-1])


# ------------------------------------------------------------------ disparity_errors


def test_disparity_errors_hand_computed():
    r = disparity_errors(PRED, GT)
    assert set(r) == set(DISPARITY_KEYS)
    assert r["n_px"] == 4
    assert r["epe"] == pytest.approx((0.2 + 1.0 + 4.0 + 0.6) / 4)
    assert r["pep_0.5"] == pytest.approx(75.0)  # 1.0, 4.0, 0.6
    assert r["pep_1"] == pytest.approx(25.0)  # an error of exactly 1 is not > 1
    assert r["pep_2"] == pytest.approx(25.0)
    assert r["pep_3"] == pytest.approx(25.0)
    assert r["density"] == pytest.approx(75.0)


def test_disparity_errors_returns_plain_python_numbers():
    r = disparity_errors(PRED.astype(np.float32), GT.astype(np.float32))
    assert all(type(r[k]) is float for k in DISPARITY_KEYS if k != "n_px")
    assert type(r["n_px"]) is int


def test_mask_restricts_the_evaluated_pixels():
    mask = np.array([[True, True, True], [True, False, True]])  # drops the missing pixel
    r = disparity_errors(PRED, GT, mask=mask)
    assert r["n_px"] == 3
    assert r["epe"] == pytest.approx((0.2 + 1.0 + 0.6) / 3)
    assert r["pep_0.5"] == pytest.approx(200.0 / 3)
    assert r["pep_1"] == 0.0
    assert r["density"] == 100.0


def test_mask_of_any_dtype_nonzero_is_evaluated():
    mask = np.array([[255, 0, 0], [0, 0, 255]], dtype=np.uint8)
    r = disparity_errors(PRED, GT, mask=mask)
    assert r["n_px"] == 2
    assert r["epe"] == pytest.approx((0.2 + 0.6) / 2)


def test_nonfinite_and_nonpositive_ground_truth_is_not_evaluated():
    gt = np.array([[INF, -INF, np.nan], [-1.0, 0.0, 2.0]])
    pred = np.full((2, 3), 1.5)
    r = disparity_errors(pred, gt)
    assert r["n_px"] == 1
    assert r["epe"] == pytest.approx(0.5)
    assert r["pep_0.5"] == 0.0  # 0.5 is not > 0.5


def test_every_nonfinite_prediction_is_a_missing_estimate():
    gt = np.array([[2.0, 3.0, 4.0, 1.0]])
    pred = np.array([[INF, -INF, np.nan, -1.0]])  # -1 is an estimate (a bad one)
    r = disparity_errors(pred, gt)
    assert r["epe"] == pytest.approx((2 + 3 + 4 + 2) / 4)
    assert r["density"] == 25.0
    assert r["pep_3"] == 25.0


@pytest.mark.parametrize(
    "gt, mask",
    [
        (np.full((2, 3), INF), None),
        (np.zeros((2, 3)), None),
        (GT, np.zeros((2, 3), bool)),
    ],
)
def test_nothing_evaluable_gives_nan_and_zero_pixels(gt, mask):
    r = disparity_errors(PRED, gt, mask=mask)
    assert r["n_px"] == 0
    assert all(math.isnan(r[k]) for k in DISPARITY_KEYS if k != "n_px")


def test_custom_thresholds_name_their_columns():
    r = disparity_errors(PRED, GT, thresholds=(0.25, 4))
    assert set(r) == {"epe", "pep_0.25", "pep_4", "density", "n_px"}
    assert r["pep_0.25"] == pytest.approx(75.0)
    assert r["pep_4"] == 0.0  # the missing pixel's error is exactly 4
    assert pep_key(1.0) == "pep_1" and pep_key(0.5) == "pep_0.5"


def test_shape_mismatch_is_an_input_error():
    with pytest.raises(InputError, match=r"prediction is 2x3, ground_truth is 2x4"):
        disparity_errors(PRED, np.ones((2, 4)))
    with pytest.raises(InputError, match="mask is 3x3"):
        disparity_errors(PRED, GT, mask=np.ones((3, 3), bool))
    with pytest.raises(InputError, match=r"shape \(2, 3, 3\)"):
        disparity_errors(np.ones((2, 3, 3)), GT)


# ---------------------------------------------------------------- photometric_scores

# 2x5 warp, by hand.  Row 0: x = u - d = 0 -> 0; 0.5 -> 5; inf -> none; 1.75 -> 17.5;
# -2 -> outside.  Row 1: 0.5 -> 105; 4.5 -> outside (> W - 1); 4 -> 250 (the last
# column is inside); 0 -> 100; nan -> none.
RIGHT = np.array([[0, 10, 20, 30, 40], [100, 110, 130, 170, 250]], dtype=np.float64)
DISP = np.array([[0.0, 0.5, INF, 1.25, 6.0], [-0.5, -3.5, -2.0, 3.0, np.nan]])
WARPED = np.array([[0, 5, np.nan, 17.5, np.nan], [105, np.nan, 250, 100, np.nan]])
# Differences to the warp on the defined pixels: 1, 0, 3 / 0, 2, 4 -> MSE = 30 / 6 = 5.
LEFT = np.array([[1, 5, 99, 20.5, 7], [105, 0, 248, 96, 0]], dtype=np.float64)


def test_warp_right_to_left_by_hand():
    warped, defined = warp_right_to_left(RIGHT, DISP)
    np.testing.assert_array_equal(defined, np.isfinite(WARPED))
    np.testing.assert_allclose(warped[defined], WARPED[defined])
    assert np.isnan(warped[~defined]).all()


def test_photometric_scores_by_hand():
    r = photometric_scores(LEFT.astype(np.float32), RIGHT.astype(np.float32), DISP)
    assert r["coverage"] == pytest.approx(60.0)
    assert r["mse"] == pytest.approx(5.0)
    assert r["psnr"] == pytest.approx(10 * math.log10(255**2 / 5.0))
    assert math.isnan(r["ssim"])  # 2x5 is smaller than the 11x11 SSIM window


def constant_shift_pair(shift, height=24, width=40, seed=0):
    """Left = right shifted by ``shift`` px to the right, exact for the bilinear warp."""
    rng = np.random.default_rng(seed)
    if float(shift).is_integer():
        right = rng.uniform(0, 255, (height, width))
        left = rng.uniform(0, 255, (height, width))
        s = int(shift)
        left[:, s:] = right[:, : width - s]
    else:  # a ramp linear in u: linear interpolation reproduces it exactly
        u = np.arange(width)[None, :]
        v = np.arange(height)[:, None]
        right = 3.0 * u + 5.0 * v + 10.0
        left = 3.0 * (u - shift) + 5.0 * v + 10.0
    return left, right


@pytest.mark.parametrize("shift, first_scored_column", [(3, 3), (1.5, 2)])
def test_constant_shift_is_warped_exactly(shift, first_scored_column):
    height, width = 24, 40
    left, right = constant_shift_pair(shift, height, width)
    r = photometric_scores(left, right, np.full((height, width), shift))
    assert r["coverage"] == pytest.approx(100.0 * (width - first_scored_column) / width)
    assert r["mse"] == pytest.approx(0.0, abs=1e-20)
    assert r["psnr"] > 150 or r["psnr"] == math.inf
    assert r["ssim"] == pytest.approx(1.0, abs=1e-9)


def test_constant_integer_shift_has_zero_mse_and_infinite_psnr():
    left, right = constant_shift_pair(3)
    r = photometric_scores(left, right, np.full(left.shape, 3.0))
    assert r["mse"] == 0.0
    assert r["psnr"] == math.inf


def test_missing_estimates_reduce_coverage_exactly():
    height, width = 24, 40
    left, right = constant_shift_pair(3, height, width)
    pred = np.full((height, width), 3.0)
    pred[0, :] = np.inf
    pred[5, 10] = np.nan
    r = photometric_scores(left, right, pred)
    scored = (height - 1) * (width - 3) - 1
    assert r["coverage"] == pytest.approx(100.0 * scored / (height * width))
    assert r["mse"] == 0.0


def test_full_coverage_agrees_with_skimage():
    rng = np.random.default_rng(1)
    left = cv2.GaussianBlur(rng.uniform(0, 255, (32, 48)), (0, 0), 2.0)
    right = np.clip(left + rng.normal(0, 8, left.shape), 0, 255)
    r = photometric_scores(left.astype(np.float32), right.astype(np.float32), np.zeros(left.shape))
    left64 = left.astype(np.float32).astype(np.float64)
    right64 = right.astype(np.float32).astype(np.float64)
    _, ssim_map = structural_similarity(
        left64,
        right64,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=255,
        full=True,
    )
    assert r["coverage"] == 100.0
    assert r["mse"] == pytest.approx(mean_squared_error(left64, right64), rel=1e-12)
    psnr = peak_signal_noise_ratio(left64, right64, data_range=255)
    assert r["psnr"] == pytest.approx(psnr, rel=1e-12)
    assert r["ssim"] == pytest.approx(ssim_map.mean(), rel=1e-12)
    assert 0.0 < r["ssim"] < 1.0


def test_ssim_averages_over_scored_pixels_with_left_filled_into_holes():
    rng = np.random.default_rng(2)
    left = cv2.GaussianBlur(rng.uniform(0, 255, (30, 30)), (0, 0), 1.5)
    right = np.clip(left + rng.normal(0, 10, left.shape), 0, 255)
    pred = np.zeros(left.shape)
    pred[10:20, 10:20] = np.inf  # a hole in the middle
    filled = np.where(np.isfinite(pred), right, left)
    _, ssim_map = structural_similarity(
        left,
        filled,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=255,
        full=True,
    )
    r = photometric_scores(left, right, pred)
    assert r["coverage"] == pytest.approx(100.0 * (900 - 100) / 900)
    assert r["ssim"] == pytest.approx(ssim_map[np.isfinite(pred)].mean(), rel=1e-12)


def test_no_scored_pixel_gives_nan_and_zero_coverage():
    left = np.ones((12, 12))
    r = photometric_scores(left, left, np.full((12, 12), np.inf))
    assert r["coverage"] == 0.0
    assert math.isnan(r["mse"]) and math.isnan(r["psnr"]) and math.isnan(r["ssim"])


def test_photometric_shape_errors():
    with pytest.raises(InputError, match="left is 2x5, right is 2x4"):
        photometric_scores(LEFT, RIGHT[:, :4], DISP)
    with pytest.raises(InputError, match="to_grey"):
        photometric_scores(np.ones((4, 4, 3)), np.ones((4, 4, 3)), np.ones((4, 4)))


# ------------------------------------------------------------------------- error_map


def test_error_map_colours():
    gt = np.array([[1.0, 2.0, INF], [3.0, 4.0, 0.0]])
    pred = np.array([[1.0, 4.0, 1.0], [INF, 9.0, 1.0]])  # errors 0, 2, -, missing, 5
    rgb = error_map(pred, gt, max_error=4.0)
    assert rgb.shape == (2, 3, 3) and rgb.dtype == np.uint8
    assert tuple(rgb[0, 0]) == jet_rgb(0) == (0, 0, 128)  # no error: dark blue
    assert tuple(rgb[0, 1]) == jet_rgb(128)  # half of max_error (127.5 rounds to 128)
    assert tuple(rgb[1, 1]) == jet_rgb(255) == (128, 0, 0)  # >= max_error: saturated red
    assert tuple(rgb[0, 2]) == (0, 0, 0)  # no ground truth
    assert tuple(rgb[1, 2]) == (0, 0, 0)
    assert tuple(rgb[1, 0]) == MISSING_COLOUR  # gt but no estimate


def test_error_map_mask_blacks_out_unevaluated_pixels():
    gt = np.full((2, 2), 2.0)
    pred = np.array([[2.0, INF], [2.0, INF]])
    mask = np.array([[True, True], [False, False]])
    rgb = error_map(pred, gt, mask=mask)
    assert tuple(rgb[0, 0]) == jet_rgb(0)
    assert tuple(rgb[0, 1]) == MISSING_COLOUR
    assert not rgb[1].any()


def test_error_map_rejects_bad_max_error_and_shapes():
    with pytest.raises(InputError, match="max_error"):
        error_map(PRED, GT, max_error=0.0)
    with pytest.raises(InputError, match="ground_truth is 3x3"):
        error_map(PRED, np.ones((3, 3)))
