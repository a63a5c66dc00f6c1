"""Pothole families of the synthetic road (d3cli.data.synth.potholes) and their truth."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.data import synth
from d3cli.data.synth.potholes import FAMILIES
from d3cli.errors import InputError

W, H = 320, 180


@pytest.fixture(scope="module")
def pairs():
    # Three potholes a pair, families cycling from a random start: 9 pairs hold every family.
    return [synth.render_pair(seed=s, width=W, height=H, potholes=3, noise=False) for s in range(9)]


def test_every_family_is_drawn_and_named_in_the_truth(pairs):
    shapes = [g["shape"] for p in pairs for g in p.defects_gt]
    assert sorted(set(shapes)) == sorted(FAMILIES)
    assert [h["shape"] for h in pairs[0].info["potholes"]] == [g["shape"] for g in pairs[0].defects_gt]


def test_truth_is_the_rendered_surface(pairs):
    # Depth, area and volume integrate the surface itself: the floor relief makes the
    # deepest point at least the profile's depth (cones: their apex between grid nodes,
    # within 2 %); water makes it shallower.
    for p in pairs:
        for g, h in zip(p.defects_gt, p.info["potholes"]):
            if "part_of" in g:
                continue
            if h["water_fill"] > 0:
                assert g["depth_mm"] < g["profile_depth_mm"]
            else:
                assert g["depth_mm"] >= 0.98 * g["profile_depth_mm"]
            assert g["area_m2"] > 0 and g["volume_l"] > 0


def test_water_is_a_flat_surface_in_the_ground_truth():
    pair = next(p for p in (synth.render_pair(seed=s, width=W, height=H, potholes=3, noise=False)
                            for s in range(20)) if any(h["water_fill"] > 0 for h in p.info["potholes"]))
    k = next(i for i, h in enumerate(pair.info["potholes"]) if h["water_fill"] > 0)
    assert pair.defects_gt[k]["shape"] == "water"
    assert 0.3 <= pair.info["potholes"][k]["water_fill"] <= 0.7


def test_classic_shapes_are_those_of_earlier_versions():
    pair = synth.render_pair(seed=2, width=W, height=H, potholes=3, noise=False, shapes="classic")
    assert {h["shape"] for h in pair.info["potholes"]} == {"classic"}
    assert all("profile_depth_mm" not in g for g in pair.defects_gt)
    varied = synth.render_pair(seed=2, width=W, height=H, potholes=3, noise=False)
    # Same rig and positions: the families change the profiles only.
    assert pair.calib == varied.calib
    assert [(h["x"], h["y"]) for h in pair.info["potholes"]] == [(h["x"], h["y"]) for h in varied.info["potholes"]]
    assert not np.array_equal(pair.disparity, varied.disparity)


def test_unknown_shapes_are_refused():
    with pytest.raises(InputError, match="unknown pothole shapes .round."):
        synth.render_pair(seed=0, width=W, height=H, shapes="round")


def test_pothole_depth_image_is_the_truth_seen_by_each_pixel(pairs):
    # Rebuilt from the seed and the exact disparity: lowered by more than 1 mm exactly
    # where the id mask says so (up to pixels on that 1 mm contour), and as deep as the
    # truth at the deepest pixel (pixel centres miss a cone's apex by up to 3 %).
    for seed, p in enumerate(pairs):
        depth = synth.pothole_depth_image(seed=seed, width=W, height=H, disparity=p.disparity, potholes=3)
        finite = np.isfinite(p.disparity)
        assert not np.isnan(depth[finite]).any() and np.isnan(depth[~finite]).all()
        assert np.mean(((depth > 1.0) == (p.pothole_ids > 0))[finite]) >= 0.998
        for g in p.defects_gt:
            if "part_of" not in g and g["visible_px"]:
                deepest = depth[p.pothole_ids == g["id"]].max()
                assert 0.97 * g["depth_mm"] <= deepest <= g["depth_mm"] + 0.01
