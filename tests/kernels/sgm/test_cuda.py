"""The CUDA sgm drivers against the CPU ones (marker ``cuda``; tests/kernels/test_cuda.py
says how they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import banded, random_volume

from d3cli.kernels import cpu
from d3cli.kernels.volume import Volume

pytestmark = pytest.mark.cuda


@pytest.fixture(autouse=True)
def few_lanes(gpu, monkeypatch):
    """Under the simulator, 4 threads per line instead of a warp's 32: every thread runs as
    Python there, and bands wider than 4 still exercise the stride over the lanes."""
    from numba import config

    from d3cli.kernels.sgm import cuda as sgm_cuda

    if config.ENABLE_CUDASIM:
        monkeypatch.setattr(sgm_cuda, "LANES", 4)


@pytest.mark.parametrize("n_disp, levels", [(1, None), (6, 4)])
def test_sgm_smooth_matches_cpu(gpu, n_disp, levels):
    rng = np.random.default_rng(29)
    cost = random_volume(rng, H, W, n_disp, levels=levels)
    got = host(gpu, gpu.sgm_smooth(gpu.to_device(cost), 0.1, 0.4))
    want = cpu.sgm_smooth(cost, 0.1, 0.4)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, want)  # the same float32 additions in the same order


def test_sgm_smooth_of_a_banded_volume_matches_cpu(gpu):
    rng = np.random.default_rng(37)
    lo = rng.integers(0, 5, (H, W))
    hi = np.minimum(9, lo + rng.integers(1, 6, (H, W)))
    volume = banded(rng.random((H, W, 9)).astype(np.float32), lo, hi)
    got = gpu.sgm_smooth(Volume(gpu.to_device(volume.cost), gpu.to_device(volume.index), volume.n_disp), 0.1, 0.4)
    want = cpu.sgm_smooth(volume, 0.1, 0.4)
    np.testing.assert_array_equal(host(gpu, got.cost), want.cost)
