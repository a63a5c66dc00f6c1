"""Pictures: robust range, KITTI log colouring, overlay, panel layout."""

import numpy as np
import pytest

from d3cli.data.formats import colorize_disparity
from d3cli.evaluation import pictures


def test_robust_range_ignores_outliers_and_invalid():
    disp = np.concatenate([np.linspace(10, 20, 1000), [1e4, np.inf, np.nan]])[None, :]
    lo, hi = pictures.robust_range(disp)
    assert lo == pytest.approx(np.percentile(disp[np.isfinite(disp)], 1))
    assert hi < 30  # the 1e4 outlier does not flatten the colours


def test_kitti_colours_follow_the_devkit_rule():
    gt = np.array([[10.0, 10.0, 100.0, 100.0, np.inf]])
    pred = gt + np.array([[0.1, 3.5, 4.0, 80.0, 0.0]])
    rgb = pictures.kitti_error_image(pred, gt, noc_mask=np.array([[1, 1, 1, 0, 1]]))
    # n = min(e/3, 20 e/gt): 0.0333 -> bin 0; 1.1667 -> bin 5; min(1.333, 0.8) -> bin 4
    assert tuple(rgb[0, 0]) == (49, 54, 149)
    assert tuple(rgb[0, 1]) == (254, 224, 144)
    assert tuple(rgb[0, 2]) == (224, 243, 248)
    assert tuple(rgb[0, 3]) == tuple(c // 2 for c in (165, 0, 38))  # n = 16: last bin, occluded: halved
    assert tuple(rgb[0, 4]) == (0, 0, 0)


def test_disparity_picture_has_a_bar_and_turbo_ends():
    disp = np.tile(np.linspace(0, 50, 200, dtype=np.float32), (40, 1))
    pic = pictures.disparity_picture(disp, 0.0, 50.0, how="fixed range")
    assert pic.shape[0] > 40 and pic.shape[1] == 200
    np.testing.assert_array_equal(pic[:40], colorize_disparity(disp, 0.0, 50.0))


def test_overlay_marks_filled_pixels_red():
    left = np.full((4, 4), 100, np.uint8)
    valid = np.ones((4, 4), bool)
    valid[0, 0] = False
    out = pictures.validity_overlay(left, valid)
    assert tuple(out[1, 1]) == (100, 100, 100)
    assert out[0, 0, 0] > out[0, 0, 1] and out[0, 0, 0] > 150


def test_panel_puts_tiles_side_by_side():
    tiles = [("a", np.zeros((50, 100, 3), np.uint8)), ("b", np.zeros((20, 40), np.uint8))]
    out = pictures.panel("title", tiles, tile_width=64)
    assert out.shape[1] == 64 * 2 + 6 and out.dtype == np.uint8


@pytest.mark.filterwarnings("error")
def test_values_near_the_float32_limit_give_pictures_and_no_warning():
    big = np.float32(3e38)
    gt = np.full((4, 6), big, np.float32)
    pred = gt.copy()
    pred[0] = 1.0  # error ~3e38: n = min(e / 3, 20 e / gt) = 20 -> the last bin
    pred[1] = -big  # error ~6e38, beyond float32
    rgb = pictures.kitti_error_image(pred, gt, noc_mask=np.ones(gt.shape))
    assert tuple(rgb[0, 0]) == tuple(rgb[1, 0]) == (165, 0, 38)
    assert tuple(rgb[2, 0]) == (49, 54, 149)  # exact
    assert pictures.error_picture(pred, gt).shape[1] == 6


@pytest.mark.filterwarnings("error")
def test_a_constant_map_of_3e38_gets_a_range_and_a_picture():
    disp = np.full((8, 10), 3e38, np.float32)
    lo, hi = pictures.robust_range(disp)
    assert lo == float(np.float32(3e38)) and hi == pytest.approx(lo * (1 + 1e-6)) and hi > lo
    pic = pictures.disparity_picture(disp, lo, hi, how="1-99th percentile")
    assert tuple(pic[0, 0]) == tuple(colorize_disparity(np.zeros((1, 1)), 0.0, 1.0)[0, 0])  # the low end
    near_max = np.full((2, 2), np.finfo(np.float32).max, np.float32)
    lo, hi = pictures.robust_range(near_max)
    assert hi == float(np.finfo(np.float32).max) and lo < hi


@pytest.mark.filterwarnings("error")
def test_a_range_wider_than_float32_colours_without_overflow():
    disp = np.array([[-3e38, 0.0, 3e38, np.inf]], np.float32)
    pic = pictures.disparity_picture(disp, -3e38, 3e38, how="fixed range")
    turbo = colorize_disparity(np.array([[0.0, 0.5, 1.0]]), 0.0, 1.0)[0]
    np.testing.assert_array_equal(pic[0, :3], turbo)
    assert tuple(pic[0, 3]) == (0, 0, 0)


@pytest.mark.filterwarnings("error")
def test_a_narrow_range_over_huge_values_colours_without_overflow():
    disp = np.array([[3e38, 10.0, 10.25, 10.5]], np.float32)
    pic = pictures.disparity_picture(disp, 10.0, 10.5, how="fixed range")
    np.testing.assert_array_equal(pic[0, :4], colorize_disparity(np.array([[1.0, 0.0, 0.5, 1.0]]), 0.0, 1.0)[0])
