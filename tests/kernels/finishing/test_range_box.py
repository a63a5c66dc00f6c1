"""Box range-kernel smoothing (``d3cli.kernels.finishing.range_box``, ``refine.smooth_kernel:
box``): the kernel against a plain NumPy reference, its glue against the NumPy formulation it
replaced, and known answers through ``d3cli.method.refinement.smooth_disparity``."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.kernels.finishing.range_box import box_range_smooth
from d3cli.method.refinement import smooth_disparity

from tests.reference.finishing import assert_same_bytes, random_map, ref_box_smoothing_glue
from tests.reference.finishing import ref_range_box_float32


def reference(resid, use, radius, threshold):
    """Per pixel: mean of the usable residuals in the clipped box within threshold."""
    h, w = resid.shape
    out = resid.copy()
    for v in range(h):
        for u in range(w):
            rp = resid[v, u]
            if not np.isfinite(rp):
                continue
            box = resid[max(0, v - radius):v + radius + 1, max(0, u - radius):u + radius + 1]
            ok = use[max(0, v - radius):v + radius + 1, max(0, u - radius):u + radius + 1]
            with np.errstate(invalid="ignore"):
                sel = ok & (np.abs(box - rp) <= np.float32(threshold))
            if sel.any():
                out[v, u] = box[sel].astype(np.float64).mean()
    return out


@pytest.mark.parametrize("radius,threshold", [(1, 0.5), (2, 3.0), (4, 1.5)])
def test_box_range_smooth_matches_numpy(radius, threshold):
    rng = np.random.default_rng(radius)
    resid = (np.kron(rng.integers(0, 4, (5, 6)), np.ones((6, 6))) * 4.0 + rng.normal(0, 1.0, (30, 36)))
    resid = resid.astype(np.float32)
    resid[rng.random(resid.shape) < 0.05] = np.inf  # no estimate
    use = np.isfinite(resid) & (rng.random(resid.shape) > 0.1)
    got = box_range_smooth(resid, use, radius, threshold)
    want = reference(resid, use, radius, threshold)
    np.testing.assert_array_equal(np.isinf(got), np.isinf(resid))
    fin = np.isfinite(resid)
    # float32 sums in the kernel, float64 in the reference
    np.testing.assert_allclose(got[fin], want[fin], rtol=0, atol=2e-5)


def test_box_smoothing_keeps_a_step_and_a_ramp_and_averages_noise():
    rows, cols = np.mgrid[0:40, 0:60].astype(np.float32)
    ramp = 30.0 + 0.3 * rows + 0.1 * cols
    truth = np.where(cols < 30, ramp, ramp + 12.0).astype(np.float32)  # a 12 px object edge
    valid = np.ones(truth.shape, bool)
    out = smooth_disparity(truth, valid, radius=4, sigma=3.0, kernel="box")
    inner = np.s_[4:-4, 4:-4]
    # a symmetric box keeps a linear ramp exactly (up to float32): away from the border and
    # from the edge (whose far side is out of range, which makes the box one-sided)
    away = np.s_[4:-4, list(range(4, 26)) + list(range(34, 56))]
    np.testing.assert_allclose(out[away], truth[away], atol=1e-4)
    # next to the edge only its own side is averaged: off by the one-sided ramp mean at most
    assert np.abs(out - truth)[inner].max() < 0.25
    rng = np.random.default_rng(0)
    noisy = (truth + rng.normal(0, 0.5, truth.shape)).astype(np.float32)
    out = smooth_disparity(noisy, valid, radius=4, sigma=3.0, kernel="box")
    assert np.abs(out - truth)[inner].mean() < 0.4 * np.abs(noisy - truth)[inner].mean()
    assert np.abs(out - truth)[:, 26:34].max() < 2.0  # next to the edge: its own side


def test_box_smoothing_with_a_plane_and_invalid_pixels():
    plane = np.tile(np.linspace(10, 20, 25, dtype=np.float32), (20, 1))
    disp = plane + 1.0
    disp[3, 3] = np.inf
    valid = np.isfinite(disp)
    valid[8, 8] = False
    disp[8, 8] = plane[8, 8] + 1.5  # not valid: never averaged in, itself smoothed to +1
    out = smooth_disparity(disp, valid, radius=2, sigma=1.0, plane=plane, kernel="box")
    assert np.isinf(out[3, 3])
    fin = np.isfinite(disp)
    np.testing.assert_allclose(out[fin], (plane + 1.0)[fin], atol=1e-5)
    with pytest.raises(ValueError, match="gaussian or box"):
        smooth_disparity(disp, valid, radius=2, sigma=1.0, kernel="median")


@pytest.mark.parametrize("shape", [(1, 1), (3, 5), (9, 8), (30, 36), (17, 61)])
@pytest.mark.parametrize("radius", [1, 2, 3, 4, 5])
def test_box_range_smooth_sums_in_the_fixed_order_bit_for_bit(shape, radius):
    """The same bytes as the per-offset float32 sums (the kernel sums three offsets per
    pass in the middle of a row and one by one at its ends, in the same order), maps
    narrower than the box included."""
    rng = np.random.default_rng(radius * 100 + shape[1])
    resid = (rng.normal(0, 2.0, shape) + 3.0).astype(np.float32)
    resid[rng.random(shape) < 0.05] = np.inf
    resid[rng.random(shape) < 0.05] = -0.0
    use = np.isfinite(resid) & (rng.random(shape) > 0.2)
    got = box_range_smooth(resid, use, radius, 1.5)
    want = ref_range_box_float32(resid, use, radius, 1.5)
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("shape", [(1, 1), (5, 7), (40, 64)])
@pytest.mark.parametrize("with_plane", [False, True])
def test_box_smoothing_glue_matches_the_numpy_formulation(shape, with_plane):
    rng = np.random.default_rng(hash((shape, with_plane)) % 2**32)
    disp, valid = random_map(rng, shape, spread=10)
    disp[rng.random(shape) < 0.1] = -0.0  # -0 + 0 is +0: the sum back keeps the NumPy order
    disp[rng.random(shape) < 0.05] = -np.inf
    plane = (rng.random(shape) * 4 - 2).astype(np.float32) if with_plane else None
    for radius in (1, 3):
        want = ref_box_smoothing_glue(disp, valid, plane,
                                      lambda r, u: box_range_smooth(r, u, radius, 1.5))
        got = smooth_disparity(disp, valid, radius=radius, sigma=1.5, plane=plane, kernel="box")
        assert_same_bytes(got, want, f"{shape} {radius}")

