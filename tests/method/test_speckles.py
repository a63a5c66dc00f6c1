"""Speckle filter before filling (``refine.speckle_size`` / ``speckle_range``).

Known answers on hand-made maps, a breadth-first NumPy/Python reference of the region
rule, and the pipeline switch (the filter applied to the unfilled map is exactly what
``refine.speckle_size`` does inside ``D3Stereo``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from d3cli import ConfigError, D3Stereo, load_config
from d3cli.method.refinement import fill_holes, speckles
from tests.reference.finishing import ref_speckles

CONFIGS = Path(__file__).resolve().parents[2] / "d3cli" / "presets"


def ramp(h=40, w=60):
    """d = 10 + 0.3 v: a road-like plane, neighbours 0.3 px apart, constant along rows."""
    return np.repeat((10.0 + 0.3 * np.arange(h, dtype=np.float32))[:, None], w, axis=1)


def test_a_small_wrong_patch_on_a_slanted_plane_is_exactly_the_speckle():
    disp = ramp()
    disp[20:24, 30:34] += 6.0  # 16 pixels, 6 px off: a wrong minimum spread by diffusion
    valid = np.ones(disp.shape, bool)
    patch = np.zeros(disp.shape, bool)
    patch[20:24, 30:34] = True
    np.testing.assert_array_equal(speckles(disp, valid, max_size=16, max_diff=2.0), patch)
    # one pixel larger than the limit: kept; the slanted plane itself is never a speckle
    assert not speckles(disp, valid, max_size=15, max_diff=2.0).any()
    # with a range above the 6 px step the patch joins the plane: one large region
    assert not speckles(disp, valid, max_size=100, max_diff=6.5).any()
    assert not speckles(disp, valid, max_size=0, max_diff=2.0).any()


def test_the_patch_removed_and_filled_gives_the_plane_back():
    truth = ramp()
    disp = truth.copy()
    disp[20:24, 30:34] += 6.0
    valid = np.ones(disp.shape, bool)
    keep = valid & ~speckles(disp, valid, max_size=50, max_diff=2.0)
    filled = fill_holes(np.where(keep, disp, np.inf).astype(np.float32), keep, smooth=True)
    # the plane is constant along rows: row-wise filling restores it exactly
    np.testing.assert_allclose(filled, truth, atol=1e-5)


def test_holes_separate_regions_and_are_never_speckles():
    disp = np.full((10, 10), 5.0, np.float32)
    valid = np.ones(disp.shape, bool)
    valid[:, 4] = False  # a column of holes cuts the map in a 4-wide and a 5-wide part
    disp[:, 4] = 5.0  # a finite value under a hole is ignored all the same
    out = speckles(disp, valid, max_size=45, max_diff=1.0)
    expected = np.zeros(disp.shape, bool)
    expected[:, :4] = True  # 40 pixels <= 45; the right part has 50
    np.testing.assert_array_equal(out, expected)
    disp[0, 0] = np.inf  # inf is a hole even where valid says otherwise
    assert not speckles(disp, valid, max_size=45, max_diff=1.0)[0, 0]


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("max_size,max_diff", [(5, 1.0), (20, 2.0), (12, 0.75)])
def test_speckles_match_the_breadth_first_reference(seed, max_size, max_diff):
    rng = np.random.default_rng(seed)
    # piecewise-constant blocks plus small steps, on the 1/16 px grid (no rounding doubt)
    blocks = rng.integers(0, 6, size=(6, 8)).astype(np.float32) * 1.5
    disp = np.kron(blocks, np.ones((5, 5), np.float32))
    disp += np.round(rng.normal(0.0, 0.4, disp.shape) * 16) / 16
    disp = np.maximum(disp, 0).astype(np.float32)
    valid = rng.random(disp.shape) > 0.1
    expected = ref_speckles(disp, valid, max_size, max_diff)
    assert expected.any() and (valid & ~expected).any()  # both kinds occur
    np.testing.assert_array_equal(speckles(disp, valid, max_size=max_size, max_diff=max_diff), expected)


def test_speckle_keys_are_checked_and_default_off():
    cfg = load_config()
    assert cfg.refine.speckle_size == 0
    cfg = load_config(None, ["refine.speckle_size=200", "refine.speckle_range=2"])
    assert cfg.refine.speckle_size == 200 and cfg.refine.speckle_range == 2.0
    with pytest.raises(ConfigError, match="speckle_size"):
        load_config(None, ["refine.speckle_size=-1"])
    with pytest.raises(ConfigError, match="speckle_range"):
        load_config(None, ["refine.speckle_range=0"])


def test_kitti_config_turns_on_the_driving_scene_finishing():
    cfg = load_config(CONFIGS / "kitti.yaml")
    assert cfg.refine.speckle_size > 0 and cfg.refine.fill_inside and cfg.refine.smooth_radius > 0
    assert not cfg.pt.enabled


def noisy_pair(seed=4, h=64, w=96, shift=6):
    """A textured pair with a constant shift and strong noise: speckles of wrong minima."""
    rng = np.random.default_rng(seed)
    base = rng.random((h, w + shift)) * 255
    left = base[:, shift:]
    right = base[:, :w]
    left = np.clip(left + rng.normal(0, 60, left.shape), 0, 255).astype(np.float32)
    right = np.clip(right + rng.normal(0, 60, right.shape), 0, 255).astype(np.float32)
    return left, right


def test_pipeline_switch_is_the_filter_applied_to_the_unfilled_map():
    left, right = noisy_pair()
    # the final smoothing off: it would change the values the speckle filter leaves
    plain = D3Stereo(load_config(None, ["run.backend=cpu", "refine.fill=false", "refine.smooth_radius=0"])).compute(
        left, right, max_disparity=16)
    cut = D3Stereo(load_config(None, ["run.backend=cpu", "refine.fill=false", "refine.smooth_radius=0",
                                      "refine.speckle_size=30",
                                      "refine.speckle_range=1"])).compute(left, right, max_disparity=16)
    speck = speckles(plain.disparity, plain.valid, max_size=30, max_diff=1.0)
    assert speck.any()  # the noisy pair has speckles to remove
    np.testing.assert_array_equal(cut.valid, plain.valid & ~speck)
    np.testing.assert_array_equal(cut.disparity, np.where(cut.valid, plain.disparity, np.inf).astype(np.float32))
    assert cut.info["speckle_share"] == pytest.approx(speck.mean())
