"""The CUDA smoothing (``d3cli.kernels.finishing.cuda_smoothing``) against the CPU's
``smooth_map`` (marker ``cuda``; tests/kernels/test_cuda.py says how they run): the same
bytes for the box and the Gaussian range kernels, with and without the road plane, clamped
or not, on small random maps with inf / NaN pixels and odd sizes."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.reference.finishing import random_map

from d3cli.kernels import finishing

pytestmark = pytest.mark.cuda

PLANE = (2.5, 0.375, -0.125)  # a0, b1, b2: a slanted plane (negative values on the right)


@pytest.fixture
def smoothing(gpu):
    from d3cli.kernels.finishing import cuda_smoothing

    return cuda_smoothing


def _map(shape, seed, spread=6.0):
    """Disparities in [-1.5, spread - 1.5) (some negative: the clamp), inf and NaN holes, one
    row with nothing finite (where the map has more than two rows)."""
    disp, valid = random_map(np.random.default_rng(seed), shape, valid_share=0.8, spread=spread)
    disp = np.where(valid, disp - np.float32(1.5), disp).astype(np.float32)
    return np.ascontiguousarray(disp)


def _same(gpu, smoothing, disp, radius, sigma, kernel, plane, non_negative, what):
    want = finishing.smooth_map(disp, radius, sigma, kernel, plane, non_negative)
    got = host(gpu, smoothing.smooth_map(disp, radius, sigma, kernel, plane, non_negative))
    assert got.dtype == np.float32 and got.shape == disp.shape
    assert got.tobytes() == want.tobytes(), f"{what}: {np.nanmax(np.abs(got.astype(np.float64) - want))}"


@pytest.mark.parametrize("shape,radius", [((1, 1), 1), ((4, 3), 2), ((7, 13), 3), ((9, 6), 4)])
def test_box_smoothing_matches_cpu(gpu, smoothing, shape, radius):
    disp = _map(shape, 1 + radius)
    for plane in (None, PLANE):
        for non_negative in (False, True):
            _same(gpu, smoothing, disp, radius, 1.5, "box", plane, non_negative, f"{shape} {plane} {non_negative}")


@pytest.mark.parametrize("shape,radius", [((4, 7), 1), ((5, 4), 2), ((6, 7), 3)])
def test_gaussian_smoothing_matches_cpu(gpu, smoothing, shape, radius):
    """Radius 1 and 2: the row pass's direct sums; 3: its running sums (about 8 levels)."""
    disp = _map(shape, 11 + radius)
    for plane, non_negative in ((None, False), (PLANE, True)):
        _same(gpu, smoothing, disp, radius, 0.75, "gaussian", plane, non_negative, f"{shape} {plane} {non_negative}")


def test_gaussian_smoothing_with_spread_levels_in_several_launches(gpu, smoothing, monkeypatch):
    """A wide range (the level spacing grows past sigma: 256 levels at most) whose columns
    hold close values (neighbours within sigma), filtered 12 levels per launch pair, 3 per
    thread."""
    rng = np.random.default_rng(3)
    disp = (np.linspace(0.0, 600.0, 7)[None, :] + rng.normal(0.0, 1.0, (5, 7))).astype(np.float32)
    disp[1, 2], disp[3, 5] = np.inf, np.nan
    monkeypatch.setattr(smoothing, "LEVEL_BYTES", 16 * 5 * 7 * 12)  # 12 levels per launch pair
    monkeypatch.setattr(smoothing, "LEVEL_LANES", 4)
    assert smoothing.levels_per_launch(5, 7) == 12
    _same(gpu, smoothing, disp, 2, 2.0, "gaussian", None, True, "spread")
    unsmoothed = finishing.smooth_map(disp, 0, 2.0, "gaussian", None, True)
    assert np.sum(finishing.smooth_map(disp, 2, 2.0, "gaussian", None, True) != unsmoothed) > 20


@pytest.mark.parametrize("kernel", ["box", "gaussian"])
def test_smoothing_of_maps_without_estimates_and_radius_0(gpu, smoothing, kernel):
    empty = np.full((3, 4), np.inf, np.float32)
    empty[1, 2] = np.nan
    disp = _map((4, 5), 5)
    for d, radius in ((empty, 2), (disp, 0)):
        for non_negative in (False, True):
            _same(gpu, smoothing, d, radius, 1.0, kernel, PLANE, non_negative, f"{radius} {non_negative}")
    with pytest.raises(ValueError, match="gaussian or box"):
        smoothing.smooth_map(disp, 2, 1.0, "median", None, False)


def test_simulator_fma_rounds_once():
    from d3cli.kernels.finishing.cuda_smoothing import fma_f32_exact

    rng = np.random.default_rng(0)
    a, b, c = (rng.normal(0, 4, 2000).astype(np.float32) for _ in range(3))
    # float64 holds a * b exactly and a * b + c to 1 ulp: the once-rounded sum, except at ties
    want = (a.astype(np.float64) * b + c).astype(np.float32)
    got = np.array([fma_f32_exact(x, y, z) for x, y, z in zip(a, b, c)], np.float32)
    assert np.array_equal(got, want)
    # (1 + 2^-12)^2 + 2^-60 = 1 + 2^-11 + 2^-24 + 2^-60: float64 drops the 2^-60 and leaves a
    # float32 tie (rounded to even: down); once rounded it goes up
    a, c = np.float32(1.0 + 2.0**-12), np.float32(2.0**-60)
    assert np.float32(float(a) * float(a) + float(c)) == np.float32(1.0 + 2.0**-11)
    assert fma_f32_exact(a, a, c) == np.float32(1.0 + 2.0**-11 + 2.0**-23)
