"""Defect finding on maps that are not a clean road: pixels beyond the horizon, planes
that explain few points, regions measured on filled pixels."""

import math

import numpy as np

from d3cli.config import RoadConfig
from d3cli.road.defects import DefectTuning, find_defects
from d3cli.road.plane import RoadPlane, plane_footprint
from d3cli.road.pointcloud import Camera

# A camera 1.5 m above the road looking down by 0.2 rad: rows above the horizon
# (v < cy - f tan(0.2) ~ 58.7) see no road at all (plane footprint 0).
CAM = Camera(f=300.0, baseline=0.12, cx=159.5, cy=119.5)
PLANE = RoadPlane(normal=(0.0, -math.cos(0.2), -math.sin(0.2)), offset=1.5, inlier_share=1.0)
HORIZON_V = CAM.cy - CAM.f * math.tan(0.2)


def test_a_region_across_the_horizon_is_measured_on_road_pixels_only():
    # Stereo on a failed map gives heights above the horizon too; a raised block that
    # lies mostly beyond the horizon once made the terrace cue take its pixel size from
    # the median footprint (0 there) and ask OpenCV for a disc billions of pixels wide.
    height = np.zeros((240, 320), np.float32)
    height[30:80, 100:200] = 0.3
    footprint = plane_footprint(height.shape, CAM, PLANE)
    assert (footprint[30:80, 100:200] == 0).mean() > 0.5
    defects = find_defects(height, np.ones(height.shape, bool), CAM, PLANE, RoadConfig())
    assert [d.kind for d in defects] == ["bump"]
    assert defects[0].bbox_px[1] == math.ceil(HORIZON_V)


def test_a_pothole_cut_by_the_image_border_is_low_confidence():
    # The far, dark top rows of a dusk pair (synth --seed 3 pair 1, road.yaml) matched
    # 1.4 px short over 0.4 m^2 and gave a confident 130 mm pothole cut by the top border:
    # what lies beyond the border is unmeasured, so its depth, area and volume are not
    # known either.  The analytic pothole cut at its centre row shows the same.
    from d3cli.road.plane import fit_road_plane, height_map
    from d3cli.road.pointcloud import disparity_to_points

    from .scene import pothole_scene

    disp, cam, _ = pothole_scene(pitch_deg=45.0, roll_deg=0.0, depth=0.08, radius=0.3, centre=(0.0, 1.5))
    valid = np.isfinite(disp)
    plane = fit_road_plane(disparity_to_points(disp, valid, cam)[0], cam, sigma_disparity=0.05)
    whole = find_defects(height_map(disp, valid, cam, plane), valid, cam, plane, RoadConfig())
    assert [(d.kind, d.at_border, d.low_confidence) for d in whole] == [("pothole", False, False)]
    v_centre = int(round(whole[0].centroid_px[1]))
    cut = Camera(f=cam.f, baseline=cam.baseline, cx=cam.cx, cy=cam.cy - v_centre)
    d_cut, v_cut = disp[v_centre:], valid[v_centre:]
    plane = fit_road_plane(disparity_to_points(d_cut, v_cut, cut)[0], cut, sigma_disparity=0.05)
    (d,) = find_defects(height_map(d_cut, v_cut, cut, plane), v_cut, cut, plane, RoadConfig())
    assert (d.kind, d.at_border, d.low_confidence, d.bbox_px[1]) == ("pothole", True, True, 0)


def test_no_estimate_inside_a_region_counts_as_undecided():
    # Holes without any estimate inside a region's outline are not measurements either:
    # a region of 60 % measured pixels around a 40 % hole is 60 % decided.
    from d3cli.road.plane import fit_road_plane, height_map
    from d3cli.road.pointcloud import disparity_to_points

    from .scene import pothole_scene

    disp, cam, _ = pothole_scene(pitch_deg=45.0, roll_deg=0.0, depth=0.08, radius=0.3, centre=(0.0, 1.5))
    valid = np.isfinite(disp)
    plane = fit_road_plane(disparity_to_points(disp, valid, cam)[0], cam, sigma_disparity=0.05)
    h = height_map(disp, valid, cam, plane)
    (full,) = find_defects(h, valid, cam, plane, RoadConfig())
    u, v = (int(round(c)) for c in full.centroid_px)
    hole = np.zeros_like(valid)
    hole[v - 12:v + 13, u - 12:u + 13] = True
    h_holed = np.where(hole, np.inf, h).astype(np.float32)
    # Splitting off: the hole's zero-filled smoothing would show a saddle.
    (d,), (region,) = find_defects(h_holed, valid & ~hole, cam, plane,
                                   RoadConfig(split_prominence_mm=100.0, split_neck=1.0),
                                   DefectTuning(split_terrace=False), return_regions=True)
    assert not (region & hole).any()
    assert d.decided_share == int(region.sum()) / int(region.sum() + hole.sum())
    assert d.decided_share < 0.9
