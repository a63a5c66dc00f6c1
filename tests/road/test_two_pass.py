"""The road report's two passes over a map (d3cli.road.defects.candidate_regions, remeasure):
the stored map's defects briefly measured first, then the defects of the re-matched map,
measured only where it changed and compared with the stored defects they lie in."""

import numpy as np
import pytest

from d3cli.config import RoadConfig
from d3cli.road.defects import median_filled, median_patched, candidate_regions, find_defects, remeasure
from d3cli.road.morphology import dilate_near
from d3cli.road.plane import fit_road_plane, height_map
from d3cli.road.pointcloud import disparity_to_points

from .scene import pothole_scene

ROAD = RoadConfig(min_depth_mm=10.0, min_area_m2=0.005)


@pytest.fixture(scope="module")
def joined():
    """Two paraboloid potholes (80 and 60 mm) that overlap into one region of the height map."""
    disp, cam, _ = pothole_scene(depth=0.08, radius=0.3, more=((0.6, 1.6, 0.3, 0.06),))
    valid = np.isfinite(disp)
    points, _ = disparity_to_points(disp, valid, cam)
    plane = fit_road_plane(points, cam, sigma_disparity=0.05)
    return height_map(disp, valid, cam, plane), valid, cam, plane


def test_the_first_pass_finds_the_defects_of_find_defects_briefly(joined):
    height, valid, cam, plane = joined
    stored = candidate_regions(height, valid, cam, plane, ROAD)
    once, regions = find_defects(height, valid, cam, plane, ROAD, return_regions=True)
    assert [round(d.max_depth_mm) for d in once] == [79, 59]  # the joined potholes cut apart
    assert [(d.kind, d.bbox_px, d.max_depth_mm, d.area_m2) for d in stored.defects] == \
        [(d.kind, d.bbox_px, d.max_depth_mm, d.area_m2) for d in once]
    assert all(np.array_equal(a, b) for a, b in zip(stored.regions, regions))
    assert [d.volume_l for d in stored.defects] == [0.0, 0.0]  # not measured: the re-match needs no volume


def test_the_second_pass_on_an_unchanged_map_is_find_defects(joined):
    height, valid, cam, plane = joined
    stored = candidate_regions(height, valid, cam, plane, ROAD)
    zones = dilate_near(stored.regions[0] | stored.regions[1], np.ones((61, 61), np.uint8))
    again, again_regions = remeasure(stored, height, zones, return_regions=True)
    once, once_regions = find_defects(height, valid, cam, plane, ROAD, return_regions=True)
    assert [d.evidence.pop("rematch_change") for d in again] == [0.0, 0.0]  # nothing re-matched
    assert again == once
    assert all(np.array_equal(a, b) for a, b in zip(again_regions, once_regions))


def test_the_second_pass_measures_only_where_the_map_changed(joined):
    height, valid, cam, plane = joined
    stored = candidate_regions(height, valid, cam, plane, ROAD)
    # A pothole appears outside the zones: the first pass saw none there, so the second
    # does not look (its map there is the stored one by contract).
    v, u = np.mgrid[0:height.shape[0], 0:height.shape[1]]
    far = np.hypot(v - 25, u - 280) < 18
    joined_pits = stored.regions[0] | stored.regions[1]
    assert not (far & joined_pits).any()
    changed = np.where(far, height - 0.05, height).astype(np.float32)
    zones = dilate_near(joined_pits, np.ones((61, 61), np.uint8))
    assert len(remeasure(stored, changed, zones)) == 2
    assert len(remeasure(stored, changed, zones | far)) == 3


def test_the_re_match_change_compares_each_defect_with_the_stored_one_it_lies_in(joined):
    height, valid, cam, plane = joined
    stored = candidate_regions(height, valid, cam, plane, ROAD)
    zones = dilate_near(stored.regions[0] | stored.regions[1], np.ones((61, 61), np.uint8))
    deeper = np.where(zones & (height < -0.002), 1.5 * height, height).astype(np.float32)  # the floors 1.5x deeper
    found = remeasure(stored, deeper, zones)
    once = find_defects(height, valid, cam, plane, ROAD)
    assert [d.max_depth_mm for d in found] == [pytest.approx(1.5 * d.max_depth_mm, rel=0.01) for d in once]
    assert [d.evidence["rematch_change"] for d in found] == [pytest.approx(0.5, abs=0.01)] * 2
    # deeper by half: what the stored map's averaging can lose (ConfidenceRules.max_rematch_change)
    assert [d.flags for d in found] == [()] * 2
    # a shelf of the deep pothole alone, re-matched shallow: far below the stored defect it lies in
    shelf = np.where(zones & (height < -0.002), 0.3 * height, height).astype(np.float32)
    (shallow, *_) = remeasure(stored, shelf, zones)
    assert shallow.evidence["rematch_change"] == pytest.approx(-0.7, abs=0.01)
    assert "rematch" in shallow.flags  # shallower than the stored map: not the floor it saw


def test_the_patched_median_is_the_median_of_the_whole_map():
    rng = np.random.default_rng(2)
    old = rng.normal(0, 0.01, (90, 140)).astype(np.float32)
    old[rng.random(old.shape) < 0.1] = np.inf
    smooth, fill = median_filled(old, 5)
    zones = np.zeros(old.shape, bool)
    zones[30:50, 60:100] = zones[0:6, 0:10] = zones[85:90, 130:140] = True  # at the corners too
    new = np.where(zones & np.isfinite(old), old + rng.normal(0, 0.02, old.shape), old).astype(np.float32)
    want, _ = median_filled(new, 5, fill)
    np.testing.assert_array_equal(median_patched(smooth, new, zones, 5, fill), want)
    np.testing.assert_array_equal(median_patched(smooth, new, np.zeros_like(zones), 5, fill), smooth)
