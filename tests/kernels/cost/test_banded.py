"""The out-of-view invalidation on banded volumes against the same driver on the full-range volume whose
missing cells hold +inf (tests/kernels/test_volume.py says why that must hold)."""

from __future__ import annotations

import numpy as np
from tests.kernels.banded import case

from d3cli.kernels import cpu
from d3cli.kernels.volume import Volume, to_dense


def test_banded_invalidation_sets_only_out_of_view_cells(case):
    _, vol, _ = case
    flat = vol.cost.copy()
    cpu.invalidate_out_of_view(Volume(flat, vol.index, vol.n_disp))
    before = to_dense(vol.cost, vol.index, vol.n_disp)
    after = to_dense(flat, vol.index, vol.n_disp)
    u = np.arange(vol.shape[1])[None, :, None]
    d = np.arange(vol.n_disp)[None, None, :]
    exists = ~np.isnan(before)
    np.testing.assert_array_equal(after[exists & (d > u)], 1.0)
    np.testing.assert_array_equal(after[exists & (d <= u)], before[exists & (d <= u)])
