"""Banded cost volumes: the index helpers, and every driver on bands against the same
driver on the full-range volume whose missing cells hold +inf.

A cell outside a pixel's band "does not exist" (``cost_or_inf`` gives inf), so every
decision on a banded volume must equal the decision on the full-range volume with those
cells set to +inf: inf never wins a minimum, never vetoes a local-minimum test, and the
parabola of the sub-pixel step is skipped next to it.  The full-range drivers are checked
against the references of tests/reference/steps.py in test_cpu.py.  The drivers on bands: the rooms' test_banded.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.banded import random_bands
from tests.volumes import banded

from d3cli.kernels.volume import dense_index, is_dense, to_dense


def test_dense_index_is_the_hwd_layout():
    index = dense_index(3, 4, 5)
    assert index.dtype == np.int32 and index.shape == (3, 4, 3)
    cube = np.arange(60, dtype=np.float32).reshape(3, 4, 5)
    np.testing.assert_array_equal(to_dense(cube.ravel(), index, 5), cube)
    assert is_dense(index, 5) and not is_dense(index, 6)


def test_banded_index_packs_bands_and_to_dense_restores_them():
    rng = np.random.default_rng(0)
    cube = rng.random((5, 7, 6)).astype(np.float32)
    lo, hi = random_bands(rng, 5, 7, 6)
    vol = banded(cube, lo, hi)
    assert vol.cost.size == int((hi - lo).sum()) and not np.isnan(vol.cost).any()
    back = to_dense(vol.cost, vol.index, 6)
    inside = (np.arange(6) >= lo[..., None]) & (np.arange(6) < hi[..., None])
    np.testing.assert_array_equal(back[inside], cube[inside])
    assert np.isnan(back[~inside]).all()


def test_an_oversized_volume_is_refused():
    with pytest.raises(MemoryError):
        dense_index(50000, 50000, 2)
