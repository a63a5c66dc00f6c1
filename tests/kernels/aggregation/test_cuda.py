"""The CUDA aggregation drivers against the CPU ones (marker ``cuda``; tests/kernels/test_cuda.py
says how they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import random_volume

from d3cli.kernels import cpu

pytestmark = pytest.mark.cuda


# ----------------------------------------------------------------------------- aggregation
def test_rbf_weights_match_cpu(gpu):
    img = np.random.default_rng(3).uniform(0, 255, (H, W)).astype(np.float32)
    got = host(gpu, gpu.rbf_weights(gpu.to_device(img), 1.5, 12.0))
    want = cpu.rbf_weights(img, 1.5, 12.0)
    assert got.shape == (H, W, 9) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    assert (got[0, :, :3] == 0).all() and (got[:, -1, 2::3] == 0).all()  # outside the image


@pytest.mark.parametrize("t_max", [0, 1, 3])
def test_rbf_filter_matches_cpu(gpu, t_max):
    rng = np.random.default_rng(4 + t_max)
    img = rng.uniform(0, 255, (H, W)).astype(np.float32)
    cost = random_volume(rng, H, W, 5)
    weights = cpu.rbf_weights(img, 2.0, 20.0)
    d_cost = gpu.to_device(cost)
    got = gpu.rbf_filter(d_cost, gpu.to_device(weights), t_max)
    assert got is not d_cost
    np.testing.assert_allclose(host(gpu, got), cpu.rbf_filter(cost, weights, t_max), rtol=0, atol=COST_ATOL)
    np.testing.assert_array_equal(gpu.to_host(d_cost), cost)  # input untouched


@pytest.mark.parametrize("t_max", [2, 3])
def test_rbf_filter_overwriting_its_input_matches_cpu(gpu, t_max):
    rng = np.random.default_rng(9 + t_max)
    img = rng.uniform(0, 255, (H, W)).astype(np.float32)
    cost = random_volume(rng, H, W, 5)
    weights = cpu.rbf_weights(img, 2.0, 20.0)
    got = gpu.rbf_filter(gpu.to_device(cost), gpu.to_device(weights), t_max, True)
    want = cpu.rbf_filter(cost.copy(), weights, t_max, True)
    np.testing.assert_allclose(host(gpu, got), want, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("radius", [0, 2])
def test_bilateral_filter_matches_cpu(gpu, radius):
    rng = np.random.default_rng(6 + radius)
    shape = (7, 9)
    img = rng.uniform(0, 255, shape).astype(np.float32)
    cost = random_volume(rng, *shape, 3)
    got = host(gpu, gpu.bilateral_filter(gpu.to_device(cost), gpu.to_device(img), radius, 2.0, 15.0))
    np.testing.assert_allclose(got, cpu.bilateral_filter(cost, img, radius, 2.0, 15.0), rtol=0, atol=COST_ATOL)
