"""The CPU perspective warp and restore against the slow references of tests/reference/steps.py."""

from __future__ import annotations

import numpy as np
import pytest
from tests import reference as ref

from d3cli.kernels import cpu


# ----------------------------------------------------------------------------- perspective transformation
@pytest.mark.parametrize("model", [(20.0, 0.1, 0.0, 4.0), (35.5, 0.08, -0.004, 8.0), (3.0, 0.02, 0.01, 2.0)])
def test_pt_warp_matches_reference(model):
    rng = np.random.default_rng(11)
    right = (rng.random((23, 41)) * 255).astype(np.float32)
    got = cpu.pt_warp(right, *model)
    np.testing.assert_allclose(got, ref.ref_pt_warp(right, *model), atol=1e-3)


def test_pt_warp_of_an_integer_shift_is_a_translation_with_replicated_border():
    right = np.tile(np.arange(30, dtype=np.float32) * 3, (5, 1))
    got = cpu.pt_warp(right, 7.0, 0.0, 0.0, 2.0)  # s = 5 everywhere
    np.testing.assert_array_equal(got[:, 5:], right[:, :-5])
    np.testing.assert_array_equal(got[:, :5], np.full((5, 5), right[0, 0]))


@pytest.mark.parametrize("model", [(20.0, 0.1, 0.0, 4.0), (35.5, 0.08, -0.004, 8.0)])
def test_pt_restore_matches_reference_and_keeps_inf(model):
    rng = np.random.default_rng(12)
    disp = (rng.random((17, 29)) * 18).astype(np.float32)
    disp[rng.random(disp.shape) < 0.2] = np.inf
    got = cpu.pt_restore(disp, *model)
    np.testing.assert_allclose(got, ref.ref_pt_restore(disp, *model), rtol=1e-6, atol=1e-4)
    np.testing.assert_array_equal(np.isinf(got), np.isinf(disp))
