"""The CUDA drivers of the finishing (``d3cli.kernels.finishing.cuda``, one thread per row)
against the CPU's (marker ``cuda``; tests/kernels/test_cuda.py says how they run): the
same bools, counts and bytes on random maps with inf / NaN / invalid pixels, odd sizes,
rows with nothing valid, nothing or everything valid."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.reference.finishing import random_map

from d3cli.kernels import finishing

pytestmark = pytest.mark.cuda

SHAPES = [(1, 1), (1, 5), (5, 1), (3, 4), (7, 13), (11, 23), (17, 9)]


@pytest.fixture
def rows(gpu):
    from d3cli.kernels.finishing import cuda as finishing_cuda

    return finishing_cuda


def _maps(shape, seed):
    rng = np.random.default_rng(seed)
    for share in (0.0, 0.4, 0.9, 1.0):
        for integers in (False, True):
            disp, valid = random_map(rng, shape, valid_share=share, spread=min(shape[1], 8) + 1, integers=integers)
            if share == 1.0 and disp.size > 3:  # non-finite estimates marked valid
                flat = disp.reshape(-1)
                flat[0], flat[1], flat[2] = np.inf, np.nan, -1e30
            yield np.ascontiguousarray(disp), np.ascontiguousarray(valid)


@pytest.mark.parametrize("shape", SHAPES)
def test_occlusion_tests_match_cpu(gpu, rows, shape):
    for i, (disp, valid) in enumerate(_maps(shape, hash(shape) % 2**32)):
        for tolerance in (0.0, 1.0):
            want = finishing.uniqueness_occluded(disp, valid, tolerance)
            got = host(gpu, rows.uniqueness_occluded(disp, valid, tolerance))
            np.testing.assert_array_equal(got, want, err_msg=f"uniqueness {shape} {i} {tolerance}")
        for start in sorted({0, shape[1] // 2, shape[1] - 1}):
            want = finishing.out_of_view_mask(disp, valid, start)
            got = host(gpu, rows.out_of_view_mask(disp, valid, start))
            np.testing.assert_array_equal(got, want, err_msg=f"out of view {shape} {i} {start}")


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("in_place", [False, True])
def test_drop_occluded_matches_cpu(gpu, rows, shape, in_place):
    for i, (disp, valid) in enumerate(_maps(shape, 7 + hash(shape) % 2**32)):
        start = min(4, shape[1] - 1)
        cpu_valid, cpu_disp = valid.copy(), disp.copy()
        cpu_out = cpu_disp if in_place else np.empty(disp.shape, np.float32)
        want_occ, want_count = finishing.drop_occluded(cpu_disp, cpu_valid, 1.0, start, cpu_out)
        d_disp, d_valid = gpu.to_device(disp), gpu.to_device(valid)
        out = d_disp if in_place else gpu.to_device(np.zeros(disp.shape, np.float32))
        occ, count = rows.drop_occluded(d_disp, d_valid, 1.0, start, out)
        np.testing.assert_array_equal(host(gpu, occ), want_occ, err_msg=f"{shape} {i}")
        np.testing.assert_array_equal(host(gpu, d_valid), cpu_valid, err_msg=f"{shape} {i}")
        assert host(gpu, out).tobytes() == cpu_out.tobytes(), f"{shape} {i}"
        assert int(count) == want_count


def test_drop_occluded_updates_a_host_validity_in_place(gpu, rows):
    disp, valid = next(iter(list(_maps((7, 13), 5))[2:]))
    want_valid = valid.copy()
    want_occ, _ = finishing.drop_occluded(disp.copy(), want_valid, 1.0, 4, np.empty(disp.shape, np.float32))
    occ, _ = rows.drop_occluded(disp, valid, 1.0, 4, gpu.to_device(np.zeros(disp.shape, np.float32)))
    np.testing.assert_array_equal(valid, want_valid)
    np.testing.assert_array_equal(host(gpu, occ), want_occ)


def _holes(shape, seed):
    """Maps for the filling: random estimates with inf / NaN among the invalid pixels,
    non-finite ones among the valid, rows with nothing valid."""
    for i, (disp, valid) in enumerate(_maps(shape, seed)):
        if i % 3 == 1 and disp.size > 2:
            disp.reshape(-1)[1] = np.inf
            valid.reshape(-1)[1] = True
        yield disp, valid


@pytest.mark.parametrize("shape", SHAPES)
def test_fill_rows_matches_cpu(gpu, rows, shape):
    for i, (disp, valid) in enumerate(_holes(shape, 11 + hash(shape) % 2**32)):
        want_filled, want_use = finishing.fill.fill_rows(disp, valid)
        filled, use = rows.fill_rows(disp, valid)
        np.testing.assert_array_equal(host(gpu, use), want_use, err_msg=f"{shape} {i}")
        assert host(gpu, filled).tobytes() == want_filled.tobytes(), f"{shape} {i}"
        # the pipeline's host path: usable, the row fill, the empty rows
        use2, row_has, _ = finishing.usable(disp, valid)
        ref, _ = finishing.fill_rows_smaller_side(disp, use2)
        if row_has.any() and not row_has.all():
            finishing.copy_nearest_rows(ref, row_has)
        if row_has.any():
            assert ref.tobytes() == want_filled.tobytes(), f"{shape} {i}"
        else:
            assert np.all(want_filled == np.inf)


@pytest.mark.parametrize("shape", [(5, 5), (7, 13), (11, 23), (17, 9)])
def test_median_of_holes_matches_opencv_and_cpu(gpu, rows, shape):
    import cv2

    for i, (disp, valid) in enumerate(_holes(shape, 23 + hash(shape) % 2**32)):
        filled, use = finishing.fill.fill_rows(disp, valid)
        want = filled.copy()
        finishing.keep_valid(want, use, cv2.medianBlur(filled, 5))
        got_cpu = finishing.fill.median_of_holes(filled, use)
        assert got_cpu.tobytes() == want.tobytes(), f"{shape} {i}"
        got = host(gpu, rows.median_of_holes(filled, use))
        assert got.tobytes() == want.tobytes(), f"{shape} {i}"
