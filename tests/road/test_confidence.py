"""Per-defect confidence: each reason against a brute-force reference or a constructed case,
and the flags of whole defects measured on analytic scenes."""

import numpy as np
import pytest

from d3cli.config import RoadConfig
from d3cli.road.confidence import (REASONS, ConfidenceRules, deep_at_border, depressions, describe, flags_of,
                                   spikiness)
from d3cli.road.defects import find_defects
from d3cli.road.plane import fit_road_plane, height_map
from d3cli.road.pointcloud import disparity_to_points

from .scene import pothole_scene
from tests.reference.road import ref_spikiness


def bowl(shape=(120, 160), centre=(60, 80), radius=40.0, depth=0.05):
    v, u = np.mgrid[: shape[0], : shape[1]]
    r2 = ((v - centre[0]) ** 2 + (u - centre[1]) ** 2) / radius ** 2
    return (depth * np.clip(1 - r2, 0, None)).astype(np.float32)


def test_spikiness_of_a_smooth_bowl_is_one_and_of_a_spiky_floor_more():
    d = bowl()
    inside = d > 0.01
    smooth = spikiness(d, inside, peak_px=9, spike_px=15)
    assert smooth == pytest.approx(ref_spikiness(d, inside, 9, 15), rel=1e-6)
    assert 1.0 <= smooth < 1.05  # a paraboloid's bottom loses 2 % in the filter
    # Reflections on a wet floor: isolated 2x2 spikes 30 mm deeper than the floor.
    spiky = d.copy()
    rng = np.random.default_rng(1)
    for v, u in zip(rng.integers(40, 80, 12), rng.integers(60, 100, 12)):
        spiky[v:v + 2, u:u + 2] += 0.03
    value = spikiness(spiky, inside, peak_px=9, spike_px=15)
    assert value == pytest.approx(ref_spikiness(spiky, inside, 9, 15), rel=1e-6)
    assert value > 1.4
    # A narrow but real deepest part (a cone's tip) stays below the flag's threshold.
    v, u = np.mgrid[:120, :160]
    cone = (0.05 * np.clip(1 - np.hypot(v - 60, u - 80) / 60.0, 0, None)).astype(np.float32)
    assert spikiness(cone, cone > 0.01, peak_px=9, spike_px=15) < ConfidenceRules().max_spikiness


def test_spikiness_without_enough_pixels_is_one():
    d = bowl()
    inside = np.zeros(d.shape, bool)
    inside[60, 80:85] = True
    assert spikiness(d, inside, peak_px=9, spike_px=15) == 1.0


def test_deep_at_border_looks_at_the_deep_part_only():
    d = bowl(centre=(60, 45), radius=50.0)  # rim reaches column 0, the deep part does not
    region = d > 0.002
    assert region[:, 0].any()
    assert not deep_at_border(d, region, float(d.max()), (0, 0), d.shape)
    d = bowl(centre=(60, 5), radius=40.0)  # the deepest part itself is cut by the border
    assert deep_at_border(d, d > 0.002, float(d.max()), (0, 0), d.shape)
    # A window of a larger image: the border is the image's, not the window's.
    assert not deep_at_border(d, d > 0.002, float(d.max()), (10, 10), (200, 300))


def test_depressions_counts_pits_that_stand_out_of_the_saddle():
    two = np.maximum(bowl(centre=(60, 45), radius=35), bowl(centre=(60, 115), radius=35, depth=0.046))
    region = two > 0.002
    assert depressions(two, region, prominence=0.006, smooth_px=0) == 2
    # Joined by a trench 44 mm deep: the shallower pit stands 2 mm above the saddle only.
    joined = np.maximum(two, np.float32(0.044) * (np.abs(np.mgrid[:120, :160][0] - 60) < 8))
    assert depressions(joined, joined > 0.002, prominence=0.006, smooth_px=0) == 1
    assert depressions(bowl(), bowl() > 0.002, prominence=0.006, smooth_px=12) == 1
    assert depressions(bowl(), np.zeros((120, 160), bool), prominence=0.006, smooth_px=12) == 0


@pytest.mark.parametrize("evidence, flags", [
    ({"spikiness": 1.05, "snr": 30.0, "decided_share": 0.9, "deep_at_border": False, "depressions": 1}, ()),
    ({"spikiness": 1.2}, ("specular",)),
    ({"snr": 9.9}, ("noisy",)),
    ({"decided_share": 0.6}, ("few_decided",)),
    ({"map_decided_share": 0.4}, ("few_decided",)),
    ({"deep_at_border": True}, ("at_border",)),
    ({"depressions": 2}, ("merged",)),
    # The stored map reads potholes shallower, by up to about half: a re-match may deepen
    # one up to twice the stored depth, but not make it shallower by more than 15 %.
    ({"rematch_change": -0.15}, ()),
    ({"rematch_change": -0.16}, ("rematch",)),
    ({"rematch_change": 0.5}, ()),
    ({"rematch_change": 1.0}, ()),
    ({"rematch_change": 1.01}, ("rematch",)),
    ({"rematch_change": 1.2, "spikiness": 1.3, "snr": 5.0}, ("specular", "noisy", "rematch")),
    # With the match margin known it speaks for the texture: spikes do not flag, and the
    # depth must be less than 4 (not 10) times the noise to be noisy.
    ({"match_margin": 0.05, "spikiness": 1.3, "snr": 5.0}, ()),
    ({"match_margin": 0.05, "snr": 3.9}, ("noisy",)),
    ({"match_margin": 0.0199}, ("weak_match",)),
    ({"match_margin": 0.020}, ()),
    ({"match_margin": None}, ("weak_match",)),  # not measurable: no disparity in the box
    ({"match_margin": 0.01, "depressions": 3, "deep_at_border": True, "rematch_change": -0.4},
     ("weak_match", "at_border", "merged", "rematch")),
    # Measured on the stored map (no clean re-match window) and narrower than that map
    # averages (27 px for d3stereo with road.yaml): the depth reads low.  Re-matched, wide
    # enough, or the method's averaging not known: not flagged.
    ({"rematch_window": 0, "inscribed_px": 26.9, "averaging_px": 27.0}, ("narrow",)),
    ({"rematch_window": 0, "inscribed_px": 27.0, "averaging_px": 27.0}, ()),
    ({"rematch_window": 9, "inscribed_px": 5.0, "averaging_px": 27.0}, ()),
    ({"rematch_window": 0, "inscribed_px": 5.0}, ()),
    ({"rematch_window": 0, "averaging_px": 27.0}, ()),
    ({"rematch_change": -0.2, "rematch_window": 0, "inscribed_px": 12.0, "averaging_px": 27.0}, ("rematch", "narrow")),
])
def test_flags_follow_the_rules_in_the_order_of_the_reasons(evidence, flags):
    assert flags_of(evidence, min_decided_share=0.75) == flags
    assert describe(flags) == ("; ".join(REASONS[f] for f in flags) or "ok")


def measured(disp, cam, road=None):
    road = road or RoadConfig(report=True, sigma_disparity=0.05)
    finite = np.isfinite(disp)
    plane = fit_road_plane(disparity_to_points(disp, finite, cam)[0], cam, sigma_disparity=road.sigma_disparity)
    return find_defects(height_map(disp, finite, cam, plane), finite, cam, plane, road)


def test_a_clean_pothole_is_ok_with_its_evidence():
    disp, cam, _ = pothole_scene()
    (d,) = measured(disp, cam)
    assert (d.confidence, d.flags, d.low_confidence) == ("ok", (), False)
    assert set(d.evidence) == {"spikiness", "snr", "decided_share", "deep_at_border", "depressions"}
    assert d.evidence["spikiness"] < 1.05 and d.evidence["depressions"] == 1 and not d.evidence["deep_at_border"]


def test_reflections_on_the_floor_flag_the_pothole_as_specular():
    # A wet floor: stereo matches the mirrored sky, so scattered pixels of the floor read far
    # too deep (smaller disparity); the reported depth follows them and the flag says so.
    disp, cam, _ = pothole_scene()
    (clean,) = measured(disp, cam)
    rng = np.random.default_rng(3)
    wet = disp.copy()
    u0, v0, u1, v1 = clean.bbox_px
    cu, cv = (u0 + u1) // 2, (v0 + v1) // 2
    for v, u in zip(rng.integers(cv - 8, cv + 8, 10), rng.integers(cu - 12, cu + 12, 10)):
        wet[v:v + 3, u:u + 3] -= 1.5
    (d,) = measured(wet, cam)
    assert d.max_depth_mm > 1.2 * clean.max_depth_mm
    assert "specular" in d.flags and d.confidence == "low" and d.low_confidence


def test_a_pothole_cut_by_the_image_border_is_flagged_one_whose_rim_touches_it_is_not():
    disp, cam, _ = pothole_scene(centre=(1.1, 1.5))
    (d,) = measured(disp, cam)
    assert d.at_border and d.evidence["deep_at_border"] and d.flags == ("at_border",)
    disp, cam, _ = pothole_scene(centre=(0.9, 1.5))
    (d,) = measured(disp, cam)
    assert d.at_border and not d.evidence["deep_at_border"] and d.confidence == "ok"
