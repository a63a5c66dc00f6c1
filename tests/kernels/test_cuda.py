"""The CUDA kernels against the CPU kernels (the reference backend).

Every test is marked ``cuda``; the main suite deselects them (``addopts = -m 'not cuda'``).
They run

* without a GPU under the CUDA simulator, in a separate process with
  ``NUMBA_ENABLE_CUDASIM=1`` set before numba is imported
  (``tests/test_cuda_simulator.py`` does that inside the normal ``pytest`` run), and
* on a real GPU with ``python -m pytest -m cuda tests/test_cuda.py``.

Inputs are tiny and odd-sized (the simulator runs every thread as Python) and the
block sizes are patched small, so every grid has several partly filled blocks.
Costs must agree to 1e-5, integer maps (disparities, seeds, masks) exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import textured_pair
from tests.volumes import (DIFFUSION_SETTINGS, banded, mark_missing_cells, random_images, random_volume, sparse_map,
                           structured_volume)

from d3cli.kernels import cpu, cuda_status
from d3cli.kernels.volume import Volume

pytestmark = pytest.mark.cuda

COST_ATOL = 1e-5
H, W = 11, 23  # 3 x 6 blocks of 4 x 4 threads, the last row and column of blocks partly filled


@pytest.fixture(scope="module")
def gpu():
    """The CUDA backend module; skips when neither a GPU nor the simulator is usable."""
    usable, why = cuda_status()
    if not usable:
        pytest.skip(f"CUDA is not usable here: {why}")
    from d3cli.kernels import cuda as backend

    return backend


@pytest.fixture(autouse=True)
def small_blocks(gpu, monkeypatch):
    """Blocks of 4 x 4 (2D) and 8 (1D) threads: many partly filled blocks on odd sizes."""
    from d3cli.kernels import cuda_launch  # where the launches read them

    monkeypatch.setattr(cuda_launch, "BLOCK_2D", (4, 4))
    monkeypatch.setattr(cuda_launch, "BLOCK_1D", 8)


def host(gpu, array):
    """Download a result, checking that the backend returned a device array."""
    assert not isinstance(array, np.ndarray), "CUDA functions must return device arrays"
    return gpu.to_host(array)


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


# ----------------------------------------------------------------------------- NCC cost
@pytest.mark.parametrize("window, max_disparity, band_rows", [(3, 6, None), (5, 7, 3), (1, 0, None)])
def test_ncc_cost_volume_matches_cpu(gpu, monkeypatch, window, max_disparity, band_rows):
    rng = np.random.default_rng(window)
    left, right = random_images(rng, (H, W))
    left[2:9, 1:6] = 117.0  # flat windows: cost 1
    right[6:, 15:] = 40.0
    if band_rows:  # a scratch of 3 rows: the volume is computed in 4 bands
        from d3cli.kernels.cost import cuda as cost_cuda  # where the driver reads it

        monkeypatch.setattr(cost_cuda, "NCC_SCRATCH_BYTES", band_rows * (W + 1) * (max_disparity + 1) * 8)
    got = host(gpu, gpu.ncc_cost_volume(gpu.to_device(left), gpu.to_device(right), max_disparity, window, 0.5))
    want = cpu.ncc_cost_volume(left, right, max_disparity, window, 0.5)
    assert got.shape == want.shape and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)
    assert (got[:, :, 1:][want[:, :, 1:] == 1.0] == 1.0).all()  # missing and flat cells exactly 1


def test_invalidate_out_of_view_matches_cpu(gpu):
    rng = np.random.default_rng(2)
    cost = rng.random((H, W, 6)).astype(np.float32) * 0.9
    want = cpu.invalidate_out_of_view(cost.copy())
    d_cost = gpu.to_device(cost)
    got = gpu.invalidate_out_of_view(d_cost)
    np.testing.assert_array_equal(host(gpu, got), want)
    np.testing.assert_array_equal(gpu.to_host(d_cost), want)  # in place
    on_host = cost.copy()
    gpu.invalidate_out_of_view(on_host)
    np.testing.assert_array_equal(on_host, want)  # a host volume is updated in place too


# ----------------------------------------------------------------------------- aggregation
def test_rbf_weights_match_cpu(gpu):
    img = np.random.default_rng(3).uniform(0, 255, (H, W)).astype(np.float32)
    got = host(gpu, gpu.rbf_weights(gpu.to_device(img), 1.5, 12.0))
    want = cpu.rbf_weights(img, 1.5, 12.0)
    assert got.shape == (H, W, 9) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    assert (got[0, :, :3] == 0).all() and (got[:, -1, 2::3] == 0).all()  # outside the image


@pytest.mark.parametrize("t_max", [0, 1, 3])
def test_rbf_filter_matches_cpu(gpu, t_max):
    rng = np.random.default_rng(4 + t_max)
    img = rng.uniform(0, 255, (H, W)).astype(np.float32)
    cost = random_volume(rng, H, W, 5)
    weights = cpu.rbf_weights(img, 2.0, 20.0)
    d_cost = gpu.to_device(cost)
    got = gpu.rbf_filter(d_cost, gpu.to_device(weights), t_max)
    assert got is not d_cost
    np.testing.assert_allclose(host(gpu, got), cpu.rbf_filter(cost, weights, t_max), rtol=0, atol=COST_ATOL)
    np.testing.assert_array_equal(gpu.to_host(d_cost), cost)  # input untouched


@pytest.mark.parametrize("t_max", [2, 3])
def test_rbf_filter_overwriting_its_input_matches_cpu(gpu, t_max):
    rng = np.random.default_rng(9 + t_max)
    img = rng.uniform(0, 255, (H, W)).astype(np.float32)
    cost = random_volume(rng, H, W, 5)
    weights = cpu.rbf_weights(img, 2.0, 20.0)
    got = gpu.rbf_filter(gpu.to_device(cost), gpu.to_device(weights), t_max, True)
    want = cpu.rbf_filter(cost.copy(), weights, t_max, True)
    np.testing.assert_allclose(host(gpu, got), want, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("radius", [0, 2])
def test_bilateral_filter_matches_cpu(gpu, radius):
    rng = np.random.default_rng(6 + radius)
    shape = (7, 9)
    img = rng.uniform(0, 255, shape).astype(np.float32)
    cost = random_volume(rng, *shape, 3)
    got = host(gpu, gpu.bilateral_filter(gpu.to_device(cost), gpu.to_device(img), radius, 2.0, 15.0))
    np.testing.assert_allclose(got, cpu.bilateral_filter(cost, img, radius, 2.0, 15.0), rtol=0, atol=COST_ATOL)


# ----------------------------------------------------------------------------- seeds, min cost
@pytest.mark.parametrize("levels", [None, 8])
def test_seeds_match_cpu(gpu, levels):
    rng = np.random.default_rng(11 if levels else 12)
    cost = random_volume(rng, H, W, 7, levels=levels)
    d_cost = gpu.to_device(cost)
    for pkrn_min, exclusion, lr_tol in [(1.0, 0, 1), (1.2, 0, 0), (1.1, 1, 1), (2.0, 2, 2)]:
        got = host(gpu, gpu.decisive_seeds(d_cost, pkrn_min, 1e-3, lr_tol, exclusion))
        want = cpu.decisive_seeds(cost, pkrn_min, 1e-3, lr_tol, exclusion)
        assert got.dtype == np.int32
        np.testing.assert_array_equal(got, want, err_msg=f"{pkrn_min=} {exclusion=} {lr_tol=}")
        assert gpu.count_decided(gpu.to_device(want)) == int((want >= 0).sum())


def test_seeds_on_a_structured_volume_match_cpu(gpu):
    rng = np.random.default_rng(13)
    true = (np.arange(W)[None, :] // 6 + np.arange(H)[:, None] // 4).astype(np.int64) + 1
    cost = structured_volume(rng, true, 8, noise=0.1)
    want = cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)
    assert (want >= 0).sum() > 30
    np.testing.assert_array_equal(host(gpu, gpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)), want)


def test_min_cost_matches_cpu(gpu):
    cost = random_volume(np.random.default_rng(14), H, W, 5, levels=6)
    got = host(gpu, gpu.min_cost(gpu.to_device(cost)))
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, cpu.min_cost(cost))


# ----------------------------------------------------------------------------- diffusion
def diffusion_cases():
    rng = np.random.default_rng(15)
    true = (np.arange(W)[None, :] // 8 + np.arange(H)[:, None] // 4).astype(np.int64) + 1
    return [
        (random_volume(rng, H, W, 5, levels=6), sparse_map(rng, (H, W), 5)),  # ties everywhere
        (structured_volume(rng, true, 7, noise=0.3), sparse_map(rng, (H, W), 7, share=0.05)),  # wrong seeds too
    ]


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_matches_cpu(gpu, settings):
    args = (settings["max_gap"], settings["tau"], settings["kappa_d"], settings["adversarial"], 100000)
    for cost, disp in diffusion_cases():
        least = cpu.min_cost(cost)
        want, want_sweeps = cpu.diffuse(cost, disp, least, *args)
        d_disp = gpu.to_device(disp)
        got, sweeps = gpu.diffuse(gpu.to_device(cost), d_disp, gpu.to_device(least), *args)
        np.testing.assert_array_equal(host(gpu, got), want, err_msg=f"{cost.shape}")
        assert sweeps == want_sweeps > 1
        np.testing.assert_array_equal(gpu.to_host(d_disp), disp)  # disp0 untouched


def test_diffusion_max_sweeps_and_no_seeds_match_cpu(gpu):
    rng = np.random.default_rng(19)
    cost = structured_volume(rng, np.full((H, W), 3), 6, noise=0.02)
    seeds = np.full((H, W), -1, np.int32)
    least = cpu.min_cost(cost)
    got, sweeps = gpu.diffuse(cost, seeds, least, -1.0, 1, 1, True, 100000)  # host inputs
    assert sweeps == 0 and (host(gpu, got) == -1).all()
    seeds[5, 11] = 3
    for limit in (1, 3):
        want, want_sweeps = cpu.diffuse(cost, seeds, least, -1.0, 1, 1, True, limit)
        got, sweeps = gpu.diffuse(cost, seeds, least, -1.0, 1, 1, True, limit)
        assert sweeps == want_sweeps == limit
        np.testing.assert_array_equal(host(gpu, got), want)
    # max_gap < 0: min_cost is never read, a dummy like the one diffusion.py passes is fine
    want, _ = cpu.diffuse(cost, seeds, np.zeros((1, 1), np.float32), -1.0, 1, 1, True, 100000)
    got, _ = gpu.diffuse(cost, seeds, gpu.to_device(np.zeros((1, 1), np.float32)), -1.0, 1, 1, True, 100000)
    np.testing.assert_array_equal(host(gpu, got), want)
    assert (want >= 0).sum() > H * W // 2


# ----------------------------------------------------------------------------- inheritance
@pytest.mark.parametrize("candidates", [0, 1])  # symmetric, paper (eq. 6-7 literally)
@pytest.mark.parametrize("prc", [True, False])
def test_inheritance_matches_cpu(gpu, prc, candidates):
    rng = np.random.default_rng(20 + prc + 2 * candidates)
    decided = 0
    for n_disp in (5, 8):
        # even disparities constant over the 2x2 patches: many patches pass the PRC
        true = np.kron(2 * rng.integers(0, (n_disp + 1) // 2, (H // 2 + 1, W // 2 + 1)), np.ones((2, 2), int))[:H, :W]
        for cost in (random_volume(rng, H, W, n_disp, levels=8), structured_volume(rng, true, n_disp)):
            coarse = rng.integers(0, (n_disp + 1) // 2, (H // 2, W // 2)).astype(np.int32)
            coarse = np.where(rng.random(coarse.shape) < 0.5, true[: H - 1:2, : W - 1:2] // 2, coarse).astype(np.int32)
            coarse[rng.random(coarse.shape) >= 0.7] = -1
            want = cpu.inherit(cost, coarse, prc, 1.05, 1e-3, candidates)
            got = host(gpu, gpu.inherit(gpu.to_device(cost), gpu.to_device(coarse), prc, 1.05, 1e-3, candidates))
            assert got.dtype == np.int32
            decided += (want >= 0).sum()
            np.testing.assert_array_equal(got, want, err_msg=f"{n_disp=}")
    assert decided > 10


def test_inheritance_of_a_perfect_coarse_map_matches_cpu(gpu):
    h, w, n_disp = 8, 25, 10
    true = np.where(np.arange(w)[None, :] < 12, 2, 6) * np.ones((h, 1), int)
    cost = np.full((h, w, n_disp), 0.9, np.float32)
    v, u = np.indices(true.shape)
    cost[v, u, true] = 0.05
    mark_missing_cells(cost)
    coarse = np.ascontiguousarray(true[::2, : w - 1:2] // 2, dtype=np.int32)
    want = cpu.inherit(cost, coarse, True, 1.05, 1e-3)
    assert (want >= 0).sum() > 40
    np.testing.assert_array_equal(host(gpu, gpu.inherit(cost, coarse, True, 1.05, 1e-3)), want)


# ----------------------------------------------------------------------------- sub-pixel
def test_subpixel_matches_cpu(gpu):
    rng = np.random.default_rng(23)
    for n_disp, levels in ((1, None), (2, None), (6, 4)):
        cost = random_volume(rng, H, W, n_disp, levels=levels)
        disp = sparse_map(rng, (H, W), n_disp, share=0.8)
        got = host(gpu, gpu.subpixel(gpu.to_device(cost), gpu.to_device(disp)))
        want = cpu.subpixel(cost, disp)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(np.isinf(got), np.isinf(want))
        np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)


@pytest.mark.parametrize("n_disp, levels", [(1, None), (6, 4)])
def test_sgm_smooth_matches_cpu(gpu, n_disp, levels):
    rng = np.random.default_rng(29)
    cost = random_volume(rng, H, W, n_disp, levels=levels)
    got = host(gpu, gpu.sgm_smooth(gpu.to_device(cost), 0.1, 0.4))
    want = cpu.sgm_smooth(cost, 0.1, 0.4)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, want)  # the same float32 additions in the same order


def test_sgm_smooth_of_a_banded_volume_matches_cpu(gpu):
    rng = np.random.default_rng(37)
    lo = rng.integers(0, 5, (H, W))
    hi = np.minimum(9, lo + rng.integers(1, 6, (H, W)))
    volume = banded(rng.random((H, W, 9)).astype(np.float32), lo, hi)
    got = gpu.sgm_smooth(Volume(gpu.to_device(volume.cost), gpu.to_device(volume.index), volume.n_disp), 0.1, 0.4)
    want = cpu.sgm_smooth(volume, 0.1, 0.4)
    np.testing.assert_array_equal(host(gpu, got.cost), want.cost)


# ----------------------------------------------------------------------------- perspective transformation
PT_MODELS = [(5.3, 0.21, -0.07, 2.0), (-3.0, 0.0, 0.4, 8.0), (30.0, 1.5, 0.0, 0.5)]  # shifts out of the image too


@pytest.mark.parametrize("model", PT_MODELS)
def test_pt_warp_matches_cpu(gpu, model):
    right = np.random.default_rng(31).uniform(0, 255, (H, W)).astype(np.float32)
    got = host(gpu, gpu.pt_warp(gpu.to_device(right), *model))
    want = cpu.pt_warp(right, *model)
    assert got.dtype == np.float32 and got.shape == (H, W)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-4)  # 0-255 grey levels


@pytest.mark.parametrize("model", PT_MODELS)
def test_pt_restore_matches_cpu(gpu, model):
    rng = np.random.default_rng(32)
    disp = rng.uniform(0, 18, (H, W)).astype(np.float32)
    disp[rng.random((H, W)) < 0.3] = np.inf
    got = host(gpu, gpu.pt_restore(gpu.to_device(disp), *model))
    want = cpu.pt_restore(disp, *model)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(np.isinf(got), np.isinf(disp))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=COST_ATOL)


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
    one upload (the band index, built on the host), and only counters (<= 2 numbers)
    come back to the host."""
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
    assert sweeps >= 2 and all(n <= 2 for n in spy.downloads) and len(spy.downloads) == sweeps + 2
    assert n_decided == int((gpu.to_host(merged) >= 0).sum()) > 0
    assert np.isfinite(gpu.to_host(sub)).sum() == n_decided


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
    # one upload of the pair (its pyramid), and per level its band index (stored cells;
    # below the coarsest also the visible bands), built on the host from the coarser map;
    # big downloads: those coarser maps, the level maps and the result
    images = [level.shape for level in want.levels] * 2
    indexes = [level.shape + (3,) for level in want.levels] + [level.shape + (3,) for level in want.levels[:-1]]
    assert sorted(spy.uploads) == sorted(images + indexes)
    assert len([n for n in spy.downloads if n > 2]) <= 2 * n_levels + 1
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
    from d3cli.method.band import band_indexes
    from d3cli.method.cost import aggregation_halo, level_cost

    cfg = load_config(overrides=[f"aggregation.rbf={str(rbf).lower()}", "aggregation.kappa_a=2",
                                 "aggregation.t_max=3", "cost.window=3"])
    rng = np.random.default_rng(50)
    left, right = random_images(rng, (H, W))
    coarse = sparse_map(rng, ((H + 1) // 2, (W + 1) // 2), 5, share=0.5)
    bands = band_indexes(coarse, (H, W), n_disp=10, margin=2, tile=4, halo=aggregation_halo(cfg))
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
    np.testing.assert_array_equal(host(gpu, gpu.min_cost(got)), least)
    start = sparse_map(rng, (H, W), 10, share=0.2)
    disp_want, sweeps_want = cpu.diffuse(want, start, least, 0.1, 1, 1, True, 1000)
    disp_got, sweeps_got = gpu.diffuse(got, start, gpu.min_cost(got), 0.1, 1, 1, True, 1000)
    np.testing.assert_array_equal(host(gpu, disp_got), disp_want)
    assert sweeps_got == sweeps_want
    np.testing.assert_array_equal(host(gpu, gpu.inherit(got, coarse, True, 1.05, 1e-3)),
                                  cpu.inherit(want, coarse, True, 1.05, 1e-3))
    np.testing.assert_allclose(host(gpu, gpu.subpixel(got, disp_want)), cpu.subpixel(want, disp_want),
                               rtol=0, atol=COST_ATOL)
