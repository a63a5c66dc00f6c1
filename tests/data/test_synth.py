"""Tests of d3cli.data.synth: synthetic road stereo with exact ground truth (small images)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from d3cli.data import formats, layouts, synth
from d3cli.data.synth import render as synth_render, rig as synth_rig
from d3cli.errors import InputError

W, H = 160, 96


@pytest.fixture(scope="module")
def sun_pair():
    return synth.render_pair(seed=7, width=W, height=H, variant="sun", material="asphalt", noise=False)


def _plane_fit(disp: np.ndarray, keep: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares d = a + b u + c v (refit once without the worst outliers)."""
    vv, uu = np.mgrid[0 : disp.shape[0], 0 : disp.shape[1]]
    design = np.column_stack([np.ones(disp.size), uu.ravel(), vv.ravel()]).astype(float)
    values = disp.ravel().astype(float)
    use = np.ones(disp.size, bool) if keep is None else keep.ravel()
    for _ in range(2):
        coef, *_ = np.linalg.lstsq(design[use], values[use], rcond=None)
        residual = values - design @ coef
        use = np.abs(residual) <= 2.5 * np.median(np.abs(residual)) + 1e-9
    return coef, residual.reshape(disp.shape)


def test_render_pair_shapes_and_types(sun_pair):
    assert sun_pair.left.shape == (H, W) and sun_pair.left.dtype == np.uint8
    assert sun_pair.right.shape == (H, W) and sun_pair.right.dtype == np.uint8
    assert sun_pair.disparity.shape == (H, W) and sun_pair.disparity.dtype == np.float32
    assert sun_pair.nocc.shape == (H, W) and sun_pair.nocc.dtype == bool
    for key in ("f", "baseline", "cx", "cy", "width", "height", "height_m", "pitch_deg", "roll_deg", "ndisp"):
        assert key in sun_pair.calib
    assert sun_pair.calib["cx"] == (W - 1) / 2 and sun_pair.calib["cy"] == (H - 1) / 2
    assert 40.0 <= sun_pair.calib["pitch_deg"] <= 70.0 and abs(sun_pair.calib["roll_deg"]) <= 3.0
    assert 0.1 <= sun_pair.calib["baseline"] <= 0.3 and 1.0 <= sun_pair.calib["height_m"] <= 1.5


def test_render_pair_is_deterministic(sun_pair):
    again = synth.render_pair(seed=7, width=W, height=H, variant="sun", material="asphalt", noise=False)
    other = synth.render_pair(seed=8, width=W, height=H, variant="sun", material="asphalt", noise=False)
    noisy_a = synth.render_pair(seed=3, width=W, height=H, variant="dusk", material="cement")
    noisy_b = synth.render_pair(seed=3, width=W, height=H, variant="dusk", material="cement")
    assert np.array_equal(again.left, sun_pair.left) and np.array_equal(again.right, sun_pair.right)
    assert np.array_equal(again.disparity, sun_pair.disparity) and np.array_equal(again.nocc, sun_pair.nocc)
    assert np.array_equal(noisy_a.left, noisy_b.left) and np.array_equal(noisy_a.right, noisy_b.right)
    assert not np.array_equal(other.left, sun_pair.left)


def test_ground_truth_finite_where_visible_and_in_range(sun_pair):
    disp, nocc = sun_pair.disparity, sun_pair.nocc
    assert np.isfinite(disp[nocc]).all() and (disp[nocc] > 0).all()
    assert nocc.mean() > 0.8
    # Left columns u < d see road outside the right image: never marked visible.
    vv, uu = np.mgrid[0:H, 0:W]
    assert not nocc[uu - disp < 0].any()
    finite = disp[np.isfinite(disp)]
    assert sun_pair.calib["ndisp"] == math.ceil(float(finite.max())) + 8
    # Disparities scale with the width: ~4-15 % of it (40-200 px at 1280).
    assert 0.03 * W < finite.min() and finite.max() < 0.16 * W


def test_self_test_is_at_noise_level_for_sun(sun_pair):
    assert synth.self_test(sun_pair) < 3.0
    noisy = synth.render_pair(seed=7, width=W, height=H, variant="sun", material="asphalt")
    assert synth.self_test(noisy) < 4.0


def test_self_test_detects_a_wrong_ground_truth(sun_pair):
    shifted = synth.SynthPair(sun_pair.left, sun_pair.right, sun_pair.disparity + 1.5, sun_pair.nocc, sun_pair.calib)
    assert synth.self_test(shifted) > 3.0 * synth.self_test(sun_pair)


def test_wet_highlights_differ_between_views():
    # The specular highlight depends on the view direction, so the warped right view
    # does not match the left as well as on a dry road.
    errors = [synth.self_test(synth.render_pair(seed=s, width=W, height=H, variant="wet", noise=False)) for s in (1, 2)]
    assert max(errors) > 4.0


def test_disparity_increases_downward(sun_pair):
    row_means = np.nanmean(np.where(np.isfinite(sun_pair.disparity), sun_pair.disparity, np.nan), axis=1)
    assert (np.diff(row_means) > 0).mean() > 0.9
    assert row_means[-8:].mean() > 1.2 * row_means[:8].mean()


def test_flat_road_follows_the_pt_plane_model_with_the_calib_roll():
    pair = synth.render_pair(seed=11, width=W, height=H, flat=True, noise=False)
    coef, residual = _plane_fit(pair.disparity)
    assert np.abs(residual).max() < 1e-3
    theta = math.radians(pair.calib["roll_deg"])
    # d = a0 + a1 (v cos(theta) - u sin(theta)) (docs/design.md, 'Perspective transformation')
    assert coef[2] > 0
    assert math.degrees(math.atan2(-coef[1], coef[2])) == pytest.approx(pair.calib["roll_deg"], abs=1e-3)
    assert coef[1] == pytest.approx(-coef[2] * math.tan(theta), abs=1e-6)
    # The rig's own numbers: d = f b / Z at the image centre, Z from the left camera's
    # height (the rig's mid-point is at height_m; roll lifts one camera a little).
    keys = ("f", "baseline", "cx", "cy", "width", "height", "height_m", "pitch_deg", "roll_deg")
    rig = synth.StereoRig(**{key: pair.calib[key] for key in keys})
    left_height = rig.centres()[0][2]
    assert left_height == pytest.approx(pair.calib["height_m"], abs=0.01)
    centre_depth = left_height / math.sin(math.radians(pair.calib["pitch_deg"]))
    expected = rig.f * rig.baseline / centre_depth
    assert coef[0] + coef[1] * (W - 1) / 2 + coef[2] * (H - 1) / 2 == pytest.approx(expected, rel=1e-4)


def test_pothole_is_farther_than_the_road_plane():
    pair = synth.render_pair(seed=2, width=2 * W, height=2 * H, potholes=1, noise=False)
    hole = pair.info["potholes"][0]
    _, residual = _plane_fit(pair.disparity)
    u, v = int(round(hole["u"])), int(round(hole["v"]))
    centre = residual[v - 1 : v + 2, u - 1 : u + 2].mean()
    assert centre < -0.2  # a few centimetres deeper = a fraction of a pixel less
    assert centre < -5.0 * np.median(np.abs(residual))


def test_rig_is_rectified():
    rig = synth_rig.sample_rig(np.random.default_rng(5), W, H)
    rot = rig.rotation()
    assert np.allclose(rot @ rot.T, np.eye(3))
    left, right = rig.centres()
    points = np.random.default_rng(1).uniform([-1, 0.5, -0.05], [1, 2.5, 0.05], (50, 3))
    cam_left, cam_right = (points - left) @ rot.T, (points - right) @ rot.T
    v_left = rig.f * cam_left[:, 1] / cam_left[:, 2]
    v_right = rig.f * cam_right[:, 1] / cam_right[:, 2]
    assert np.allclose(v_left, v_right, atol=1e-9)
    disparity = rig.f * (cam_left[:, 0] / cam_left[:, 2] - cam_right[:, 0] / cam_right[:, 2])
    assert np.allclose(disparity, rig.f * rig.baseline / cam_left[:, 2])


def test_occlusion_check_hides_points_under_the_surface():
    flat = np.zeros((64, 64))
    lip = np.full((4, 4), 1e-4)
    points = np.zeros((2, 3, 3))
    points[..., 0] = np.linspace(-0.05, 0.05, 3)
    points[..., 1] = 0.1
    points[1, :, 2] = -0.01  # 1 cm below the road
    visible = synth_render.visible_from(np.array([0.0, 0.0, 1.0]), points, flat, lip, 16, -0.5, -0.5, 0.02, 1e-3, 5e-4)
    assert visible[0].all() and not visible[1].any()


@pytest.mark.parametrize("kwargs", [{"variant": "fog"}, {"material": "gravel"}, {"width": 8}])
def test_render_pair_rejects_bad_arguments(kwargs):
    args = {"seed": 0, "width": W, "height": H, **kwargs}
    with pytest.raises(InputError, match="synth: "):
        synth.render_pair(**args)


def test_pothole_ground_truth_matches_the_analytic_profile():
    # One pothole: the profile is 1 on the floor (rho < flat) and a raised cosine out to
    # rho = 1, where rho is the normalised radius divided by rim(theta) = 1 + a2 cos(2 theta
    # + p2) + a3 cos(3 theta + p3).  Integrating over theta, int rim^2 = 2 pi (1 + (a2^2 +
    # a3^2) / 2); the area deeper than t is pi a b rho_t^2 (1 + (a2^2 + a3^2) / 2) with
    # w(rho_t) = t / D, and the volume D a b int rim^2 int_0^1 rho w(rho) d rho.
    pair = synth.render_pair(seed=2, width=2 * W, height=2 * H, potholes=1, noise=False, shapes="classic")
    (hole,) = pair.info["potholes"]
    (truth,) = pair.defects_gt
    a, b = hole["semi_axes_m"]
    depth, flat = hole["depth_m"], hole["flat_fraction"]
    a2, _, a3, _ = hole["wobble"]
    rim2 = 2 * math.pi * (1 + (a2 ** 2 + a3 ** 2) / 2)
    rho_t = flat + (1 - flat) * math.acos(2 * 0.01 / depth - 1) / math.pi
    rho = np.linspace(0, 1, 20001)
    w = np.where(rho < flat, 1.0, 0.5 * (1 + np.cos(np.pi * np.clip((rho - flat) / (1 - flat), 0, 1))))
    volume = depth * a * b * rim2 * float(np.sum(rho * w) * (rho[1] - rho[0]))
    assert truth["id"] == 1 and truth["depth_mm"] == pytest.approx(1e3 * depth)
    assert truth["area_m2"] == pytest.approx(a * b * rim2 / 2 * rho_t ** 2, rel=0.02)
    assert truth["volume_l"] == pytest.approx(1e3 * volume, rel=0.02)
    # The id mask: the pixels seeing the pothole, around its centre, counted in visible_px.
    ids = pair.pothole_ids
    assert ids.dtype == np.uint8 and set(np.unique(ids)) == {0, 1}
    assert truth["visible_px"] == int((ids == 1).sum()) > 0
    assert ids[int(round(hole["v"])), int(round(hole["u"]))] == 1


def test_generate_dataset_writes_consistent_pair_folders(tmp_path):
    folders = synth.generate_dataset(tmp_path / "out", n=3, seed=4, width=W, height=H)
    names = [f.name for f in folders]
    assert names == ["synth-0000-sun-asphalt", "synth-0001-dusk-cement", "synth-0002-wet-asphalt"]
    import cv2

    for folder in folders:
        files = sorted(p.name for p in folder.iterdir())
        assert files == ["SOURCE.txt", "calib.txt", "defects_gt.json", "disp_gt.pfm", "left.png", "mask0nocc.png",
                         "potholes_gt.png", "right.png"]
        left = cv2.imread(str(folder / "left.png"), cv2.IMREAD_UNCHANGED)
        right = cv2.imread(str(folder / "right.png"), cv2.IMREAD_UNCHANGED)
        mask = cv2.imread(str(folder / "mask0nocc.png"), cv2.IMREAD_UNCHANGED)
        disp = formats.read_pfm(folder / "disp_gt.pfm")
        assert left.shape == right.shape == mask.shape == disp.shape == (H, W)
        assert left.dtype == np.uint8 and set(np.unique(mask)) <= {0, 255}
        assert np.isfinite(disp[mask > 0]).all()
        source = dict(line.split(": ", 1) for line in (folder / "SOURCE.txt").read_text().splitlines())
        calib = dict(line.split(": ", 1) for line in (folder / "calib.txt").read_text().splitlines())
        assert source["gt_scale"] == "1" and source["gt_invalid"] == "inf" and source["family"] == "synth"
        ndisp = math.ceil(float(disp[np.isfinite(disp)].max())) + 8
        assert int(calib["ndisp"]) == int(source["max_disparity"]) == ndisp
        assert int(calib["width"]) == W and int(calib["height"]) == H
        # The recorded pair seed reproduces the pair bit for bit.
        again = synth.render_pair(seed=int(source["pair_seed"]), width=W, height=H,
                                  variant=source["variant"], material=source["material"])
        assert np.array_equal(again.left, left) and np.array_equal(again.right, right)
        assert np.array_equal(again.disparity, disp) and np.array_equal(again.nocc, mask > 0)
    # Same seed, same files; no temporary files left behind.
    second = synth.generate_dataset(tmp_path / "again", n=1, seed=4, width=W, height=H)[0]
    assert (second / "left.png").read_bytes() == (folders[0] / "left.png").read_bytes()
    assert (second / "disp_gt.pfm").read_bytes() == (folders[0] / "disp_gt.pfm").read_bytes()
    assert not [p for p in (tmp_path / "out").rglob(".*")]


def test_generated_folders_are_read_by_the_io_and_datasets_modules(tmp_path):
    io, datasets = formats, layouts
    folder = synth.generate_dataset(tmp_path, n=1, seed=9, width=W, height=H)[0]
    pair = datasets.discover([tmp_path])[0]
    assert pair.name == folder.name and pair.family == "synth" and pair.gt_invalid == "inf"
    gt, mask = datasets.load_ground_truth(pair, (H, W))
    assert np.array_equal(gt, formats.read_pfm(folder / "disp_gt.pfm"))
    assert pair.max_disparity == io.read_calib(folder / "calib.txt")["ndisp"]


def test_generate_dataset_rejects_zero_pairs(tmp_path):
    with pytest.raises(InputError, match="at least one pair"):
        synth.generate_dataset(tmp_path, n=0)


def test_pfm_bytes_of_the_ground_truth_writer(tmp_path):
    disp = np.arange(12, dtype=np.float32).reshape(3, 4)
    disp[0, 0] = np.inf
    formats.write_pfm(tmp_path / "d.pfm", disp)
    data = (tmp_path / "d.pfm").read_bytes()
    assert data == b"Pf\n4 3\n-1.0\n" + np.flipud(disp).astype("<f4").tobytes()
    assert np.array_equal(formats.read_pfm(tmp_path / "d.pfm"), disp)
