"""The CUDA cost drivers against the CPU ones (marker ``cuda``; tests/kernels/test_cuda.py
says how they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import random_images

from d3cli.kernels import cpu

pytestmark = pytest.mark.cuda


# ----------------------------------------------------------------------------- NCC cost
@pytest.mark.parametrize("window, max_disparity, band_rows", [(3, 6, None), (5, 7, 3), (1, 0, None)])
def test_ncc_cost_volume_matches_cpu(gpu, monkeypatch, window, max_disparity, band_rows):
    rng = np.random.default_rng(window)
    left, right = random_images(rng, (H, W))
    left[2:9, 1:6] = 117.0  # flat windows: cost 1
    right[6:, 15:] = 40.0
    if band_rows:  # a scratch of 3 rows: the volume is computed in 4 bands
        from d3cli.kernels.cost import cuda as cost_cuda  # where the driver reads it

        monkeypatch.setattr(cost_cuda, "NCC_SCRATCH_BYTES", band_rows * (W + 1) * (max_disparity + 1) * 8)
    got = host(gpu, gpu.ncc_cost_volume(gpu.to_device(left), gpu.to_device(right), max_disparity, window, 0.5))
    want = cpu.ncc_cost_volume(left, right, max_disparity, window, 0.5)
    assert got.shape == want.shape and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)
    assert (got[:, :, 1:][want[:, :, 1:] == 1.0] == 1.0).all()  # missing and flat cells exactly 1


def test_invalidate_out_of_view_matches_cpu(gpu):
    rng = np.random.default_rng(2)
    cost = rng.random((H, W, 6)).astype(np.float32) * 0.9
    want = cpu.invalidate_out_of_view(cost.copy())
    d_cost = gpu.to_device(cost)
    got = gpu.invalidate_out_of_view(d_cost)
    np.testing.assert_array_equal(host(gpu, got), want)
    np.testing.assert_array_equal(gpu.to_host(d_cost), want)  # in place
    on_host = cost.copy()
    gpu.invalidate_out_of_view(on_host)
    np.testing.assert_array_equal(on_host, want)  # a host volume is updated in place too
