"""The CUDA perspective drivers against the CPU ones (marker ``cuda``; tests/kernels/test_cuda.py
says how they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)

from d3cli.kernels import cpu

pytestmark = pytest.mark.cuda


# ----------------------------------------------------------------------------- perspective transformation
PT_MODELS = [(5.3, 0.21, -0.07, 2.0), (-3.0, 0.0, 0.4, 8.0), (30.0, 1.5, 0.0, 0.5)]  # shifts out of the image too


@pytest.mark.parametrize("model", PT_MODELS)
def test_pt_warp_matches_cpu(gpu, model):
    right = np.random.default_rng(31).uniform(0, 255, (H, W)).astype(np.float32)
    got = host(gpu, gpu.pt_warp(gpu.to_device(right), *model))
    want = cpu.pt_warp(right, *model)
    assert got.dtype == np.float32 and got.shape == (H, W)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-4)  # 0-255 grey levels


@pytest.mark.parametrize("model", PT_MODELS)
def test_pt_restore_matches_cpu(gpu, model):
    rng = np.random.default_rng(32)
    disp = rng.uniform(0, 18, (H, W)).astype(np.float32)
    disp[rng.random((H, W)) < 0.3] = np.inf
    got = host(gpu, gpu.pt_restore(gpu.to_device(disp), *model))
    want = cpu.pt_restore(disp, *model)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(np.isinf(got), np.isinf(disp))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=COST_ATOL)
