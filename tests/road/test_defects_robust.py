"""Defect finding on maps that are not a clean road: pixels beyond the horizon, planes
that explain few points, regions measured on filled pixels."""

import math

import numpy as np

from d3cli.config import RoadConfig
from d3cli.road.defects import find_defects
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
