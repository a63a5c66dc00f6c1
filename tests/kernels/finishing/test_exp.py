"""NumPy's float32 ``exp`` inside the kernels (``d3cli.kernels.finishing.exp``) against
``np.exp``, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from d3cli.kernels import finishing

from tests.reference.finishing import assert_same_bytes, numpy_exp_is_simd


@pytest.mark.skipif(not numpy_exp_is_simd(), reason="NumPy's float32 exp is the C library's here")
def test_numpy_expf_equals_np_exp_bit_for_bit():
    """All float32 values were checked once (2^32, equal, NaN payloads included); here
    every 4099th bit pattern, the arguments of the smoothing (-100..0), the ends of the
    range (overflow, subnormal and zero results) and the special values."""
    rng = np.random.default_rng(0)
    sweep = np.arange(0, 2**32, 4099, dtype=np.uint64).astype(np.uint32).view(np.float32)
    weights = -(rng.random(500_000) ** 2 * 100).astype(np.float32)
    ends = []
    for edge in (-103.97208404541015625, -87.33654, -0.0, 88.72283935546875):
        centre = np.array([edge], np.float32).view(np.uint32)[0].astype(np.int64)
        ends.append((centre + np.arange(-3000, 3001)).astype(np.uint32).view(np.float32))
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 1e-45, -1e-45, 3.4e38, -3.4e38], np.float32)
    payloads = np.array([0x7FC00001, 0xFFC12345, 0x7F800001], np.uint32).view(np.float32)
    x = np.concatenate([sweep, weights, *ends, special, payloads])
    with np.errstate(all="ignore"):
        want = np.exp(x)
    got = finishing.numpy_exp(x)
    assert_same_bytes(got, want, "numpy_expf")

