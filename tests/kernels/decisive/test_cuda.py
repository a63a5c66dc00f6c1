"""The CUDA decisive drivers against the CPU ones (marker ``cuda``; tests/kernels/test_cuda.py
says how they run)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.cuda_fixtures import COST_ATOL, H, W, gpu, host, small_blocks  # noqa: F401  (fixtures)
from tests.volumes import DIFFUSION_SETTINGS, mark_missing_cells, random_volume, sparse_map, structured_volume

from d3cli.kernels import cpu

pytestmark = pytest.mark.cuda


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


@pytest.mark.parametrize("cooperative", [True, False], ids=["one-kernel", "host-loop"])
@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_matches_cpu(gpu, settings, cooperative, monkeypatch):
    """Both ways of running the sweeps: one cooperative kernel per level, and the fallback
    host loop (one launch per phase) where cooperative launches are unavailable."""
    from d3cli.kernels.decisive import cuda_diffusion

    monkeypatch.setattr(cuda_diffusion, "COOPERATIVE", cooperative)
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
@pytest.mark.parametrize("equiangular", [False, True])
def test_subpixel_matches_cpu(gpu, equiangular):
    rng = np.random.default_rng(23)
    for n_disp, levels in ((1, None), (2, None), (6, 4)):
        cost = random_volume(rng, H, W, n_disp, levels=levels)
        disp = sparse_map(rng, (H, W), n_disp, share=0.8)
        got = host(gpu, gpu.subpixel(gpu.to_device(cost), gpu.to_device(disp), equiangular))
        want = cpu.subpixel(cost, disp, equiangular)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(np.isinf(got), np.isinf(want))
        np.testing.assert_allclose(got, want, rtol=0, atol=COST_ATOL)
