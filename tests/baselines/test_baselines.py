"""OpenCV SGBM baseline, hole filling and the method dispatcher."""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import textured_pair

from d3cli.baselines import fill_holes_rowwise, sgbm_disparity
from d3cli.batch import compute_pair
from d3cli.config import Config, SGBMConfig
from d3cli.errors import ConfigError

INF = np.inf


# ----------------------------------------------------------------------------- fill
def test_fill_takes_smaller_neighbour():
    disp = np.array([[5.0, INF, INF, 2.0, 3.0]], dtype=np.float32)
    valid = np.isfinite(disp)
    out = fill_holes_rowwise(disp, valid)
    np.testing.assert_array_equal(out, [[5, 2, 2, 2, 3]])
    assert out.dtype == np.float32


def test_fill_one_sided_at_row_ends():
    disp = np.array([[INF, INF, 7.0, 9.0, INF]], dtype=np.float32)
    out = fill_holes_rowwise(disp, np.isfinite(disp))
    np.testing.assert_array_equal(out, [[7, 7, 7, 9, 9]])


def test_fill_uses_valid_mask_not_values():
    disp = np.array([[1.0, 99.0, 4.0], [2.0, 2.0, 2.0]], dtype=np.float32)
    valid = np.array([[True, False, True], [True, True, True]])
    out = fill_holes_rowwise(disp, valid)
    np.testing.assert_array_equal(out, [[1, 1, 4], [2, 2, 2]])


def test_fill_rows_are_independent_and_empty_rows_stay_inf():
    disp = np.array([[INF, INF, INF], [INF, 3.0, INF]], dtype=np.float32)
    out = fill_holes_rowwise(disp, np.isfinite(disp))
    assert np.isinf(out[0]).all()
    np.testing.assert_array_equal(out[1], [3, 3, 3])


def test_fill_does_not_modify_input():
    disp = np.array([[1.0, INF, 2.0]], dtype=np.float32)
    before = disp.copy()
    fill_holes_rowwise(disp, np.isfinite(disp))
    np.testing.assert_array_equal(disp, before)


def test_fill_rejects_mismatched_shapes():
    with pytest.raises(ValueError):
        fill_holes_rowwise(np.zeros((2, 3)), np.ones((3, 2), bool))


# ----------------------------------------------------------------------------- sgbm
@pytest.mark.parametrize("colour", [False, True])
def test_sgbm_constant_shift_is_accurate(colour):
    shift = 7
    left, right, gt = textured_pair(shift, (64, 128), seed=3, colour=colour)
    res = sgbm_disparity(left, right, max_disparity=16, cfg=SGBMConfig(fill=False))
    assert res.disparity.dtype == np.float32 and res.disparity.shape == gt.shape
    assert res.valid.dtype == bool
    # Away from the borders (SGBM leaves the first numDisparities columns invalid).
    inner = np.zeros_like(res.valid)
    inner[8:-8, 40:-8] = True
    est = res.disparity[inner]
    assert np.isfinite(est).mean() > 0.95
    epe = np.abs(est[np.isfinite(est)] - shift).mean()
    assert epe < 0.5
    assert np.isinf(res.disparity[~res.valid]).all()
    assert res.timings["total"] > 0
    assert res.info["num_disparities"] == 32


def test_sgbm_fill_gives_dense_map_and_keeps_mask():
    left, right, _ = textured_pair(5, (48, 96), seed=1)
    res = sgbm_disparity(left, right, max_disparity=16, cfg=SGBMConfig(fill=True))
    assert np.isfinite(res.disparity).all()
    assert not res.valid.all()  # the left border stays marked as undecided


def test_sgbm_range_limits_estimates():
    left, right, _ = textured_pair(12, (48, 128), seed=2)
    res = sgbm_disparity(left, right, max_disparity=20, cfg=SGBMConfig(fill=False))
    finite = res.disparity[np.isfinite(res.disparity)]
    assert finite.min() >= 0 and finite.max() <= 20


def test_compute_pair_dispatch():
    left, right, _ = textured_pair(4, (32, 64))
    res = compute_pair("sgbm", Config(), left, right, max_disparity=8)
    assert res.info["method"] == "sgbm"
    res = compute_pair("pt-sgm", Config(), left, right, max_disparity=8)
    assert res.info["method"] == "pt-sgm" and "pt" in res.info
    with pytest.raises(ConfigError, match="unknown method"):
        compute_pair("nope", Config(), left, right, max_disparity=8)


# ----------------------------------------------------------------------------- pt-sgm
def road_pair(shape=(96, 200), *, a0=10.0, b1=0.2, seed=0):
    """Random-dot pair whose disparity grows towards the bottom (integer per row)."""
    rng = np.random.default_rng(seed)
    h, w = shape
    right = (rng.random((h, w)) * 255).astype(np.float32)
    right = np.clip(right, 0, 255)
    truth = np.rint(a0 + b1 * np.arange(h)).astype(int)
    left = np.stack([np.roll(row, d) for row, d in zip(right, truth)])
    return left.astype(np.uint8), right.astype(np.uint8), truth


def test_pt_sgm_recovers_a_road_ramp_with_a_narrow_search():
    left, right, truth = road_pair()
    cfg = Config()
    res = compute_pair("pt-sgm", cfg, left, right, max_disparity=48)
    assert res.info["pt"]["fallback"] is False
    assert res.info["num_disparities"] == 32  # 16 * ceil((2 * 8 + 2 + 1) / 16)
    inner = res.disparity[:, 64:]
    assert np.median(np.abs(inner - truth[:, None])) < 0.3


def test_pt_sgm_falls_back_to_plain_sgbm_with_a_warning():
    left, right, truth = road_pair(b1=-0.1, a0=30.0)
    res = compute_pair("pt-sgm", Config(), left, right, max_disparity=48)
    assert res.info["pt"]["fallback"] is True
    assert any("perspective transformation skipped" in w for w in res.warnings)
    assert res.info["num_disparities"] == 64  # the full range
