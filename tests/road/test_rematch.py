"""The re-match of a defect's zone: windows sharing one set of warps give what separate calls give."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.road.rematch import MIN_RELIABLE, SHARE_GROWTH, WINDOWS, hopeless, match_margin, rematch
from tests.helpers import textured_pair
from tests.reference.road import ref_match_margin


def test_shared_warps_give_the_results_of_separate_calls():
    left, right, disparity = textured_pair(6, (120, 160), seed=3)
    disp = np.asarray(disparity, np.float32) + np.float32(0.3)
    zone = np.zeros(disp.shape, bool)
    zone[40:80, 60:110] = True
    shared = {"pad_window": max(WINDOWS)}
    for window in WINDOWS:
        alone = rematch(left, right, disp, zone, window=window)
        together = rematch(left, right, disp, zone, window=window, shared=shared)
        np.testing.assert_array_equal(alone[0], together[0])
        np.testing.assert_array_equal(alone[1], together[1])
    assert shared["warps"] is not None  # the shared path was taken
    shared = {}  # the first window's warps, smallest first: the larger windows warp their own box
    for window in WINDOWS:
        np.testing.assert_array_equal(rematch(left, right, disp, zone, window=window)[0],
                                      rematch(left, right, disp, zone, window=window, shared=shared)[0])
    holed = disp.copy()
    holed[50, 70] = np.inf  # a pixel without an estimate: each call on its own
    shared = {"pad_window": max(WINDOWS)}
    for window in WINDOWS:
        np.testing.assert_array_equal(rematch(left, right, holed, zone, window=window)[0],
                                      rematch(left, right, holed, zone, window=window, shared=shared)[0])


def _shifted_pair(texture_sigma, shape=(40, 60), d=6, seed=2):
    """A random texture (blurred by ``texture_sigma`` pixels) seen at a constant disparity."""
    import cv2
    rng = np.random.default_rng(seed)
    right = rng.uniform(0, 255, shape).astype(np.float32)
    if texture_sigma:
        right = cv2.GaussianBlur(right, (0, 0), texture_sigma)
    left = np.empty_like(right)
    left[:, d:] = right[:, :-d]
    left[:, :d] = right[:, :1]
    return left, right, np.full(shape, float(d), np.float32)


def test_match_margin_is_the_ncc_lead_of_the_disparity_over_its_neighbours():

    left, right, disp = _shifted_pair(0.0)
    region = np.zeros(disp.shape, bool)
    region[15:25, 25:40] = True
    got = match_margin(left, right, disp, region, window=7, pad=4)
    assert got == pytest.approx(ref_match_margin(left, right, disp, region, 7, 4), abs=1e-4)
    assert got > 0.8  # white noise: one pixel off is uncorrelated
    # A smooth floor (texture blurred over 4 px): one pixel off matches almost as well.
    left_s, right_s, _ = _shifted_pair(4.0)
    smooth = match_margin(left_s, right_s, disp, region, window=7, pad=4)
    assert smooth == pytest.approx(ref_match_margin(left_s, right_s, disp, region, 7, 4), abs=1e-4)
    assert 0 < smooth < 0.1
    # At a disparity one pixel off, the neighbour scores best: the margin is negative.
    assert match_margin(left, right, disp + 1, region, window=7, pad=4) < -0.5


def test_match_margin_fills_pixels_without_disparity_and_is_nan_without_any():
    left, right, disp = _shifted_pair(0.0)
    region = np.zeros(disp.shape, bool)
    region[15:25, 25:40] = True
    holes = disp.copy()
    holes[18:20, 30:33] = np.inf  # warped by the box's median disparity (6)
    assert match_margin(left, right, holes, region, window=7, pad=4) == pytest.approx(
        match_margin(left, right, disp, region, window=7, pad=4), abs=1e-6)
    assert np.isnan(match_margin(left, right, np.full(disp.shape, np.inf, np.float32), region))
    assert np.isnan(match_margin(left, right, disp, np.zeros(disp.shape, bool)))


def test_the_noise_limit_grows_with_the_depth_past_the_absolute_one():
    from d3cli.road.rematch import NOISE_M, REL_NOISE, noise_limit

    assert noise_limit(0.0) == noise_limit(0.02) == NOISE_M  # shallow: 1.5 mm
    assert noise_limit(0.06) == pytest.approx(REL_NOISE * 0.06) == pytest.approx(0.003)
    assert noise_limit(NOISE_M / REL_NOISE) == pytest.approx(NOISE_M)


def test_a_zone_too_few_of_whose_pixels_match_tries_no_larger_window():
    """Below MIN_RELIABLE / SHARE_GROWTH^(windows left) no larger window is tried; a share
    that could still grow to MIN_RELIABLE tries the next."""
    left_over = len(WINDOWS) - 1
    limit = MIN_RELIABLE / SHARE_GROWTH ** left_over
    assert hopeless(0.99 * limit, left_over) and not hopeless(1.01 * limit, left_over)
    assert hopeless(0.0, 1) and not hopeless(MIN_RELIABLE, 0)


def test_an_untextured_zone_is_matched_with_the_first_window_only(monkeypatch, tmp_path):
    from d3cli.config import RoadConfig
    from d3cli.road import outputs

    from .scene import pothole_scene

    disparity, camera, _ = pothole_scene(depth=0.08, radius=0.3)
    flat = np.full(disparity.shape, 100, np.uint8)  # no texture: no pixel matches reliably
    tried = []
    real = outputs.rematch

    def counting(*args, window, **kwargs):
        tried.append(window)
        return real(*args, window=window, **kwargs)

    monkeypatch.setattr(outputs, "rematch", counting)
    items = outputs.road_report(tmp_path, flat, disparity, np.isfinite(disparity), camera, {}, RoadConfig(),
                                right=flat, groups=frozenset())[0]
    assert [d["kind"] for d in items] == ["pothole"]
    assert tried == [WINDOWS[0]]
    assert items[0]["evidence"]["rematch_window"] == 0  # the stored map kept
