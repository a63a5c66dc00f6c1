"""Geolocation against exactly known poses: pixels onto the road plane and onto the earth
within 1 cm, and the error budget of docs/survey.md measured on the same analytic frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("pyproj")
pytest.importorskip("shapely")

from d3cli.road.pointcloud import Camera  # noqa: E402
from d3cli.survey.geolocate import locate_defect, pixels_to_road, road_axes, road_to_lonlat  # noqa: E402

from .drive import BASELINE, CX, CY, F, GEOD, Pose, camera_points, plane_info, project, road_of  # noqa: E402

CAMERA = Camera(f=F, baseline=BASELINE, cx=CX, cy=CY)
#: Road points (forward, right) metres from the point below the rig's mid-point.
ROAD = np.array([[2.5, 0.0], [4.0, -1.2], [6.0, 1.5], [8.0, -0.4], [10.0, 2.0], [12.0, -2.5]])


def _axes(pose: Pose):
    info = plane_info(pose)
    return road_axes(info["normal"], info["offset_m"], BASELINE)


@pytest.mark.parametrize("pose", [Pose(1.5, 12.0, 0.0), Pose(1.2, 5.0, 2.0), Pose(2.0, 20.0, -3.0),
                                  Pose(1.6, -2.0, 0.5)])
def test_pixels_come_back_to_their_road_points(pose):
    uv = project(camera_points(ROAD, pose))
    got = pixels_to_road(uv, CAMERA, _axes(pose))
    assert np.abs(got - ROAD).max() < 1e-3  # metres: the geometry is exact


def test_a_ray_above_the_horizon_meets_no_road():
    axes = _axes(Pose(1.5, 5.0, 0.0))
    got = pixels_to_road([[CX, CY - 200.0], [CX, CY + 200.0]], CAMERA, axes)
    assert np.isnan(got[0]).all() and np.isfinite(got[1]).all()


@pytest.mark.parametrize("heading", [0.0, 37.0, 181.0, 300.0])
@pytest.mark.parametrize("lat", [48.1, -33.9, 69.6])
def test_road_points_land_within_a_centimetre_of_their_place_on_the_earth(heading, lat):
    pose = Pose(1.4, 9.0, 1.0)
    fix = (11.5, lat)
    uv = project(camera_points(ROAD, pose))
    lon, la = road_to_lonlat(pixels_to_road(uv, CAMERA, _axes(pose)), fix[0], fix[1], heading)
    for (fwd, right), lo, a in zip(ROAD, lon, la):
        got = road_of(lo, a, fix, heading)
        assert math.dist(got, (fwd, right)) < 0.01


def test_antenna_offset_and_camera_yaw():
    fix, heading = (11.5, 48.1), 80.0
    # The antenna 1.5 m ahead of and 0.4 m right of the rig: a road point 6 m ahead of the rig
    # is 4.5 m ahead of and 0.4 m left of the fix.
    lon, lat = road_to_lonlat([[6.0, 0.0]], *fix, heading, antenna_forward_m=1.5, antenna_right_m=0.4)
    assert road_of(lon[0], lat[0], fix, heading) == pytest.approx((4.5, -0.4), abs=1e-3)
    # A camera turned 90 degrees right looks across the road: its "forward" is the car's right.
    lon, lat = road_to_lonlat([[5.0, 1.0]], *fix, heading, camera_yaw_deg=90.0)
    assert road_of(lon[0], lat[0], fix, heading) == pytest.approx((-1.0, 5.0), abs=1e-3)


def test_a_defect_of_defects_json_is_located_with_its_outline():
    from .drive import frame_defects, pothole

    pose = Pose()
    fix, heading = (11.5, 48.1), 120.0
    lo, la, _ = GEOD.fwd(fix[0], fix[1], heading + math.degrees(math.atan2(0.5, 7.0)), math.hypot(7.0, 0.5))
    [d] = frame_defects(fix, heading, [pothole(lo, la, 0.2, 30.0)], pose)
    got = locate_defect(d, CAMERA, _axes(pose), fix[0], fix[1], heading)
    assert GEOD.inv(lo, la, *got["centroid"])[2] < 0.01
    assert got["road_centroid"] == pytest.approx((7.0, 0.5), abs=1e-3)
    ring = got["outline"][0]
    radii = [GEOD.inv(lo, la, x, y)[2] for x, y in ring]
    assert max(abs(r - 0.2) for r in radii) < 0.01


def test_the_error_budget_of_the_docs():
    """The sensitivities docs/survey.md states, measured on the analytic frame (h = 1.5 m,
    f = 800 px): a pixel, a plane pitch error, a camera height error, a heading error."""
    pose = Pose(1.5, 12.0, 0.0)
    axes = _axes(pose)
    h, f = 1.5, F
    for z in (5.0, 10.0):
        p = np.array([[z, 0.0]])
        uv = project(camera_points(p, pose))
        # Half a pixel down and across.
        along = pixels_to_road(uv + [0.0, 0.5], CAMERA, axes)[0, 0] - z
        across = pixels_to_road(uv + [0.5, 0.0], CAMERA, axes)[0, 1]
        assert abs(along) == pytest.approx(z * z * 0.5 / (f * h), rel=0.15)
        assert across == pytest.approx(z * 0.5 / f, rel=0.1)
        # The plane fit's pitch off by 0.1 degree; its height off by 1 cm.
        tilted = Pose(1.5, 12.1, 0.0)
        err_pitch = pixels_to_road(uv, CAMERA, _axes(tilted))[0, 0] - z
        assert abs(err_pitch) == pytest.approx(z * z * math.radians(0.1) / h, rel=0.2)
        err_h = pixels_to_road(uv, CAMERA, road_axes(plane_info(pose)["normal"], 1.51, BASELINE))[0, 0] - z
        assert err_h == pytest.approx(z * 0.01 / h, rel=0.05)
        # Heading 0.5 degree off: across by z * 0.5 degree.
        lon, lat = road_to_lonlat(p, 11.5, 48.1, 30.5)
        assert road_of(lon[0], lat[0], (11.5, 48.1), 30.0)[1] == pytest.approx(z * math.radians(0.5), rel=0.01)


def test_rendered_synthetic_frames_put_their_potholes_where_they_are(tmp_path):
    """d3stereo synth frames (their rig: the mid-point above the world origin, x right, y
    forward): the road report on the ground-truth disparity, then each pothole's outline
    onto its fitted plane, lands within 5 cm of the pothole's true centre (SOURCE.txt)."""
    import json
    import re

    from shapely.geometry import Polygon

    from d3cli.config import load_config
    from d3cli.data import formats as io
    from d3cli.data.synth import generate_dataset
    from d3cli.road.pointcloud import camera_from
    from d3cli.road.outputs import road_report

    cfg = load_config("road")
    folders = generate_dataset(tmp_path / "in", n=2, seed=0, width=320, height=192)
    errors = []
    for folder in folders:
        gt = io.read_pfm(folder / "disp_gt.pfm")
        camera = camera_from(io.read_calib(folder / "calib.txt"), cfg, gt.shape)
        truth = [(float(y), float(x)) for x, y in re.findall(r" x=(-?[\d.]+) y=(-?[\d.]+)",
                                                             (folder / "SOURCE.txt").read_text())]
        out = tmp_path / folder.name
        out.mkdir()
        items, _ = road_report(out, io.read_image(folder / "left.png"), gt, np.isfinite(gt), camera, {}, cfg.road,
                               groups=frozenset())
        plane = json.loads((out / "defects.json").read_text())["plane"]
        axes = road_axes(plane["normal"], plane["offset_m"], camera.baseline)
        for d in items:
            if d["kind"] == "pothole":
                c = Polygon(pixels_to_road(np.asarray(d["outline_px"][0], float), camera, axes)).centroid
                errors.append(min(math.dist((c.x, c.y), t) for t in truth))
    assert len(errors) >= 3 and max(errors) < 0.05
