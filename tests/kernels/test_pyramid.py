"""The pyramid's 2x2 area average (d3cli.kernels.pyramid) against the NumPy expression it
replaced: the same bytes, for odd sizes, off-grid values, NaN and inf, any thread count."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from d3cli.kernels import pyramid
from d3cli.method.pyramid import build_pyramid, downsample


def numpy_halve(img):
    """The reference: the pipeline's downsampling before the kernel (NumPy)."""
    h, w = img.shape[0] // 2 * 2, img.shape[1] // 2 * 2
    a = img[:h, :w].astype(np.float32, copy=False)
    return (0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2])).astype(np.float32)


def _image(rng, shape):
    """Grey levels off any binary grid (so that the order of the additions shows), with a
    few NaN, inf and denormal values."""
    img = (rng.random(shape) * 255.0 + rng.random(shape) * 1e-3).astype(np.float32)
    flat = img.reshape(-1)
    if flat.size < 12:
        return img
    picks = rng.choice(flat.size, size=12, replace=False)
    flat[picks[:3]] = np.nan
    flat[picks[3:6]] = np.inf
    flat[picks[6:8]] = -np.inf
    flat[picks[8:]] = np.float32(1e-40)
    return img


@pytest.mark.parametrize("shape", [(2, 2), (3, 5), (64, 96), (121, 203), (720, 1280)])
def test_halve_area_gives_the_bytes_of_the_numpy_expression(shape):
    img = _image(np.random.default_rng(sum(shape)), shape)
    got = pyramid.halve_area(img)
    want = numpy_halve(img)
    assert got.dtype == np.float32 and got.shape == (shape[0] // 2, shape[1] // 2)
    assert got.tobytes() == want.tobytes()


def test_sums_in_the_reference_order():
    """(a00 + a10) + a01, + a11: another order rounds these four differently."""
    img = np.array([[1.0, 2.0 ** -24], [2.0 ** -24, 2.0 ** -24]], np.float32)
    # in order: 1 + 2^-24 rounds to 1 (ties to even), twice, then 1 + 2^-24 -> 1: 0.25
    assert pyramid.halve_area(img)[0, 0] == np.float32(0.25) == numpy_halve(img)[0, 0]
    # the three small ones first would give 1 + 3 * 2^-24 -> 1 + 2^-23 (round up)
    assert np.float32(0.25) * (np.float32(1.0) + np.float32(3 * 2.0 ** -24)) != np.float32(0.25)


def test_strided_input_and_empty_results():
    img = _image(np.random.default_rng(3), (40, 60))
    view = img[::-1, 1:]  # negative and offset strides
    assert pyramid.halve_area(view).tobytes() == numpy_halve(np.ascontiguousarray(view)).tobytes()
    assert pyramid.halve_area(np.zeros((1, 9), np.float32)).shape == (0, 4)
    assert downsample(np.zeros((9, 1), np.float32)).shape == (4, 0)


def test_the_same_bytes_with_one_thread_and_with_all():
    img = _image(np.random.default_rng(9), (333, 517))
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = build_pyramid(img, 4)
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(single, build_pyramid(img, 4)):
        assert a.tobytes() == b.tobytes()
    assert [p.shape for p in single] == [(333, 517), (166, 258), (83, 129), (41, 64)]


def test_the_kernel_is_cached_and_releases_the_gil():
    assert len(pyramid.KERNELS) == 1
    for kernel in pyramid.KERNELS:
        assert isinstance(kernel, numba.core.registry.CPUDispatcher), kernel
        assert kernel.targetoptions.get("nogil") is True
        assert type(kernel._cache).__name__ == "FunctionCache"
