"""The CUDA drivers of the speckle filter (``finishing/cuda_speckle.py``, a union-find on
the device) and of the filling inside surfaces (``finishing/cuda_fill_inside.py``) against
``cv2.filterSpeckles`` and the CPU's kernels (marker ``cuda``; tests/kernels/test_cuda.py
says how they run): the same bools, counts and bytes on random maps with inf / NaN /
invalid pixels, odd sizes, regions at the size threshold and long snakes whose pixels the
union-find joins through many links."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.reference.finishing import random_map

from d3cli.kernels import finishing
from d3cli.method.refinement import drop_speckles as host_drop_speckles
from d3cli.method.refinement import fill_holes

pytestmark = pytest.mark.cuda


@pytest.fixture
def speckle(gpu):
    from d3cli.kernels.finishing import cuda_speckle

    return cuda_speckle


@pytest.fixture
def inside(gpu):
    from d3cli.kernels.finishing import cuda_fill_inside

    return cuda_fill_inside


def _speckle_maps(shape, seed):
    """Plateaus of a few values (regions of many sizes), inf / NaN among the holes, valid
    but non-finite estimates, nothing or everything valid."""
    rng = np.random.default_rng(seed)
    for share in (0.0, 0.7, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=4)
        disp = np.where(rng.random(shape) < 0.7, np.round(disp), disp).astype(np.float32)
        if disp.size > 3:
            disp.reshape(-1)[:2] = np.inf, np.nan
            valid.reshape(-1)[:2] = True  # valid but not finite: in no region, never a speckle
        yield np.ascontiguousarray(disp), np.ascontiguousarray(valid)


def _snake(h, w):
    """A one-pixel path winding through every other row of an (h, w) map, holes around it:
    its pixels are joined through links that meet only at the row ends."""
    disp = np.full((h, w), np.inf, np.float32)
    valid = np.zeros((h, w), bool)
    for y in range(0, h, 2):
        valid[y] = True
        if y + 1 < h:
            valid[y + 1, w - 1 if (y // 2) % 2 == 0 else 0] = True
    disp[valid] = 3.0
    return disp, valid


def _check(gpu, speckle, disp, valid, max_size, max_diff, what, in_place=True):
    want_valid = valid.copy()
    want_count, want_out = host_drop_speckles(disp, want_valid, max_size=max_size, max_diff=max_diff)
    cpu_valid, cpu_out = valid.copy(), np.empty(disp.shape, np.float32)
    cpu_count = finishing.drop_speckles(disp, cpu_valid, max_size, max_diff, cpu_out)
    d_disp, d_valid = gpu.to_device(disp), gpu.to_device(valid)
    out = d_disp if in_place else gpu.to_device(np.zeros(disp.shape, np.float32))
    count = speckle.drop_speckles(d_disp, d_valid, max_size, max_diff, out)
    np.testing.assert_array_equal(cpu_valid, want_valid, err_msg=what)
    np.testing.assert_array_equal(host(gpu, d_valid), want_valid, err_msg=what)
    assert cpu_out.tobytes() == want_out.tobytes(), what
    assert host(gpu, out).tobytes() == want_out.tobytes(), what
    assert int(count) == cpu_count == want_count, what
    return want_count


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (6, 1), (7, 13), (11, 23)])
def test_drop_speckles_matches_opencv_and_cpu(gpu, speckle, shape):
    for i, (disp, valid) in enumerate(_speckle_maps(shape, 3 + hash(shape) % 2**32)):
        for max_size, max_diff in ((1, 0.5), (4, 0.0), (12, 2.0)):
            _check(gpu, speckle, disp, valid, max_size, max_diff, f"{shape} {i} {max_size} {max_diff}",
                   in_place=bool(i % 2))


def test_regions_at_the_size_threshold(gpu, speckle):
    """Regions of exactly ``max_size`` pixels are speckles, of one more pixel not; steps of
    exactly ``max_diff`` join, one 1/16 px more do not."""
    disp = np.full((6, 11), np.inf, np.float32)
    valid = np.zeros(disp.shape, bool)
    disp[0:2, 0:3], valid[0:2, 0:3] = 1.0, True  # 6 pixels
    disp[3:5, 0:3], valid[3:5, 0:3] = 5.0, True
    disp[4, 3], valid[4, 3] = 5.0 + 2.0, True  # 7 pixels: a step of exactly 2 px joins
    disp[0:3, 5:7], valid[0:3, 5:7] = 9.0, True
    disp[2, 7], valid[2, 7] = 9.0 + 2.0 + 1 / 16, True  # 6 + 1 alone: one 1/16 px too far
    disp[4:6, 6:11], valid[4:6, 6:11] = 0.0, True  # 10 pixels, 0: the fixed point's lowest value
    assert _check(gpu, speckle, disp, valid, 0, 2.0, "no speckle") == 0
    assert _check(gpu, speckle, disp, valid, 6, 2.0, "threshold 6") == 6 + 6 + 1
    assert _check(gpu, speckle, disp, valid, 7, 2.0, "threshold 7") == 6 + 7 + 6 + 1


@pytest.mark.parametrize("shape", [(9, 7), (5, 17)])
def test_long_snakes_join_into_one_region(gpu, speckle, shape):
    disp, valid = _snake(*shape)
    n = int(valid.sum())
    assert _check(gpu, speckle, disp, valid, n - 1, 1.0, f"{shape} below") == 0
    assert _check(gpu, speckle, disp, valid, n, 1.0, f"{shape} at") == n


def test_drop_speckles_updates_a_host_validity_in_place(gpu, speckle):
    disp, valid = list(_speckle_maps((7, 13), 5))[1]
    want_valid = valid.copy()
    host_drop_speckles(disp, want_valid, max_size=4, max_diff=1.0)
    speckle.drop_speckles(disp, valid, 4, 1.0, gpu.to_device(np.zeros(disp.shape, np.float32)))
    np.testing.assert_array_equal(valid, want_valid)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (6, 1), (7, 13), (11, 23)])
def test_fill_inside_matches_cpu_and_fill_holes(gpu, inside, shape):
    rng = np.random.default_rng(13 + hash(shape) % 2**32)
    for share in (0.0, 0.05, 0.6, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share)
        if disp.size > 3:
            disp.reshape(-1)[1], valid.reshape(-1)[1] = np.nan, True  # valid, not usable
        occluded = (rng.random(shape) < 0.4) & ~valid
        what = f"{shape} {share}"
        want, want_use = finishing.fill_inside_holes(disp, valid, occluded)
        filled, use = inside.fill_inside(disp, valid, occluded)
        np.testing.assert_array_equal(host(gpu, use), want_use, err_msg=what)
        assert host(gpu, filled).tobytes() == want.tobytes(), what
        # the pipeline's host path, without and with the median of the filled pixels
        assert fill_holes(disp, valid, smooth=False, occluded=occluded).tobytes() == want.tobytes(), what
        if min(shape) >= 5:
            median = host(gpu, gpu.median_of_holes(filled, use))
            assert median.tobytes() == fill_holes(disp, valid, smooth=True, occluded=occluded).tobytes(), what


@pytest.mark.parametrize("config, overrides, shares", [
    ("kitti", [], ("occluded_share", "speckle_share")),
    ("kitti", ["refine.smooth_radius=0"], ("occluded_share", "speckle_share")),
    ("kitti", ["refine.occlusion_check=false", "refine.smooth_radius=0"], ("speckle_share",)),  # the row-wise fill
    ("default", ["refine.speckle_size=6", "refine.smooth_radius=0"], ("occluded_share", "speckle_share")),
])
def test_the_device_finishing_equals_the_hosts(gpu, config, overrides, shares):
    """``D3Stereo._finish_on_backend`` (occlusion check, speckles, filling on the device)
    against ``_finish_on_host`` of the same map (what ``--backend cpu`` runs): the same map,
    validity and shares, on a map with occlusions (random disparities), plateaus (regions
    of every size) and undecided pixels."""
    from d3cli import D3Stereo, load_config
    from d3cli.method.pipeline import _Match

    rng = np.random.default_rng(17)
    h, w, dmax = 12, 23, 8
    disp = rng.integers(0, dmax + 1, (h, w)).astype(np.int32)
    disp[:6, 4:15] = 3  # a plateau, speckles and holes around it
    disp[rng.random((h, w)) < 0.2] = -1
    sub = np.where(disp >= 0, disp + rng.uniform(-0.5, 0.5, (h, w)), np.inf).astype(np.float32)
    stereo = D3Stereo(load_config(config, overrides=["run.backend=cuda", *overrides]))
    info_gpu, info_cpu = {}, {}
    match = _Match(disparity=gpu.to_device(disp), cost=None, level_maps=[], per_level=[])
    got, got_valid = stereo._finish_on_backend(match, gpu.to_device(sub), dmax, info_gpu, None)
    want, want_valid = stereo._finish_on_host(sub.copy(), disp >= 0, True, dmax, info_cpu, None)
    np.testing.assert_array_equal(got_valid, want_valid)
    assert got.tobytes() == want.tobytes()
    assert info_gpu == info_cpu
    assert [key for key in ("occluded_share", "speckle_share") if info_cpu.get(key, 0) > 0] == list(shares)
