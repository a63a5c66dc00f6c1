"""Fixtures and sizes of the CUDA parity tests (every room's test_cuda.py): the backend,
small blocks, host copies.  Imported by name, so that pytest finds the fixtures in each module."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.kernels import cuda_status


COST_ATOL = 1e-5


H, W = 11, 23  # 3 x 6 blocks of 4 x 4 threads, the last row and column of blocks partly filled


@pytest.fixture(scope="module")
def gpu():
    """The CUDA backend module; skips when neither a GPU nor the simulator is usable."""
    usable, why = cuda_status()
    if not usable:
        pytest.skip(f"CUDA is not usable here: {why}")
    from d3cli.kernels import cuda as backend

    return backend


@pytest.fixture(autouse=True)
def small_blocks(gpu, monkeypatch):
    """Blocks of 4 x 4 (2D) and 8 (1D) threads: many partly filled blocks on odd sizes."""
    from d3cli.kernels import cuda_launch  # where the launches read them

    monkeypatch.setattr(cuda_launch, "BLOCK_2D", (4, 4))
    monkeypatch.setattr(cuda_launch, "BLOCK_1D", 8)
    from numba import config

    if config.ENABLE_CUDASIM:  # the smoothing (on by default) with 4 lanes a line: the simulator runs each as Python
        from d3cli.kernels.sgm import cuda as sgm_cuda

        monkeypatch.setattr(sgm_cuda, "LANES", 4)


def host(gpu, array):
    """Download a result, checking that the backend returned a device array."""
    assert not isinstance(array, np.ndarray), "CUDA functions must return device arrays"
    return gpu.to_host(array)
