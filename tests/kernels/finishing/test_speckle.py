"""The speckle filter's passes (``d3cli.kernels.finishing.speckle``) against the NumPy
formulation they replaced: OpenCV's 1/16 px fixed point, and the dropping of the speckles
with the masking of the map.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from d3cli.kernels import finishing
from d3cli.method.refinement import drop_speckles

from tests.reference.finishing import assert_same_bytes, random_map, ref_drop_speckles


def test_fixed_point_16_matches_the_numpy_formulation():
    """The speckle filter's 1/16 px fixed point: ties of the rounding (half to even), both
    ends of the int16 range, negative and huge estimates, holes."""
    rng = np.random.default_rng(8)
    disp = np.concatenate([rng.random(50_000) * 2100, np.arange(-64, 64) / 32.0, np.arange(0, 2100, 1 / 32),
                           [2047.96875, 2047.97, 2048.0, 1e30, 3e38, -5.0, -0.0, 1e-40]]).astype(np.float32)
    valid = rng.random(disp.size) < 0.9
    with np.errstate(over="ignore"):
        want = np.where(valid, np.clip(np.round(disp * 16.0), 0, 32767), -1).astype(np.int16)
    got = finishing.fixed_point_16(disp.reshape(1, -1), valid.reshape(1, -1))
    np.testing.assert_array_equal(got.ravel(), want)


@pytest.mark.parametrize("shape", [(1, 1), (5, 5), (23, 31), (40, 64)])
@pytest.mark.parametrize("max_size", [0, 1, 4, 30])
def test_drop_speckles_matches_the_speckle_filter_and_the_masking(shape, max_size):
    rng = np.random.default_rng(hash((shape, max_size)) % 2**32)
    for share in (0.0, 0.6, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=6)
        disp = np.where(rng.random(shape) < 0.5, np.round(disp), disp).astype(np.float32)  # plateaus
        valid |= ~np.isfinite(disp) & (rng.random(shape) < 0.3)  # valid but inf/NaN: never a speckle
        for max_diff, in_place in ((0.5, True), (2.0, True), (2.0, False)):
            want_valid, want_out, share_want = ref_drop_speckles(disp, valid, max_size=max_size, max_diff=max_diff)
            got_valid = valid.copy()
            src = disp.copy()
            count, got_out = drop_speckles(src, got_valid, max_size=max_size, max_diff=max_diff,
                                           out=src if in_place else None)
            np.testing.assert_array_equal(got_valid, want_valid)
            assert_same_bytes(got_out, want_out, f"{shape} {share} {max_diff}")
            assert count / disp.size == share_want and (got_out is src) == in_place
            assert_same_bytes(src, disp if not in_place else want_out, "the input map")


def test_filter_speckles_on_the_cpu_equals_opencv():
    """The CPU's union-find (the backend's ``drop_speckles``) against ``cv2.filterSpeckles``
    on int16 maps of random small values and holes."""
    rng = np.random.default_rng(1)
    for _ in range(200):
        h, w = (int(x) for x in rng.integers(1, 30, 2))
        fixed = rng.integers(-1, int(rng.integers(1, 50)), (h, w)).astype(np.int16)
        fixed[rng.random((h, w)) < rng.random() * 0.5] = -1
        max_size, max_diff = int(rng.integers(0, 25)), int(rng.integers(1, 16))
        want, got = fixed.copy(), fixed.copy()
        cv2.filterSpeckles(want, -1, max_size, max_diff)
        finishing.filter_speckles(got, max_size, max_diff)
        np.testing.assert_array_equal(got, want, err_msg=f"{h}x{w} {max_size} {max_diff}")


@pytest.mark.parametrize("shape", [(1, 1), (7, 13), (40, 64)])
def test_the_cpu_backends_drop_speckles_matches_the_host_path(shape):
    """The backend contract's ``drop_speckles`` (the union-find) against
    ``refinement.drop_speckles`` (``cv2.filterSpeckles``): the same validity, map and count."""
    rng = np.random.default_rng(hash(shape) % 2**32)
    for share in (0.0, 0.6, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=6)
        disp = np.where(rng.random(shape) < 0.5, np.round(disp), disp).astype(np.float32)
        valid |= ~np.isfinite(disp) & (rng.random(shape) < 0.3)
        for max_size, max_diff in ((0, 2.0), (4, 0.5), (30, 2.0)):
            want_valid = valid.copy()
            want_count, want_out = drop_speckles(disp, want_valid, max_size=max_size, max_diff=max_diff)
            got_valid, got_out = valid.copy(), np.empty(shape, np.float32)
            count = finishing.drop_speckles(disp, got_valid, max_size, max_diff, got_out)
            np.testing.assert_array_equal(got_valid, want_valid)
            assert_same_bytes(got_out, want_out, f"{shape} {share} {max_size}")
            assert count == want_count
