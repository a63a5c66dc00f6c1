"""A scene the coarse road fit accepts but that is not a road: rejected after the
narrow-range match (``pt.max_band_end_share``) and matched over the full range."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from d3cli import D3Stereo, load_config
from d3cli.errors import ConfigError
from d3cli.method.perspective import RoadModel, band_end_share

SHAPE = (96, 160)


def plane_and_block_pair(block: bool):
    """(left, right, truth): a textured plane whose integer disparity grows downwards
    (4 at the top row to 15 at the bottom, a road's gradient), and with ``block`` a box
    over 20 % of the image 12 px nearer than the plane: the coarse fit still takes the
    plane (75 % inliers), the box lies outside the narrow band of +-8 px.

    The texture is smoothed (Gaussian, sigma 2 px) as natural images are: the cost of an
    off-band surface then falls towards its true disparity, so its pixels match at the
    band's end (on white noise they match anywhere inside the band).
    """
    rng = np.random.default_rng(5)
    h, w = SHAPE
    right = cv2.GaussianBlur((rng.random((h, w)) * 255).astype(np.float32), (0, 0), 2.0)
    right = (right - right.min()) / (right.max() - right.min()) * 255
    truth = np.repeat((4 + np.arange(h) * 12 // h)[:, None], w, axis=1)
    if block:
        truth[20:68, 60:124] += 12
    u = np.arange(w)[None, :] - truth
    left = np.take_along_axis(right, np.clip(u, 0, w - 1), axis=1)
    return left, right, truth


def compute(block: bool, *overrides):
    left, right, truth = plane_and_block_pair(block)
    cfg = load_config(None, ["pt.enabled=true", "pyramid.levels=2", "run.backend=cpu", *overrides])
    return D3Stereo(cfg).compute(left, right, max_disparity=36), truth


def test_a_plane_with_a_box_off_the_band_falls_back_to_the_full_range():
    result, truth = compute(True)
    pt = result.info["pt"]
    # The coarse fit alone accepts the plane; 20 % of the image matched at the band's ends rejects it.
    assert pt["inlier_share"] > 0.7 and pt["fallback"] is True and pt["band_end_share"] > 0.1
    (warning,) = result.warnings
    assert warning.startswith("perspective transformation skipped: ") and "off the fitted plane" in warning
    assert warning.endswith("searched the full range 0-36")
    box = (slice(20, 68), slice(70, 124))  # the box, its occluded left edge left out
    assert np.median(np.abs(result.disparity[box] - truth[box])) < 0.5


def test_the_plane_alone_keeps_the_model():
    result, truth = compute(False)
    pt = result.info["pt"]
    assert pt["fallback"] is False and pt["range_end_share"] <= 0.03 and result.warnings == []
    inner = (slice(8, -8), slice(24, -8))
    assert np.median(np.abs(result.disparity[inner] - truth[inner])) < 0.5


def test_the_fallback_matches_with_the_settings_of_the_fallback_config():
    result, truth = compute(True, "pt.fallback_config=default")
    (warning,) = result.warnings
    assert warning.endswith("searched the full range 0-36 with the settings of default.yaml")
    assert result.info["pt"]["fallback"] is True and result.info["pt"]["fallback_config"] == "default"
    assert "pt_fit" in result.timings
    # the same map as a run with default.yaml's settings (its pyramid too) and no PT
    left, right, _ = plane_and_block_pair(True)
    plain = D3Stereo(load_config("default", ["run.backend=cpu"])).compute(left, right, max_disparity=36)
    np.testing.assert_array_equal(result.disparity, plain.disparity)


def test_band_end_share_counts_decided_pixels_at_either_end():
    narrow = np.array([[-1, 0, 1, 17], [18, 19, 5, -1]])
    assert band_end_share(narrow, narrow_range=18) == pytest.approx(3 / 8)


def test_off_band_rejects_above_the_limit_only():
    model = RoadModel(10.0, 0.1, 0.0, 0.1, 0.0, 0.9, 1000)
    assert model.off_band(0.03, limit=0.03, margin=8) is model
    rejected = model.off_band(0.074, limit=0.03, margin=8)
    assert not rejected.road_like and rejected.a0 == model.a0
    assert rejected.reason == "7.4% of the pixels lie more than 8 px of disparity off the fitted plane (> 3.0%)"


@pytest.mark.parametrize("key, value", [("pt.max_band_end_share", "1.5"), ("pt.fallback_config", "nope")])
def test_the_new_keys_are_range_checked(key, value):
    with pytest.raises(ConfigError, match="number in \\[0, 1\\]|bundled config"):
        load_config(None, [f"{key}={value}"])


def tilted(model: RoadModel, *, top: float, slope: float) -> RoadModel:
    """``model`` moved by ``top`` px at the top row and tilted by ``slope`` px per row."""
    b1 = model.b1 + slope
    return dataclasses.replace(model, a0=model.a0 + top, b1=b1, a1=float(np.copysign(np.hypot(b1, model.b2), b1)))


def test_a_road_whose_coarse_fit_is_tilted_keeps_the_model_fitted_again_to_the_band(monkeypatch):
    """The coarse fit of a dark pair can be several pixels off at the far rows (a 1280x720
    dusk pair: +7 px at the top, 10 % of its pixels at the band's ends): the plane fitted
    again to the full-resolution match inside the band is the road's, and the pair keeps
    the road settings instead of falling back as if it were no road."""
    from d3cli.method import pipeline

    fit = pipeline.fit_road_model
    monkeypatch.setattr(pipeline, "fit_road_model", lambda *a, **k: tilted(fit(*a, **k), top=9.0, slope=-0.1))
    result, truth = compute(False)
    pt = result.info["pt"]
    assert pt["refit"] is True and pt["first_band_end_share"] > 0.05
    assert pt["fallback"] is False and pt["range_end_share"] <= 0.03 and result.warnings == []
    assert pt["b1"] == pytest.approx(12 / 96, abs=0.01)  # the staircase's own gradient, not the tilted one
    inner = (slice(8, -8), slice(24, -8))
    assert np.median(np.abs(result.disparity[inner] - truth[inner])) < 0.5


def test_a_scene_off_the_band_after_the_refit_still_falls_back(monkeypatch):
    from d3cli.method import pipeline

    fit = pipeline.fit_road_model
    monkeypatch.setattr(pipeline, "fit_road_model", lambda *a, **k: tilted(fit(*a, **k), top=9.0, slope=-0.1))
    result, _ = compute(True)
    pt = result.info["pt"]
    assert pt["refit"] is True and pt["fallback"] is True and pt["band_end_share"] > 0.1
    (warning,) = result.warnings
    assert warning.startswith("perspective transformation skipped: ") and "off the fitted plane" in warning
