"""The steps CUDA runs on the device between the images and the cost volume (the pyramid,
the full-range and banded indexes, the decided pixels) against the CPU drivers: integer
results equal, floats bit for bit (marker ``cuda``; tests/kernels/test_cuda.py says how
they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import random_images

from d3cli.kernels import cpu

pytestmark = pytest.mark.cuda


@pytest.mark.parametrize("dtype, shape, levels", [(np.uint8, (H, W), 3), (np.float32, (H, W), 3),
                                                  (np.uint8, (33, 47), 4), (np.float32, (8, 9), 1)])
def test_pyramid_matches_cpu_bit_for_bit(gpu, dtype, shape, levels):
    rng = np.random.default_rng(sum(shape))
    if dtype == np.uint8:
        img = rng.integers(0, 256, shape, dtype=np.uint8)
    else:
        img = (rng.random(shape) * 255.0 + rng.random(shape) * 1e-3).astype(np.float32)
    got = gpu.pyramid(img, levels)
    want = cpu.pyramid(img, levels)
    assert len(got) == len(want) == levels
    for g, w in zip(got, want):
        g = host(gpu, g)
        assert g.dtype == np.float32 and g.shape == w.shape
        assert g.tobytes() == w.tobytes()


def test_pyramid_uploads_a_uint8_image_in_its_own_bytes(gpu):
    from d3cli.kernels.cuda_calls import count_cuda_calls

    img = np.arange(H * W, dtype=np.uint8).reshape(H, W)
    with count_cuda_calls() as calls:
        levels = gpu.pyramid(img, 3)
    assert (calls.host_to_device, calls.host_to_device_bytes) == (1, img.nbytes)
    assert calls.device_to_host == 0 and calls.launches == 3  # conversion, two halvings
    device_levels = gpu.pyramid(levels[0], 2)  # a device image: nothing uploaded
    assert host(gpu, device_levels[1]).tobytes() == cpu.pyramid(img, 2)[1].tobytes()


def test_dense_index_matches_cpu(gpu):
    np.testing.assert_array_equal(host(gpu, gpu.dense_index(H, W, 7)), cpu.dense_index(H, W, 7))


def test_decided_mask_matches_cpu(gpu):
    disp = np.random.default_rng(1).integers(-1, 5, (H, W)).astype(np.int32)
    got = host(gpu, gpu.decided_mask(gpu.to_device(disp)))
    assert got.dtype == np.bool_
    np.testing.assert_array_equal(got, cpu.decided_mask(disp))


def _coarse(rng, shape, n_disp, undecided):
    coarse = rng.integers(0, max(1, n_disp // 2), shape).astype(np.int32)
    coarse[rng.random(shape) < undecided] = -1
    return coarse


@pytest.mark.parametrize("shape, coarse_shape, n_disp, margin, tile, halo, undecided", [
    ((H, W), (5, 11), 9, 2, 4, 2, 0.3),
    ((H, W), (6, 12), 9, 1, 3, 0, 0.0),     # a coarse map larger than half the level
    ((17, 30), (8, 15), 13, 2, 5, 4, 0.6),
    ((16, 16), (8, 8), 6, 0, 16, 3, 1.0),   # nothing decided: the full range
    ((9, 21), (4, 10), 5, 3, 2, 1, 0.1),
])
def test_band_indexes_match_cpu(gpu, shape, coarse_shape, n_disp, margin, tile, halo, undecided):
    rng = np.random.default_rng(n_disp + tile)
    coarse = _coarse(rng, coarse_shape, n_disp, undecided)
    kw = dict(n_disp=n_disp, margin=margin, tile=tile, halo=halo)
    want_store, want_visible, want_cells = cpu.band_indexes(coarse, shape, **kw)
    store, visible, cells = gpu.band_indexes(gpu.to_device(coarse), shape, **kw)
    np.testing.assert_array_equal(host(gpu, store), want_store)
    np.testing.assert_array_equal(host(gpu, visible), want_visible)
    assert gpu.counts_to_host([cells]) == [want_cells]


def test_a_device_band_costs_what_the_cpu_band_costs(gpu):
    from d3cli.kernels.cuda_calls import count_cuda_calls

    rng = np.random.default_rng(4)
    left, right = random_images(rng, (H, W))
    coarse = _coarse(rng, (H // 2, W // 2), 8, 0.2)
    kw = dict(n_disp=8, margin=1, tile=4, halo=2)
    store, visible, n_cells = cpu.band_indexes(coarse, (H, W), **kw)
    want = cpu.ncc_cost_volume(left, right, 7, 3, 0.5, index=store)
    d_left, d_right, d_coarse = gpu.to_device(left), gpu.to_device(right), gpu.to_device(coarse)
    with count_cuda_calls() as calls:  # the volume is sized without a copy to the host
        d_store, _, _ = gpu.band_indexes(d_coarse, (H, W), **kw)
        got = gpu.ncc_cost_volume(d_left, d_right, 7, 3, 0.5, index=d_store)
    assert calls.device_to_host == 0 and calls.host_to_device == 0
    flat = host(gpu, got.cost)
    assert flat.shape[0] == H * W * 8  # allocated at the full-range size
    np.testing.assert_allclose(flat[:n_cells], want.cost, rtol=0, atol=COST_ATOL)


def test_a_device_dense_index_sizes_its_volume_without_a_copy(gpu):
    from d3cli.kernels.cuda_calls import count_cuda_calls

    rng = np.random.default_rng(5)
    left, right = random_images(rng, (H, W))
    d_left, d_right = gpu.to_device(left), gpu.to_device(right)
    with count_cuda_calls() as calls:
        got = gpu.ncc_cost_volume(d_left, d_right, 5, 3, 0.5, index=gpu.dense_index(H, W, 6))
    assert calls.device_to_host == 0 and calls.host_to_device == 0
    want = cpu.ncc_cost_volume(left, right, 5, 3, 0.5, index=cpu.dense_index(H, W, 6))
    np.testing.assert_allclose(host(gpu, got.cost), want.cost, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("narrow_range", [6, 9])
def test_pt_validity_and_range_ends_match_cpu(gpu, narrow_range):
    rng = np.random.default_rng(narrow_range)
    narrow = rng.integers(-1, 11, (H, W)).astype(np.int32)
    restored = (rng.random((H, W)) * 30.0 - 3.0).astype(np.float32)
    restored[0, :4] = [np.inf, np.nan, -0.0, 0.5]
    restored[1, :3] = [np.float32(1.5), np.float32(2.5), np.float32(2.4999)]  # at the left border's slack
    want_kept, want_masked, want_counts = cpu.pt_validity(narrow, restored, narrow_range)
    kept, masked, counts = gpu.pt_validity(gpu.to_device(narrow), gpu.to_device(restored), narrow_range)
    np.testing.assert_array_equal(host(gpu, kept), want_kept)
    assert host(gpu, masked).tobytes() == want_masked.tobytes()
    assert gpu.counts_to_host(counts) == want_counts and sum(want_counts) > 0
    ends = gpu.count_range_ends(gpu.to_device(narrow), narrow_range)
    assert gpu.counts_to_host([ends]) == [cpu.count_range_ends(narrow, narrow_range)]
