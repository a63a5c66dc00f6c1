"""End-to-end tests of ``D3Stereo.compute`` on synthetic pairs with exact disparity.

Each scene is rendered here from a smooth random texture: the left view samples the
texture at (u, v) and the right view at the left point that lands on it, i.e. the right
pixel x shows T(u*, v) with u* - d(u*, v) = x (solved by fixed-point iteration, exact
for planes), using bilinear interpolation.  The error bounds are about twice what the
default configuration measured when these tests were written (see each test).
"""

from __future__ import annotations

import cv2
import numba
import numpy as np
import pytest

from d3cli import D3Stereo, InputError, load_config

H, W = 120, 160
PAD = 64  # texture columns beyond either side of the image
BORDER = 8  # rows/columns ignored at the image border


# ----------------------------------------------------------------------------- scenes
def texture(seed: int) -> np.ndarray:
    """A (H, W + 2 PAD) float32 texture on the 0-255 scale with fine and coarse detail.

    The coarse octaves keep the coarsest pyramid level (1/8 resolution) matchable.
    """
    rng = np.random.default_rng(seed)
    tex = np.zeros((H, W + 2 * PAD), np.float32)
    for sigma, amplitude in ((1.0, 1.0), (3.0, 0.8), (8.0, 0.6)):
        noise = cv2.GaussianBlur(rng.uniform(-1, 1, tex.shape).astype(np.float32), (0, 0), sigma)
        tex += amplitude * noise / noise.std()
    tex -= tex.min()
    return tex * np.float32(255.0 / tex.max())


def sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear sample along rows: T(u, v) for real image columns u and integer rows v."""
    x = u + PAD
    x0 = np.floor(x).astype(int)
    frac = x - x0
    rows = v.astype(int)
    return ((1 - frac) * tex[rows, x0] + frac * tex[rows, x0 + 1]).astype(np.float32)


def pixel_grid():
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return u, v


def render(disparity, *, seed: int):
    """(left, right, gt) for a smooth left-view disparity function d(u, v)."""
    tex = texture(seed)
    u, v = pixel_grid()
    left = sample(tex, u, v)
    source = u + disparity(u, v)
    for _ in range(40):  # u* = x + d(u*, v); |dd/du| < 1 makes this converge
        source = u + disparity(source, v)
    right = sample(tex, source, v)
    return left, right, disparity(u, v).astype(np.float32)


def constant_scene():
    return render(lambda u, v: np.full_like(u, 6.0), seed=0)


def slanted_scene():
    return render(lambda u, v: 4.0 + 0.05 * u + 0.03 * v, seed=1)


POTHOLE = dict(u=80.0, v=80.0, radius_u=14.0, radius_v=10.0, depth=2.0)


def road_disparity(u, v):
    """Road plane (disparity linear in v) with a smooth pothole: a 2 px depression."""
    bump = np.exp(-(((u - POTHOLE["u"]) / POTHOLE["radius_u"]) ** 2 + ((v - POTHOLE["v"]) / POTHOLE["radius_v"]) ** 2))
    return 2.0 + 0.12 * v - POTHOLE["depth"] * bump


def road_scene():
    return render(road_disparity, seed=2)


FOREGROUND = dict(u0=60, u1=120, v0=30, v1=90, d=14.0)
BACKGROUND_D = 4.0


def in_foreground(u, v):
    f = FOREGROUND
    return (u >= f["u0"]) & (u < f["u1"]) & (v >= f["v0"]) & (v < f["v1"])


def step_scene():
    """A fronto-parallel rectangle (d = 14) in front of a plane (d = 4), own textures.

    Returns left, right, gt and the mask of left pixels occluded in the right view.
    """
    back, front = texture(3), texture(103)
    u, v = pixel_grid()
    df = FOREGROUND["d"]
    left = np.where(in_foreground(u, v), sample(front, u, v), sample(back, u, v))
    # right pixel x sees the foreground when the left point x + df is foreground
    right = np.where(in_foreground(u + df, v), sample(front, u + df, v), sample(back, u + BACKGROUND_D, v))
    gt = np.where(in_foreground(u, v), df, BACKGROUND_D).astype(np.float32)
    occluded = ~in_foreground(u, v) & in_foreground(u - BACKGROUND_D + df, v)
    return left, right, gt, occluded


# ----------------------------------------------------------------------------- helpers
def cfg(*overrides):
    return load_config(overrides=["run.backend=cpu", *overrides])


@pytest.fixture(scope="module")
def matcher():
    return D3Stereo(cfg())


def interior(max_disparity: int) -> np.ndarray:
    """Pixels away from the border and from the columns without a full disparity range."""
    mask = np.zeros((H, W), bool)
    mask[BORDER:-BORDER, BORDER + max_disparity:-BORDER] = True
    return mask


def end_point_error(result, gt, mask) -> float:
    return float(np.mean(np.abs(result.disparity[mask] - gt[mask])))


# ----------------------------------------------------------------------------- accuracy
def test_constant_shift(matcher):
    left, right, gt = constant_scene()
    result = matcher.compute(left, right, max_disparity=16)
    inner = interior(16)
    # measured: EPE 0.031 px (max 0.15 px), 100 % of the interior and 96 % of the image decided
    assert end_point_error(result, gt, inner) < 0.06
    assert np.abs(result.disparity[inner] - gt[inner]).max() < 0.4
    assert result.valid[inner].mean() > 0.97
    assert result.valid.mean() > 0.85
    assert result.disparity.dtype == np.float32 and result.disparity.shape == (H, W)
    assert np.isfinite(result.disparity).all()  # filled
    assert result.warnings == []


def test_slanted_plane(matcher):
    left, right, gt = slanted_scene()
    result = matcher.compute(left, right, max_disparity=24)
    inner = interior(24)
    # measured: EPE 0.057 px, 0 % above 1 px, 94 % of the interior and 90 % of the image decided
    assert end_point_error(result, gt, inner) < 0.11
    assert np.mean(np.abs(result.disparity[inner] - gt[inner]) > 1) < 0.005
    assert result.valid[inner].mean() > 0.88
    assert result.valid.mean() > 0.8


def test_road_plane_with_pothole(matcher):
    left, right, gt = road_scene()
    result = matcher.compute(left, right, max_disparity=24)
    u, v = pixel_grid()
    depression = gt < (2.0 + 0.12 * v) - 0.2  # where the pothole is at least 0.2 px deep
    inner = interior(24)
    road = inner & ~depression
    pothole = inner & depression
    error = np.abs(result.disparity - gt)
    # measured: road EPE 0.069 px, pothole EPE 0.093 px, 1.77 of its 2 px depth seen at
    # the centre, 97 % of the interior decided
    assert end_point_error(result, gt, road) < 0.14
    assert pothole.sum() > 500
    assert error[pothole].mean() < 0.2
    deepest = (np.abs(u - POTHOLE["u"]) <= 3) & (np.abs(v - POTHOLE["v"]) <= 2)
    assert np.median(result.disparity[deepest] - (2.0 + 0.12 * v[deepest])) < -1.3
    assert result.valid[inner].mean() > 0.9


def test_two_planes_with_a_step(matcher):
    left, right, gt, occluded = step_scene()
    result = matcher.compute(left, right, max_disparity=24)
    inner = interior(24) & ~occluded
    foreground = in_foreground(*pixel_grid()).astype(np.uint8)
    square = np.ones((13, 13), np.uint8)
    edge_band = cv2.dilate(foreground, square) != cv2.erode(foreground, square)  # within 6 px of the step
    error = np.abs(result.disparity - gt)
    # measured: EPE 0.037 px away from the step, 0.49 px within 6 px of it, 0.13 px
    # overall, 1.1 % of the pixels wrong by more than 1 px, 97 % decided
    assert error[inner & ~edge_band].mean() < 0.08
    assert error[inner & edge_band].mean() < 1.0
    assert error[inner].mean() < 0.27
    assert np.mean(error[inner] > 1) < 0.025
    assert np.median(result.disparity[in_foreground(*pixel_grid()) & ~edge_band]) == pytest.approx(14, abs=0.1)
    assert result.valid[inner].mean() > 0.9


def test_no_fill_leaves_inf_exactly_where_undecided():
    left, right, gt, _ = step_scene()
    # without the final smoothing, which moves a value by more than the sub-pixel half pixel
    result = D3Stereo(cfg("refine.fill=false", "refine.smooth_radius=0")).compute(left, right, max_disparity=24)
    np.testing.assert_array_equal(np.isfinite(result.disparity), result.valid)
    assert 0.8 < result.valid.mean() < 1.0
    assert len(result.levels) == 4 and result.levels[0].shape == (H, W)
    # valid = decided at level 1, less what the occlusion check rejected
    assert not (result.valid & (result.levels[0] < 0)).any()
    assert (result.levels[0] >= 0).mean() - result.valid.mean() < 0.05
    # sub-pixel values stay within half a pixel of the integer map
    decided = result.valid
    assert np.abs(result.disparity[decided] - result.levels[0][decided]).max() <= 0.5


def test_no_decided_match_falls_outside_the_right_image(matcher):
    left, right, _ = slanted_scene()
    result = matcher.compute(left, right, max_disparity=24)
    for level_map in result.levels:
        columns = np.arange(level_map.shape[1])[None, :]
        assert not ((level_map >= 0) & (level_map > columns)).any()


# ----------------------------------------------------------------------------- special pairs
def test_identical_images_give_zero_disparity(matcher):
    left, _, _ = constant_scene()
    result = matcher.compute(left, left.copy(), max_disparity=16)
    assert result.valid.all()
    assert (result.disparity == 0).all()


def test_flat_pair_has_no_seeds_and_no_disparity():
    flat = np.full((40, 64), 128, np.uint8)
    for fill in ("true", "false"):
        result = D3Stereo(cfg(f"refine.fill={fill}")).compute(flat, flat, max_disparity=16)
        assert any("no decisive seeds" in w for w in result.warnings)
        assert not result.valid.any()
        assert np.isinf(result.disparity).all()  # documented: nothing to fill from
        assert result.info["decided_share"] == 0.0


def test_colour_and_16_bit_inputs_match_grey(matcher):
    left, right, _ = constant_scene()
    left8, right8 = np.rint(left).astype(np.uint8), np.rint(right).astype(np.uint8)
    grey = matcher.compute(left8, right8, max_disparity=16)
    colour = matcher.compute(np.repeat(left8[..., None], 3, 2), np.repeat(right8[..., None], 3, 2), max_disparity=16)
    deep = matcher.compute(left8.astype(np.uint16) * 257, right8.astype(np.uint16) * 257, max_disparity=16)
    np.testing.assert_allclose(colour.disparity, grey.disparity, atol=1e-3)
    assert deep.disparity.tobytes() == grey.disparity.tobytes()


# ----------------------------------------------------------------------------- determinism
def test_two_runs_are_bit_identical(matcher):
    left, right, _, _ = step_scene()
    first = matcher.compute(left, right, max_disparity=24)
    second = matcher.compute(left, right, max_disparity=24)
    assert first.disparity.tobytes() == second.disparity.tobytes()
    assert all(a.tobytes() == b.tobytes() for a, b in zip(first.levels, second.levels))


def test_one_thread_and_all_threads_are_bit_identical(matcher):
    left, right, _ = road_scene()
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = matcher.compute(left, right, max_disparity=24)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        multi = matcher.compute(left, right, max_disparity=24)
    finally:
        numba.set_num_threads(before)
    assert single.disparity.tobytes() == multi.disparity.tobytes()
    assert single.valid.tobytes() == multi.valid.tobytes()
    assert [s["sweeps"] for s in single.info["per_level"]] == [s["sweeps"] for s in multi.info["per_level"]]


# ----------------------------------------------------------------------------- input errors
@pytest.fixture(scope="module")
def small_pair():
    rng = np.random.default_rng(9)
    left = rng.integers(0, 256, (24, 32), dtype=np.uint8)
    return left, np.roll(left, -2, axis=1)


@pytest.mark.parametrize("max_disparity", [0, -3, 32, 100])
def test_max_disparity_outside_the_image_width_is_an_input_error(matcher, small_pair, max_disparity):
    with pytest.raises(InputError, match=r"max disparity .*\[1, 31\].*;"):
        matcher.compute(*small_pair, max_disparity=max_disparity)


def test_max_disparity_at_the_limits_is_accepted(matcher, small_pair):
    for max_disparity in (1, 31):
        result = matcher.compute(*small_pair, max_disparity=max_disparity)
        assert result.disparity.shape == (24, 32)


def test_shape_mismatch_is_an_input_error(matcher, small_pair):
    left, right = small_pair
    with pytest.raises(InputError, match=r"left is 24x32 but right is 24x30; a stereo pair needs equal sizes"):
        matcher.compute(left, right[:, :30], max_disparity=8)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_float_input_is_an_input_error(matcher, small_pair, bad):
    left = small_pair[0].astype(np.float32)
    left[3, 4] = bad
    with pytest.raises(InputError, match=r"left image: .*NaN.*;"):
        matcher.compute(left, small_pair[1].astype(np.float32), max_disparity=8)


@pytest.mark.parametrize("shape", [(0, 10), (5,), (2, 3, 4, 5)])
def test_empty_or_wrongly_shaped_input_is_an_input_error(matcher, shape):
    img = np.zeros(shape, np.float32)
    with pytest.raises(InputError):
        matcher.compute(img, img, max_disparity=1)


# ----------------------------------------------------------------------------- smoothing (refine.smooth_radius)
def test_smooth_disparity_averages_noise_and_keeps_a_step():
    from d3cli.method.refinement import smooth_disparity

    rng = np.random.default_rng(3)
    truth = np.where(np.arange(80)[None, :] < 40, 20.0, 30.0) * np.ones((60, 1))
    noisy = (truth + rng.normal(0.0, 0.3, truth.shape)).astype(np.float32)
    out = smooth_disparity(noisy, np.ones(truth.shape, bool), radius=5, sigma=1.0)
    inner = np.s_[10:50, 10:70]
    assert np.abs(out - truth)[inner].std() < 0.5 * np.abs(noisy - truth)[inner].std()
    # The 10 px step stays a step: the columns next to it keep their own side's level.
    assert np.abs(out[:, 38:40] - 20.0).max() < 0.3
    assert np.abs(out[:, 40:42] - 30.0).max() < 0.3


def test_smooth_disparity_residual_to_plane_and_linear_ramp():
    from d3cli.method.refinement import smooth_disparity

    rows, cols = np.mgrid[0:50, 0:70].astype(np.float32)
    ramp = (40.0 + 0.3 * rows + 0.1 * cols).astype(np.float32)
    valid = np.ones(ramp.shape, bool)
    # A linear ramp is kept away from the border (symmetric box); the range levels of the
    # piecewise-linear filter leave an error of a few thousandths of a pixel.
    out = smooth_disparity(ramp, valid, radius=4, sigma=1.0)
    np.testing.assert_allclose(out[6:-6, 6:-6], ramp[6:-6, 6:-6], atol=0.01)
    # With the ramp as plane the residual is 0 everywhere: exact even at the border.
    out = smooth_disparity(ramp, valid, radius=4, sigma=0.5, plane=ramp)
    np.testing.assert_allclose(out, ramp, atol=1e-4)


def test_smooth_disparity_ignores_invalid_and_keeps_inf():
    from d3cli.method.refinement import smooth_disparity

    disp = np.full((20, 20), 10.0, np.float32)
    disp[5, 5] = np.inf
    disp[10, 10] = 10.4  # not valid: never averaged into others, itself smoothed
    valid = np.isfinite(disp)
    valid[10, 10] = False
    out = smooth_disparity(disp, valid, radius=2, sigma=1.0)
    assert np.isinf(out[5, 5])
    np.testing.assert_allclose(np.delete(out.ravel(), 5 * 20 + 5), 10.0, atol=1e-5)
    same = smooth_disparity(disp, valid, radius=0, sigma=1.0)
    assert same is not disp and np.array_equal(same, disp)


def test_smooth_keys_are_checked_by_the_config():
    from d3cli import ConfigError

    cfg = load_config(None, ["refine.smooth_radius=3", "refine.smooth_sigma=0.5"])
    assert cfg.refine.smooth_radius == 3 and cfg.refine.smooth_sigma == 0.5
    with pytest.raises(ConfigError, match="smooth_radius"):
        load_config(None, ["refine.smooth_radius=-1"])
    with pytest.raises(ConfigError, match="smooth_sigma"):
        load_config(None, ["refine.smooth_sigma=0"])


def test_smooth_radius_changes_the_output_and_lowers_the_error_of_a_noisy_plane():
    left, right, gt = slanted_scene()
    rng = np.random.default_rng(0)
    noisy_l = np.clip(left + rng.normal(0, 10, left.shape), 0, 255).astype(np.float32)
    noisy_r = np.clip(right + rng.normal(0, 10, right.shape), 0, 255).astype(np.float32)
    plain = D3Stereo(cfg("refine.smooth_radius=0")).compute(noisy_l, noisy_r, max_disparity=32)
    smooth = D3Stereo(cfg("refine.smooth_radius=3")).compute(noisy_l, noisy_r, max_disparity=32)
    mask = interior(32)
    assert not np.array_equal(plain.disparity, smooth.disparity)
    assert end_point_error(smooth, gt, mask) < end_point_error(plain, gt, mask)
