"""Point clouds: camera from calibration/config, back-projection, binary PLY."""

from __future__ import annotations

import math

import numpy as np
import pytest

from d3cli import load_config
from d3cli.errors import InputError
from d3cli.data.formats import read_calib
from d3cli.road.pointcloud import Camera, camera_from, disparity_to_points, read_ply, save_pair_cloud, write_ply
from d3cli.data.synth import render_pair


def test_camera_from_calibration_scales_to_the_image_and_config_fills_gaps():
    cfg = load_config(None, ["camera.baseline=0.3"])
    calib = {"f": 1000.0, "cx": 399.5, "cy": 299.5, "doffs": 20.0, "width": 800}
    cam = camera_from(calib, cfg, (300, 400))  # images at half the calibrated size
    assert cam == Camera(f=500.0, baseline=0.3, cx=199.5, cy=149.5, doffs=10.0)


def test_camera_defaults_to_the_image_centre_and_needs_f_and_baseline():
    cfg = load_config(None, ["camera.f=700", "camera.baseline=0.5"])
    assert camera_from(None, cfg, (101, 201)) == Camera(f=700.0, baseline=0.5, cx=100.0, cy=50.0)
    assert camera_from({"f": 700.0}, load_config(), (10, 10)) is None


def test_middlebury_calib_file_gives_metres(tmp_path):
    (tmp_path / "calib.txt").write_text(
        "cam0=[1500 0 199; 0 1500 187; 0 0 1]\ncam1=[1500 0 251; 0 1500 187; 0 0 1]\n"
        "doffs=52\nbaseline=80\nwidth=450\nheight=375\nndisp=64\n"
    )
    cam = camera_from(read_calib(tmp_path / "calib.txt"), load_config(), (375, 450))
    assert (cam.f, cam.baseline, cam.doffs) == (1500.0, 0.08, 52.0)
    points, _ = disparity_to_points(np.full((375, 450), 28.0), np.ones((375, 450), bool), cam)
    assert points[:, 2] == pytest.approx(1500 * 0.08 / 80.0)  # Z = f B / (d + doffs)


def test_back_projection_keeps_only_valid_finite_pixels():
    cam = Camera(f=100.0, baseline=0.2, cx=1.0, cy=0.5)
    disp = np.array([[10.0, 20.0, np.inf], [5.0, 0.0, 40.0]])
    valid = np.array([[True, True, True], [False, True, True]])
    points, index = disparity_to_points(disp, valid, cam)
    np.testing.assert_array_equal(index, [[0, 0], [0, 1], [1, 2]])
    z = 100 * 0.2 / np.array([10.0, 20.0, 40.0])
    np.testing.assert_allclose(points[:, 2], z, rtol=1e-6)
    np.testing.assert_allclose(points[:, 0], (np.array([0, 1, 2]) - 1.0) * z / 100, rtol=1e-6)
    np.testing.assert_allclose(points[:, 1], (np.array([0, 0, 1]) - 0.5) * z / 100, rtol=1e-6)
    with pytest.raises(InputError, match="differ"):
        disparity_to_points(disp, valid[:1], cam)


def test_ply_round_trip_is_binary_little_endian(tmp_path):
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(57, 3)).astype(np.float32)
    cols = rng.integers(0, 256, (57, 3), dtype=np.uint8)
    path = write_ply(tmp_path / "cloud.ply", pts, cols)
    head = path.read_bytes()[:200]
    assert head.startswith(b"ply\nformat binary_little_endian 1.0\n") and b"element vertex 57\n" in head
    got_pts, got_cols = read_ply(path)
    np.testing.assert_array_equal(got_pts, pts)
    np.testing.assert_array_equal(got_cols, cols)
    assert [p.name for p in tmp_path.iterdir()] == ["cloud.ply"]  # no temporary left behind


def test_cloud_of_a_synthetic_flat_road_is_a_plane_at_the_camera_height(tmp_path):
    pair = render_pair(seed=3, width=160, height=90, flat=True, noise=False)
    calib = pair.calib
    cam = camera_from(calib, load_config(), pair.left.shape)
    valid = np.isfinite(pair.disparity)
    n = save_pair_cloud(tmp_path / "cloud.ply", pair.disparity, valid, pair.left, cam)
    points, colours = read_ply(tmp_path / "cloud.ply")
    assert n == valid.sum() == points.shape[0]
    # Plane fit: the smallest singular vector is the normal; residuals are tiny.
    centred = points.astype(np.float64) - points.mean(axis=0)
    _, sing, vt = np.linalg.svd(centred, full_matrices=False)
    normal = vt[2]
    residual = centred @ normal
    assert np.sqrt(np.mean(residual**2)) < 2e-3  # metres
    # Distance of the left camera (origin) to the plane = camera height above the road
    # (the left camera sits baseline/2 off the rig's mid-point, along the camera x axis).
    distance = abs(points.mean(axis=0).astype(np.float64) @ normal)
    roll, pitch = math.radians(calib["roll_deg"]), math.radians(calib["pitch_deg"])
    left_height = calib["height_m"] - 0.5 * calib["baseline"] * math.sin(roll) * math.cos(pitch)
    assert distance == pytest.approx(left_height, abs=0.005)
    assert abs(normal[1]) == pytest.approx(math.cos(pitch), abs=0.02)  # the road tilts by the pitch
    assert colours[0].tolist() == [pair.left[np.nonzero(valid)][0]] * 3


def test_depth_range_drops_points_outside_it():
    """Z = f B / d: 100 * 0.2 / d; d = 0.001 px would be 20 km away."""
    cam = Camera(f=100.0, baseline=0.2, cx=0.0, cy=0.0)
    disp = np.array([[0.001, 0.1, 1.0, 4.0, 40.0]])
    valid = np.ones_like(disp, dtype=bool)
    points, index = disparity_to_points(disp, valid, cam, depth_range=(1.0, 100.0))
    np.testing.assert_allclose(points[:, 2], [20.0, 5.0], rtol=1e-6)  # 20000 m, 200 m and 0.5 m dropped
    np.testing.assert_array_equal(index, [[0, 2], [0, 3]])
    every, _ = disparity_to_points(disp, valid, cam)  # no range: all of them
    assert every.shape[0] == 5


def test_saved_cloud_has_no_point_beyond_the_configured_depth(tmp_path):
    cfg = load_config(None, ["camera.f=100", "camera.baseline=0.2", "camera.max_depth_m=10"])
    assert (cfg.camera.min_depth_m, cfg.camera.max_depth_m) == (0.0, 10.0)
    rng = np.random.default_rng(1)
    disp = rng.uniform(0.0, 8.0, (30, 40))  # depths from 2.5 m to infinity
    cam = camera_from(None, cfg, disp.shape)
    n = save_pair_cloud(tmp_path / "cloud.ply", disp, np.ones(disp.shape, bool), np.zeros((30, 40), np.uint8), cam,
                        depth_range=(cfg.camera.min_depth_m, cfg.camera.max_depth_m))
    points, _ = read_ply(tmp_path / "cloud.ply")
    assert n == points.shape[0] == int((100 * 0.2 / disp <= 10.0).sum())
    assert points[:, 2].max() <= 10.0


@pytest.mark.parametrize("overrides, message", [
    (["camera.max_depth_m=0"], "camera.max_depth_m must be a number > 0"),
    (["camera.min_depth_m=-1"], "camera.min_depth_m must be a number >= 0"),
    (["camera.min_depth_m=50", "camera.max_depth_m=20"], "camera.min_depth_m (50) must be smaller than "
                                                          "camera.max_depth_m (20)"),
])
def test_depth_range_is_checked(overrides, message):
    from d3cli.errors import ConfigError

    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_config(None, overrides)


def test_depth_range_overrides_apply_in_any_order():
    cfg = load_config(None, ["camera.min_depth_m=150", "camera.max_depth_m=200"])
    assert (cfg.camera.min_depth_m, cfg.camera.max_depth_m) == (150.0, 200.0)
