"""The CUDA kernels against the CPU kernels (the reference backend).

Every test is marked ``cuda``; the main suite deselects them (``addopts = -m 'not cuda'``).
They run

* without a GPU under the CUDA simulator, in a separate process with
  ``NUMBA_ENABLE_CUDASIM=1`` set before numba is imported
  (``tests/kernels/test_cuda_simulator.py`` does that inside the normal ``pytest`` run), and
* on a real GPU with ``python -m pytest -m cuda tests/kernels``.

Inputs are tiny and odd-sized (the simulator runs every thread as Python) and the
block sizes are patched small, so every grid has several partly filled blocks.
Costs must agree to 1e-5, integer maps (disparities, seeds, masks) exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import textured_pair
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import random_images, sparse_map

from d3cli.kernels import cpu, cuda_status
from d3cli.kernels.device_counts import POOL_SLOTS
from d3cli.kernels.volume import Volume

pytestmark = pytest.mark.cuda


# ----------------------------------------------------------------------------- backend selection
def test_backend_selection(gpu):
    from numba import config as numba_config

    from d3cli.kernels import SIMULATOR, device_description, get_backend

    assert get_backend("cuda") == (gpu, "cuda")
    if numba_config.ENABLE_CUDASIM:
        assert cuda_status() == (True, SIMULATOR)
        assert device_description() == SIMULATOR
        assert get_backend("auto")[1] == "cpu"  # the simulator is never picked automatically
    else:
        assert get_backend("auto")[1] == "cuda"
        assert "compute capability" in device_description()


def test_arrays_round_trip_and_host_inputs_are_accepted(gpu):
    rng = np.random.default_rng(1)
    disp = sparse_map(rng, (H, W), 5, share=0.4)
    d_disp = gpu.to_device(disp)
    assert not isinstance(d_disp, np.ndarray) and gpu.to_device(d_disp) is d_disp
    np.testing.assert_array_equal(gpu.to_host(d_disp), disp)
    np.testing.assert_array_equal(gpu.to_host(disp), disp)  # host arrays pass through
    assert gpu.count_decided(d_disp) == gpu.count_decided(disp) == cpu.count_decided(disp) == int((disp >= 0).sum())
    fallback = sparse_map(rng, (H, W), 5, share=0.5)
    want = cpu.merge_sparse(disp, fallback)
    got = host(gpu, gpu.merge_sparse(d_disp, fallback))
    np.testing.assert_array_equal(got, want)
    assert got.dtype == np.int32


# ----------------------------------------------------------------------------- the pipeline
class TransferSpy:
    """Records host-to-device uploads (``cuda.to_device``) and the sizes of downloads."""

    def __init__(self, gpu, monkeypatch):
        self.uploads = []
        self.downloads = []
        upload = gpu.cuda.to_device
        probe = gpu.cuda.device_array(1, np.int32)
        download = type(probe).copy_to_host

        def spy_upload(array, *args, **kwargs):
            self.uploads.append(np.shape(array))
            return upload(array, *args, **kwargs)

        def spy_download(array, *args, **kwargs):
            self.downloads.append(int(np.prod(array.shape)))
            return download(array, *args, **kwargs)

        monkeypatch.setattr(gpu.cuda, "to_device", spy_upload)
        monkeypatch.setattr(type(probe), "copy_to_host", spy_download)


def test_a_level_stays_on_the_device(gpu, monkeypatch):
    """Cost, aggregation, seeds, diffusion, inheritance and sub-pixel on device arrays:
    one upload (a host index; the counts' slots are zeroed on the device), nothing comes
    back until the counts are read, then all of them in one copy."""
    from d3cli.kernels.volume import dense_index

    rng = np.random.default_rng(40)
    left, right = random_images(rng, (H, W))
    d_left, d_right = gpu.to_device(left), gpu.to_device(right)
    index = dense_index(H, W, 6)
    spy = TransferSpy(gpu, monkeypatch)
    cost = gpu.ncc_cost_volume(d_left, d_right, 5, 3, 1e-2, index=index)
    cost = gpu.invalidate_out_of_view(gpu.rbf_filter(cost, gpu.rbf_weights(d_left, 1.5, 12.0), 2))
    seeds = gpu.decisive_seeds(cost, 1.05, 1e-3, 1, 0)
    disp, sweeps = gpu.diffuse(cost, seeds, gpu.min_cost(cost), 0.1, 1, 1, True, 100000)
    fine = gpu.inherit(cost, disp, True, 1.05, 1e-3)
    merged = gpu.merge_sparse(fine, seeds)
    n_decided = gpu.count_decided(merged)
    sub = gpu.subpixel(cost, merged)
    assert spy.uploads == [(H, W, 3)]
    assert spy.downloads == []
    sweeps, n_decided = gpu.counts_to_host([sweeps, n_decided])
    assert spy.downloads == [POOL_SLOTS]
    assert sweeps >= 2 and n_decided == int((gpu.to_host(merged) >= 0).sum()) > 0
    assert np.isfinite(gpu.to_host(sub)).sum() == n_decided


@pytest.mark.parametrize("shape", [(H, W), (3, 2)])  # (3, 2): fewer pixels than a pool has slots
def test_outputs_come_back_in_one_copy(gpu, monkeypatch, shape):
    """The map, the validity and every unread pool of counts in one download, the values
    equal to separate downloads; counts of a pool read before are taken as they are."""
    from d3cli.kernels.device_counts import counts_to_host

    rng = np.random.default_rng(7)
    disp = rng.uniform(0, 9, shape).astype(np.float32)
    disp[rng.random(shape) < 0.3] = np.inf
    valid = np.isfinite(disp)
    maps = [sparse_map(rng, shape, 5, share=share) for share in (0.2, 0.5, 0.8)]
    read_before = gpu.count_decided(gpu.to_device(maps[0]))
    int(read_before)  # its pool is read: counts taken later come from a new pool
    counts = [gpu.count_decided(gpu.to_device(m)) for m in maps]
    from d3cli.kernels.device_counts import CountPool, DeviceCount

    extra = CountPool(4)  # a second unread pool, of 4 slots
    extra.array.copy_to_device(np.array([11, 12, 13, 14], np.int64))
    extra.take()
    counts.append(DeviceCount(extra, extra.take()))
    d_disp, d_valid = gpu.to_device(disp), gpu.to_device(valid)
    spy = TransferSpy(gpu, monkeypatch)
    got_disp, got_valid, values = gpu.outputs_to_host(d_disp, d_valid, [read_before, 5, *counts])
    assert spy.downloads == [-(-5 * disp.size // 8) * 8 + 8 * (POOL_SLOTS + 4)]
    want = [int((m >= 0).sum()) for m in maps]
    assert values == [want[0], 5, *want, 12]
    assert counts_to_host(counts) == [*want, 12] and len(spy.downloads) == 1  # read: no copy
    np.testing.assert_array_equal(got_disp, disp)
    np.testing.assert_array_equal(got_valid, valid)
    assert got_disp.dtype == np.float32 and got_valid.dtype == np.bool_ and got_disp.flags.writeable
    on_cpu = cpu.outputs_to_host(disp, valid, [3])
    assert on_cpu[0] is disp and on_cpu[1] is valid and on_cpu[2] == [3]


@pytest.mark.parametrize("max_value", [40, 300, 40000])
def test_small_ints_come_back_narrow(gpu, monkeypatch, max_value):
    """An integer map downloaded as int8, int16 or int32 by its range: the same values."""
    rng = np.random.default_rng(8)
    disp = rng.integers(-1, max_value + 1, (H, W)).astype(np.int32)
    d_disp = gpu.to_device(disp)
    spy = TransferSpy(gpu, monkeypatch)
    got = gpu.small_ints_to_host(d_disp, max_value)
    np.testing.assert_array_equal(got, disp)
    assert spy.downloads == [disp.size]
    assert got.itemsize == {40: 1, 300: 2, 40000: 4}[max_value]
    assert cpu.small_ints_to_host(disp, max_value) is disp


def test_pipeline_on_cuda_equals_cpu(gpu, monkeypatch):
    from d3cli import D3Stereo, load_config

    left, right, _ = textured_pair(4, (16, 30), seed=3)  # two pyramid levels
    results = {}
    for backend in ("cpu", "cuda"):
        matcher = D3Stereo(load_config(overrides=[f"run.backend={backend}"]))
        assert matcher.backend_name == backend
        if backend == "cuda":
            spy = TransferSpy(gpu, monkeypatch)
        results[backend] = matcher.compute(left, right, max_disparity=6)
    want, got = results["cpu"], results["cuda"]
    n_levels = len(want.levels)
    # one upload of each uint8 image (the pyramid, the indexes and the counts' slots are
    # made on the device); one download: the map (occlusion check, row-wise filling and its
    # median on the device), the decided pixels and the counts, the levels' with the
    # occluded pixels', packed in one byte buffer (the level maps only when read, below)
    assert left.dtype == np.uint8 and n_levels >= 2
    assert spy.uploads == [left.shape, right.shape]
    assert spy.downloads == [-(-5 * left.size // 8) * 8 + 8 * POOL_SLOTS]
    assert got.info["occluded_share"] == want.info["occluded_share"]
    assert got.info["backend"] == "cuda"
    assert len(got.levels) == len(want.levels) >= 2
    for level_got, level_want in zip(got.levels, want.levels):
        assert isinstance(level_got, np.ndarray)
        np.testing.assert_array_equal(level_got, level_want)
    np.testing.assert_array_equal(got.valid, want.valid)
    assert want.valid.mean() > 0.5
    np.testing.assert_array_equal(np.isinf(got.disparity), np.isinf(want.disparity))
    np.testing.assert_allclose(got.disparity, want.disparity, rtol=0, atol=COST_ATOL)
    def facts(result):
        keys = ("seeds", "inherited", "sweeps", "decided_share")
        return [{k: s[k] for k in keys if k in s} for s in result.info["per_level"]]

    assert facts(got) == facts(want)


# ----------------------------------------------------------------------------- deep features
@pytest.mark.parametrize("max_disparity", [0, 5])
def test_cosine_cost_volume_matches_cpu(gpu, max_disparity):
    from d3cli.method.features import normalise

    rng = np.random.default_rng(7)
    fl, nl = normalise(rng.normal(size=(H, W, 5)).astype(np.float32))
    fr, nr = normalise(rng.normal(size=(H, W, 5)).astype(np.float32))
    fl[3, 4], nl[3, 4] = 0.0, 0.0  # a zero feature vector: cost 1 on both backends
    want = cpu.cosine_cost_volume(fl, fr, nl, nr, max_disparity)
    got = host(gpu, gpu.cosine_cost_volume(fl, fr, nl, nr, max_disparity))
    np.testing.assert_allclose(got, want, atol=COST_ATOL)


# ----------------------------------------------------------------------------- band search
@pytest.mark.parametrize("rbf", [True, False])
def test_banded_level_matches_cpu(gpu, rbf):
    """A level with ragged bands: every stored cell after the cost and
    the aggregation, and every decision on the visible bands, as on the CPU."""
    from d3cli import load_config
    from d3cli.kernels.host import band_indexes
    from d3cli.method.cost import aggregation_halo, level_cost

    cfg = load_config(overrides=[f"aggregation.rbf={str(rbf).lower()}", "aggregation.kappa_a=2",
                                 "aggregation.t_max=3", "aggregation.finest_t_max=null", "cost.window=3"])
    rng = np.random.default_rng(50)
    left, right = random_images(rng, (H, W))
    coarse = sparse_map(rng, ((H + 1) // 2, (W + 1) // 2), 5, share=0.5)
    bands = band_indexes(coarse, (H, W), n_disp=10, margin=2, tile=4, halo=aggregation_halo(cfg, 0))
    want = level_cost(left, right, level=0, max_disparity=9, cfg=cfg, backend=cpu, bands=bands)
    got = level_cost(gpu.to_device(left), gpu.to_device(right), level=0, max_disparity=9, cfg=cfg, backend=gpu,
                     bands=bands)
    assert isinstance(got, Volume) and got.cost.size == bands[2]
    np.testing.assert_allclose(host(gpu, got.cost), want.cost, rtol=0, atol=COST_ATOL)
    seeds_want = cpu.decisive_seeds(want, 1.05, 1e-3, 1, 0)
    np.testing.assert_array_equal(host(gpu, gpu.decisive_seeds(got, 1.05, 1e-3, 1, 0)), seeds_want)
    skip = sparse_map(rng, (H, W), 10, share=0.5)
    np.testing.assert_array_equal(host(gpu, gpu.decisive_seeds(got, 1.05, 1e-3, 1, 0, skip=gpu.to_device(skip))),
                                  cpu.decisive_seeds(want, 1.05, 1e-3, 1, 0, skip=skip))
    least = cpu.min_cost(want)
    # the least costs are costs: equal to COST_ATOL (on a GPU the aggregation's multiply-adds
    # are fused, so the last bit differs in about a third of the cells; exact in the simulator)
    np.testing.assert_allclose(host(gpu, gpu.min_cost(got)), least, rtol=0, atol=COST_ATOL)
    start = sparse_map(rng, (H, W), 10, share=0.2)
    disp_want, sweeps_want = cpu.diffuse(want, start, least, 0.1, 1, 1, True, 1000)
    disp_got, sweeps_got = gpu.diffuse(got, start, gpu.min_cost(got), 0.1, 1, 1, True, 1000)
    np.testing.assert_array_equal(host(gpu, disp_got), disp_want)
    assert sweeps_got == sweeps_want
    np.testing.assert_array_equal(host(gpu, gpu.inherit(got, coarse, True, 1.05, 1e-3)),
                                  cpu.inherit(want, coarse, True, 1.05, 1e-3))
    np.testing.assert_allclose(host(gpu, gpu.subpixel(got, disp_want)), cpu.subpixel(want, disp_want),
                               rtol=0, atol=COST_ATOL)


def test_road_pipeline_on_cuda_equals_cpu(gpu):
    """The road config on a synthetic road: the coarse pass, the road fit, the narrow match
    and the validity after the restore (on the device on CUDA) give the CPU's maps and shares."""
    from d3cli import D3Stereo, load_config
    from d3cli.data.synth import render_pair

    pair = render_pair(seed=1, width=64, height=32, variant="sun", flat=True, noise=False, supersample=1)
    results = {backend: D3Stereo(load_config("road", overrides=[f"run.backend={backend}"])).compute(
        pair.left, pair.right, max_disparity=16) for backend in ("cpu", "cuda")}
    want, got = results["cpu"], results["cuda"]
    assert want.info["pt"]["road_like"] and not want.info["pt"].get("fallback")
    assert got.info["pt"] == want.info["pt"]
    assert got.info["occluded_share"] == want.info["occluded_share"]
    for level_got, level_want in zip(got.levels, want.levels):
        np.testing.assert_array_equal(level_got, level_want)
    np.testing.assert_array_equal(got.valid, want.valid)
    assert want.valid.mean() > 0.5
    np.testing.assert_array_equal(np.isinf(got.disparity), np.isinf(want.disparity))
    np.testing.assert_allclose(got.disparity, want.disparity, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("equiangular", [False, True])
def test_subpixel_gives_the_cpus_bytes_under_the_simulator(gpu, equiangular):
    """The offset in float64 from the float32 sums on, on both targets: the simulator's
    NumPy scalars give the CPU's bytes (a GPU may fuse a multiply-add: within COST_ATOL)."""
    from numba import config as numba_config

    rng = np.random.default_rng(41)
    cost = rng.random((H, W, 8)).astype(np.float32)
    disp = rng.integers(-1, 8, (H, W)).astype(np.int32)
    want = cpu.subpixel(cost, disp, equiangular)
    got = host(gpu, gpu.subpixel(cost, disp, equiangular))
    if numba_config.ENABLE_CUDASIM:
        assert got.tobytes() == want.tobytes()
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)
