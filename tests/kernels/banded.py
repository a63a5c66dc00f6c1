"""Banded test volumes shared by the rooms' tests: random bands, and a banded volume
beside the full-range one whose missing cells hold +inf."""

from __future__ import annotations

import numpy as np
import pytest
from tests.volumes import banded, random_volume


def random_bands(rng, h, w, n_disp):
    """Bands [lo, hi) per pixel: random, some full, some a single disparity."""
    lo = rng.integers(0, n_disp, (h, w))
    hi = np.minimum(n_disp, lo + rng.integers(1, n_disp + 1, (h, w)))
    full = rng.random((h, w)) < 0.2
    lo[full], hi[full] = 0, n_disp
    return lo, hi


@pytest.fixture(params=[0, 1, 2])
def case(request):
    rng = np.random.default_rng(100 + request.param)
    h, w, n_disp = [(9, 11, 6), (13, 8, 9), (1, 12, 5)][request.param]
    cube = random_volume(rng, h, w, n_disp)
    lo, hi = random_bands(rng, h, w, n_disp)
    vol = banded(cube, lo, hi)
    inside = (np.arange(n_disp) >= lo[..., None]) & (np.arange(n_disp) < hi[..., None])
    with_inf = np.where(inside, cube, np.float32(np.inf)).astype(np.float32)
    return rng, vol, with_inf
