"""The CPU decisive steps (seeds, least costs, diffusion, inheritance, sub-pixel) against
the slow references of tests/reference/steps.py: integer maps exactly, known answers by hand."""

from __future__ import annotations

import cv2
import numba
import numpy as np
import pytest
from tests import reference as ref
from tests.volumes import DIFFUSION_SETTINGS, mark_missing_cells, random_volume, sparse_map, structured_volume

from d3cli.kernels import cpu
from d3cli.kernels.cpu_common import ops
from d3cli.kernels.decisive.cpu_diffusion import SERIAL_FRONTIER
from d3cli.kernels.volume import banded_index
from d3cli.method.pyramid import downsample

COST_ATOL = 1e-5
SHAPES = [(7, 9), (13, 11), (1, 12), (12, 1), (1, 1), (5, 6)]


# ----------------------------------------------------------------------------- seeds
@pytest.mark.parametrize("levels", [None, 8])
def test_seeds_match_reference_on_random_volumes(levels):
    rng = np.random.default_rng(11 if levels else 12)
    for h, w in SHAPES:
        for n_disp in (1, 2, 4, 7):
            cost = random_volume(rng, h, w, n_disp, levels=levels)
            for pkrn_min, exclusion, lr_tol in [(1.0, 0, 1), (1.2, 0, 0), (1.1, 1, 1), (2.0, 2, 2)]:
                got = cpu.decisive_seeds(cost, pkrn_min, 1e-3, lr_tol, exclusion)
                want = ref.ref_decisive_seeds(cost, pkrn_min, 1e-3, lr_tol, exclusion)
                np.testing.assert_array_equal(got, want, err_msg=f"{h}x{w}x{n_disp} {pkrn_min=} {exclusion=}")


def test_seeds_match_reference_on_structured_volumes():
    rng = np.random.default_rng(13)
    true = (np.arange(11)[None, :] // 4 + np.arange(13)[:, None] // 5).astype(np.int64) + 1
    cost = structured_volume(rng, true, 7, noise=0.1)
    for pkrn_min in (1.0, 1.3, 2.0):
        got = cpu.decisive_seeds(cost, pkrn_min, 1e-3, 1, 0)
        np.testing.assert_array_equal(got, ref.ref_decisive_seeds(cost, pkrn_min, 1e-3, 1, 0))
    assert (cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0) >= 0).sum() > 20


def test_seeds_single_clear_minimum():
    h, w, d0 = 5, 9, 3
    cost = np.full((h, w, 6), 0.8, np.float32)
    cost[:, :, d0] = 0.1
    mark_missing_cells(cost)
    seeds = cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)
    want = np.where(np.arange(w)[None, :] >= d0, d0, -1) * np.ones((h, 1), int)
    np.testing.assert_array_equal(seeds, want)
    assert seeds.dtype == np.int32


def test_seeds_reject_ambiguous_and_inconsistent_pixels():
    cost = np.full((1, 8, 4), 0.8, np.float32)
    cost[0, 5, 2] = 0.1  # clear minimum at (5, 0) with d = 2 ...
    cost[0, 6, 3] = 0.05  # ... but right pixel 3 prefers d = 3 (left pixel 6): within tolerance 1
    cost[0, 7, 0] = 0.3
    cost[0, 7, 1] = 0.3  # tie at (7, 0): PKRN = 1 -> no seed
    mark_missing_cells(cost)
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 5] == 2
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 0, 0)[0, 5] == -1  # strict LR check
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 7] == -1
    assert cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 1)[0, 7] == 0  # tie is inside the exclusion zone


def test_seed_whose_right_pixel_is_outside_is_rejected():
    cost = np.full((1, 6, 4), 0.9, np.float32)
    cost[0, 0, 2] = 0.1  # an aggregated 'missing' cell that wins: right pixel u - d = -2
    verdicts = set()
    for far_value in (0.5, 0.05):
        cost[0, 4, 0] = far_value  # unrelated pixel that Numba reads through the wrap-around
        verdicts.add(int(cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)[0, 0]))
    assert verdicts == {-1}


def _in_order_candidate(cells, lo, u, pkrn_min, epsilon, exclusion):
    """Test (a) of the seeds as the in-order scan with a strict ``<`` (the kernel before
    interleaved lanes): the first disparity of least cost, then the second cost."""
    d1, c1 = lo, cells[0]
    for k in range(1, len(cells)):
        if cells[k] < c1:
            d1, c1 = lo + k, cells[k]
    if c1 >= 1.0:
        return -1
    if exclusion == 0:
        others = [c for k, c in enumerate(cells) if k != d1 - lo]
    else:
        others = [c for k, c in enumerate(cells) if abs(lo + k - d1) > exclusion]
    c2 = min(others, default=np.inf)
    if c2 == np.inf or float(c2) + epsilon < pkrn_min * (float(c1) + epsilon):
        return -1
    return d1 if u - d1 >= 0 else -1


@pytest.mark.parametrize("levels", [None, 3])
def test_seed_candidate_by_lanes_equals_the_in_order_scan(levels):
    """pixel.seed_candidate takes the least and second costs by value in four interleaved
    lanes and d1 as the first disparity holding the least: the same verdicts as
    the in-order scan on bands of 1 to 41 cells (every lane remainder), ties included."""
    rng = np.random.default_rng(21 if levels else 22)
    h, w, n_disp = 6, 60, 48
    lo = rng.integers(0, 8, (h, w))
    hi = np.minimum(n_disp, lo + 1 + np.arange(h * w).reshape(h, w) % 41)
    index, n_cells = banded_index(lo, hi)
    cost = rng.random(n_cells, dtype=np.float32)
    if levels:
        cost = np.round(cost * levels) / levels  # coarse values: many ties, some cost 1
    cost = cost.astype(np.float32)
    for pkrn_min, exclusion in [(1.0, 0), (1.2, 0), (1.1, 1), (1.05, 3)]:
        for v in range(h):
            for u in range(w):
                cells = cost[index[v, u, 0] + lo[v, u]:index[v, u, 0] + hi[v, u]]
                want = _in_order_candidate(cells, lo[v, u], u, pkrn_min, 1e-3, exclusion)
                got = ops.seed_candidate(cost, index, v, u, pkrn_min, 1e-3, exclusion)
                assert got == want, (v, u, pkrn_min, exclusion)


@pytest.mark.parametrize("curve, pkrn_min, want", [
    ([0.9, 0.2, 0.5, 0.1], 1.9, 3),   # c2 is the minimum the last cell displaced: 0.2 / 0.1
    ([0.9, 0.2, 0.5, 0.1], 2.1, -1),  # (c2 = 0.5 would pass)
    ([0.2, 0.5, 0.2, 0.9], 1.05, -1),  # two equal minima: c2 = c1, PKRN 1
    ([0.5, 0.2, 0.9, 0.9], 2.4, 1),    # c2 = 0.5, ahead of the minimum
    ([0.5, 0.2, 0.9, 0.9], 2.6, -1),
])
def test_seed_pkrn_second_cost_known_answers(curve, pkrn_min, want):
    # Naive PKRN (exclusion 0) keeps c2 in the same pass as the minimum: the
    # second cost is the least of the other cells, wherever it lies.
    cost = np.ones((1, 8, 4), np.float32)
    cost[0, 5] = curve
    assert cpu.decisive_seeds(cost, pkrn_min, 0.0, 0, 0)[0, 5] == want


# ----------------------------------------------------------------------------- min cost
def test_min_cost_matches_reference():
    rng = np.random.default_rng(14)
    cost = random_volume(rng, 7, 9, 5)
    np.testing.assert_array_equal(cpu.min_cost(cost), ref.ref_min_cost(cost))


# ----------------------------------------------------------------------------- diffusion
def run_diffusion(cost, disp, *, max_gap, tau, kappa_d, adversarial, max_sweeps=100000):
    return cpu.diffuse(cost, disp, cpu.min_cost(cost), float(max_gap), tau, kappa_d, adversarial, max_sweeps)


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_matches_whole_image_jacobi_reference(settings):
    rng = np.random.default_rng(15)
    cases = []
    for h, w in SHAPES:
        for n_disp in (1, 3, 7):
            cases.append((random_volume(rng, h, w, n_disp), sparse_map(rng, (h, w), n_disp)))
            cases.append((random_volume(rng, h, w, n_disp, levels=6), sparse_map(rng, (h, w), n_disp)))
    true = (np.arange(11)[None, :] // 5 + np.arange(13)[:, None] // 4).astype(np.int64) + 1
    for noise in (0.02, 0.3):
        cost = structured_volume(rng, true, 7, noise=noise)
        cases.append((cost, sparse_map(rng, true.shape, 7, share=0.05)))  # some seeds wrong
    for cost, disp in cases:
        before = disp.copy()
        got, sweeps = run_diffusion(cost, disp, **settings)
        want, want_sweeps = ref.ref_diffuse(cost, disp, **settings)
        np.testing.assert_array_equal(got, want, err_msg=f"{cost.shape}")
        assert sweeps == want_sweeps
        np.testing.assert_array_equal(disp, before)  # input untouched
        if not settings["adversarial"]:
            assert (got[before >= 0] == before[before >= 0]).all()


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_finding_the_least_costs_itself_matches_reference(settings):
    # min_cost None (the pipeline's call): pixel.diffuse_at finds the least
    # cost of a pixel whose candidate reaches the gap test; the maps of the reference
    rng = np.random.default_rng(27)
    for h, w in SHAPES:
        for n_disp in (1, 3, 7):
            cost = random_volume(rng, h, w, n_disp, levels=6)
            disp = sparse_map(rng, (h, w), n_disp)
            got, sweeps = cpu.diffuse(cost, disp, None, float(settings["max_gap"]), settings["tau"],
                                      settings["kappa_d"], settings["adversarial"], 100000)
            want, want_sweeps = ref.ref_diffuse(cost, disp, **settings)
            np.testing.assert_array_equal(got, want, err_msg=f"{cost.shape}")
            assert sweeps == want_sweeps


def test_diffusion_from_one_seed_fills_the_known_minimum_map():
    rng = np.random.default_rng(16)
    h, w, n_disp = 13, 17, 8
    true = np.broadcast_to((2 + np.arange(h) // 3)[:, None], (h, w)).astype(np.int64)  # road-like: d grows with v
    cost = structured_volume(rng, true, n_disp, noise=0.01)
    seeds = np.full((h, w), -1, np.int32)
    seeds[h // 2, w // 2] = true[h // 2, w // 2]
    got, sweeps = run_diffusion(cost, seeds, max_gap=-1.0, tau=1, kappa_d=1, adversarial=True)
    exists = np.arange(w)[None, :] >= true  # the true cell has a right pixel
    np.testing.assert_array_equal(got[exists], true[exists])
    want, want_sweeps = ref.ref_diffuse(cost, seeds, -1.0, 1, 1, True)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps >= max(h, w) // 2


def test_diffusion_adversarial_update_corrects_a_wrong_seed():
    h, w = 5, 9
    true = np.full((h, w), 2)
    cost = structured_volume(np.random.default_rng(17), true, 6, noise=0.0)
    seeds = np.full((h, w), -1, np.int32)
    seeds[2, 4] = 2
    seeds[2, 6] = 4  # wrong, and a local minimum of nothing: its neighbours will overrule it
    got, _ = run_diffusion(cost, seeds, max_gap=-1.0, tau=2, kappa_d=1, adversarial=True)
    assert got[2, 6] == 2
    kept, _ = run_diffusion(cost, seeds, max_gap=-1.0, tau=2, kappa_d=1, adversarial=False)
    assert kept[2, 6] == 4


def test_diffusion_without_seeds_runs_no_sweep():
    cost = random_volume(np.random.default_rng(18), 5, 7, 3)
    got, sweeps = run_diffusion(cost, np.full((5, 7), -1, np.int32), max_gap=-1.0, tau=1, kappa_d=1, adversarial=True)
    assert sweeps == 0 and (got == -1).all()


def test_diffusion_max_sweeps_safeguard_matches_truncated_reference():
    rng = np.random.default_rng(19)
    true = np.full((9, 11), 3)
    cost = structured_volume(rng, true, 6, noise=0.02)
    seeds = np.full((9, 11), -1, np.int32)
    seeds[4, 5] = 3
    for limit in (1, 2, 3):
        got, sweeps = run_diffusion(cost, seeds, max_gap=-1.0, tau=1, kappa_d=1, adversarial=True, max_sweeps=limit)
        want, _ = ref.ref_diffuse(cost, seeds, -1.0, 1, 1, True, max_sweeps=limit)
        assert sweeps == limit
        np.testing.assert_array_equal(got, want)


_diffuse_at = ops.diffuse_at


@numba.njit(cache=False)
def whole_image_jacobi(cost, index, disp0, least, max_gap, tau, kappa_d, adversarial):
    """Every pixel every sweep with ``pixel.diffuse_at`` (no frontier, no first-sweep
    special case), sweeps counted as the driver counts them."""
    disp = disp0.copy()
    h, w = disp.shape
    if not (disp >= 0).any():
        return disp, 0
    sweeps = 0
    while True:
        sweeps += 1
        new = disp.copy()
        for v in range(h):
            for u in range(w):
                new[v, u] = _diffuse_at(cost, index, disp, least, max_gap, v, u, tau, kappa_d, adversarial)
        changed = (new != disp).any()
        disp = new
        if not changed:
            return disp, sweeps


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_diffusion_with_large_frontiers_matches_whole_image_jacobi(settings):
    """Frontiers above ``SERIAL_FRONTIER`` (parallel, in chunks), rows of several 64-pixel
    bitmap words plus a partial one: the frontier driver as whole-image Jacobi sweeps."""
    from d3cli.kernels.volume import dense_index

    rng = np.random.default_rng(23)
    h, w, n_disp = 96, 203, 9
    blocks = rng.integers(1, n_disp, (h // 8 + 1, w // 8 + 1))
    true = np.repeat(np.repeat(blocks, 8, 0), 8, 1)[:h, :w]
    cost = structured_volume(rng, true, n_disp, noise=0.1)
    seeds = sparse_map(rng, (h, w), n_disp, share=0.03)
    seeds[seeds >= 0] = np.where(rng.random((seeds >= 0).sum()) < 0.8, true[seeds >= 0], seeds[seeds >= 0])
    least = cpu.min_cost(cost)
    got, sweeps = cpu.diffuse(cost, seeds, least, max_sweeps=100000, **settings)
    index = dense_index(h, w, n_disp)
    args = (float(settings["max_gap"]), settings["tau"], settings["kappa_d"], settings["adversarial"])
    want, want_sweeps = whole_image_jacobi(cost.ravel(), index, seeds, least, *args)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps > 3
    first, _ = cpu.diffuse(cost, seeds, least, max_sweeps=1, **settings)
    assert (first != seeds).sum() * 3 > SERIAL_FRONTIER  # a parallel frontier follows


@numba.njit(cache=False)
def one_jacobi_sweep(cost, index, disp, max_gap, tau, kappa_d, adversarial):
    """One sweep of ``pixel.diffuse_at`` over every pixel (least costs found per pixel)."""
    least = np.empty((0, 0), np.float32)
    new = np.empty_like(disp)
    for v in range(disp.shape[0]):
        for u in range(disp.shape[1]):
            new[v, u] = _diffuse_at(cost, index, disp, least, max_gap, v, u, tau, kappa_d, adversarial)
    return new


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS, ids=lambda s: "-".join(f"{k}{v}" for k, v in s.items()))
def test_first_sweep_on_plain_neighbourhoods_matches_diffuse_at(settings):
    """The first sweep settles pixels without a decided neighbour and decided pixels in
    a uniform 3x3 block without ``pixel.diffuse_at``: on maps of uniform and
    undecided blocks, over bands (the disparity sometimes outside the band), costs with
    ties and NaN cells, it gives what ``diffuse_at`` gives every pixel."""
    from d3cli.kernels.volume import Volume, banded_index

    rng = np.random.default_rng(29)
    h, w, n_disp = 37, 71, 9
    for trial in range(6):
        size = (2, 3, 5)[trial % 3]
        blocks = rng.integers(-1, n_disp, (h // size + 1, w // size + 1))
        disp = np.repeat(np.repeat(blocks, size, 0), size, 1)[:h, :w].astype(np.int32)
        disp[rng.random((h, w)) < 0.03] = -1
        lo = rng.integers(0, n_disp // 2, (h, w))
        hi = np.minimum(n_disp, lo + rng.integers(1, n_disp + 1, (h, w)))
        index, n_cells = banded_index(lo, hi)
        cost = np.floor(rng.random(n_cells) * 4).astype(np.float32) / 4  # many ties
        cost[rng.random(n_cells) < 0.02] = np.nan
        args = (float(settings["max_gap"]), settings["tau"], settings["kappa_d"], settings["adversarial"])
        got, sweeps = cpu.diffuse(Volume(cost, index, n_disp), disp, None, max_sweeps=1, **settings)
        np.testing.assert_array_equal(got, one_jacobi_sweep(cost, index, disp, *args))
        assert sweeps == 1


# ----------------------------------------------------------------------------- inheritance
def coarse_map_for(rng, shape, n_disp, share=0.7):
    h, w = shape
    coarse = rng.integers(0, (n_disp + 1) // 2, (h // 2, w // 2)).astype(np.int32)
    coarse[rng.random(coarse.shape) >= share] = -1
    return coarse


def test_inheritance_without_prc_matches_reference():
    rng = np.random.default_rng(20)
    for h, w in [(7, 9), (13, 11), (2, 12), (12, 2), (6, 6)]:
        for n_disp in (3, 5, 7):
            for levels in (None, 5):
                cost = random_volume(rng, h, w, n_disp, levels=levels)
                coarse = coarse_map_for(rng, (h, w), n_disp)
                for pkrn in (1.0, 1.05, 1.5):
                    got = cpu.inherit(cost, coarse, False, pkrn, 1e-3)
                    np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, False, pkrn, 1e-3))


def test_inheritance_with_prc_and_zero_disparity_matches_reference():
    # dc = 0: the left and right patches coincide, so this part of the PRC is pinned
    # independently of which patch each view looks at.
    rng = np.random.default_rng(21)
    for h, w in [(7, 9), (13, 11), (2, 12), (6, 6)]:
        for n_disp in (2, 5):
            cost = random_volume(rng, h, w, n_disp, levels=8)
            coarse = np.where(rng.random((h // 2, w // 2)) < 0.8, 0, -1).astype(np.int32)
            got = cpu.inherit(cost, coarse, True, 1.05, 1e-3)
            np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, True, 1.05, 1e-3))


def test_inheritance_with_prc_matches_reference():
    rng = np.random.default_rng(22)
    for h, w in [(7, 9), (13, 11), (2, 12), (12, 2), (6, 6)]:
        for n_disp in (3, 5, 7):
            for _ in range(4):
                cost = random_volume(rng, h, w, n_disp, levels=8)
                coarse = coarse_map_for(rng, (h, w), n_disp)
                got = cpu.inherit(cost, coarse, True, 1.05, 1e-3)
                np.testing.assert_array_equal(got, ref.ref_inherit(cost, coarse, True, 1.05, 1e-3))


def sharp_volume(true, n_disp):
    """Cost 0.05 at the true disparity, 0.9 elsewhere, 1 where the right pixel is missing."""
    cost = np.full(true.shape + (n_disp,), 0.9, np.float32)
    v, u = np.indices(true.shape)
    cost[v, u, true] = 0.05
    return mark_missing_cells(cost)


def inside_patches(true, coarse_true):
    """Fine pixels whose left patch, right patch and outside cells all lie in the image."""
    h, w = true.shape
    v, u = np.indices((h, w))
    u0 = 2 * (u // 2)
    x0 = u0 - 2 * coarse_true[v // 2, u // 2]
    return (x0 - 2 >= 0) & (u0 + 3 < w) & (v < 2 * (h // 2))


@pytest.mark.parametrize("prc", [True, False])
def test_inheritance_of_a_perfect_coarse_map_constant_disparity(prc):
    # With the bug, columns within 2 dc of either border are dropped: the left-view PRC
    # looks at left pixels u0 - 2dc (missing cells, cost 1) and the right-view PRC at
    # C_R(u0, .) = C_L(u0 + 2dc, .) (outside the image, inf).
    h, w, n_disp = 8, 24, 10
    true = np.full((h, w), 6)
    coarse = np.full((h // 2, w // 2), 3, np.int32)
    got = cpu.inherit(sharp_volume(true, n_disp), coarse, prc, 1.05, 1e-3)
    inside = inside_patches(true, coarse)
    assert inside.sum() > 40
    np.testing.assert_array_equal(got[inside], 6)
    np.testing.assert_array_equal(got, ref.ref_inherit(sharp_volume(true, n_disp), coarse, prc, 1.05, 1e-3))


def test_inheritance_of_a_perfect_coarse_map_rejects_wrong_coarse_disparity():
    true = np.full((8, 24), 6)
    coarse = np.full((4, 12), 1, np.int32)  # 2 dc = 2: the true minimum is far outside {1, 2, 3}
    assert (cpu.inherit(sharp_volume(true, 10), coarse, True, 1.05, 1e-3) == -1).all()


def test_inheritance_of_a_perfect_coarse_map_with_a_disparity_step():
    h, w, n_disp = 6, 40, 12
    true = np.where(np.arange(w)[None, :] < 16, 2, 8) * np.ones((h, 1), int)
    coarse = (true[::2, ::2] // 2).astype(np.int32)
    got = cpu.inherit(sharp_volume(true, n_disp), coarse, True, 1.05, 1e-3)
    # Every pixel of the far plane whose patches lie inside it inherits its disparity,
    # including u in [16, 24) where the right patch u0 - 8 lies over the near plane's columns.
    u = np.broadcast_to(np.arange(w)[None, :], (h, w))
    far = (u >= 16) & (u + 3 < w)
    np.testing.assert_array_equal(got[far], 8)


# ----------------------------------------------------------------------------- sub-pixel
@pytest.mark.parametrize("equiangular", [False, True])
def test_subpixel_matches_reference(equiangular):
    rng = np.random.default_rng(23)
    for h, w in SHAPES:
        for n_disp in (1, 2, 5):
            cost = random_volume(rng, h, w, n_disp, levels=None if n_disp != 5 else 4)
            disp = sparse_map(rng, (h, w), n_disp, share=0.8)
            got = cpu.subpixel(cost, disp, equiangular)
            np.testing.assert_allclose(got, ref.ref_subpixel(cost, disp, equiangular), rtol=0, atol=COST_ATOL)
            assert got.dtype == np.float32 and (np.isinf(got) == (disp < 0)).all()


def parabola_volume(d0, n_disp=8, a=0.02, b=0.1):
    d = np.arange(n_disp, dtype=np.float64)
    return (a * (d - d0) ** 2 + b).astype(np.float32).reshape(1, 1, n_disp)


def test_subpixel_known_answers():
    one = np.array([[3]], np.int32)
    assert cpu.subpixel(parabola_volume(3.0), one)[0, 0] == 3.0  # symmetric: exactly integer
    np.testing.assert_allclose(cpu.subpixel(parabola_volume(3.3), one)[0, 0], 3.3, atol=1e-5)
    np.testing.assert_allclose(cpu.subpixel(parabola_volume(2.75), one)[0, 0], 2.75, atol=1e-5)
    # at d = 2 the parabola through 0.1, 0.2, 0.5 has its vertex 1 px to the left: clamped to -0.5
    steep = np.array([0.9, 0.1, 0.2, 0.5, 0.9], np.float32).reshape(1, 1, 5)
    assert cpu.subpixel(steep, np.array([[2]], np.int32))[0, 0] == 1.5
    concave = np.array([0.2, 0.5, 0.2], np.float32).reshape(1, 1, 3)
    assert cpu.subpixel(concave, np.array([[1]], np.int32))[0, 0] == 1.0
    flat = np.full((1, 1, 3), 0.4, np.float32)
    assert cpu.subpixel(flat, np.array([[1]], np.int32))[0, 0] == 1.0
    ends = parabola_volume(0.3, n_disp=4)
    assert cpu.subpixel(ends, np.array([[0]], np.int32))[0, 0] == 0.0
    assert cpu.subpixel(ends, np.array([[3]], np.int32))[0, 0] == 3.0
    assert np.isinf(cpu.subpixel(ends, np.array([[-1]], np.int32))[0, 0])


def v_volume(d0, n_disp=8, slope=0.05, b=0.1):
    """A cost with a V-shaped minimum at ``d0``: b + slope |d - d0|."""
    return (slope * np.abs(np.arange(n_disp) - d0) + b).astype(np.float32).reshape(1, 1, n_disp)


@pytest.mark.parametrize("d0", [3.0, 3.3, 2.75, 3.49])
def test_equiangular_subpixel_finds_the_tip_of_a_v_the_parabola_misses(d0):
    """Two lines of equal slope through three costs of a V meet at its tip exactly; the
    parabola through them is pulled towards the integer (pixel locking: at 3.3 it says
    3.2, at 2.75 it says 2.83)."""
    one = np.array([[int(round(d0))]], np.int32)
    np.testing.assert_allclose(cpu.subpixel(v_volume(d0), one, True)[0, 0], d0, atol=1e-5)
    parabola = cpu.subpixel(v_volume(d0), one)[0, 0]
    assert d0 not in (3.3, 2.75) or abs(parabola - d0) > 0.05
    steep = np.array([0.9, 0.1, 0.2, 0.5, 0.9], np.float32).reshape(1, 1, 5)
    assert cpu.subpixel(steep, np.array([[2]], np.int32), True)[0, 0] == 1.5  # not a minimum: clamped
    flat = np.full((1, 1, 3), 0.4, np.float32)
    assert cpu.subpixel(flat, np.array([[1]], np.int32), True)[0, 0] == 1.0


# ----------------------------------------------------------------------------- realistic volumes
@pytest.fixture(scope="module")
def aggregated_levels():
    """Aggregated NCC volumes of a textured slanted pair at 30x40 and 60x80 (as the pipeline makes).

    Unlike the random volumes above, the cells whose right pixel is outside the image hold
    averages below 1 here, as after RBF in the pipeline.
    """
    rng = np.random.default_rng(27)
    h, w = 60, 80
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (h, w + 40)).astype(np.float32), (0, 0), 1.2)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    # d = 3 + 0.04 u + 0.02 v; right pixel x shows the left point u with u - d(u) = x
    source = (u + 3.0 + 0.02 * v) / 0.96
    x0 = np.floor(source).astype(int)
    frac = source - x0
    left = tex[:, :w].copy()
    right = ((1 - frac) * tex[v.astype(int), x0] + frac * tex[v.astype(int), x0 + 1]).astype(np.float32)
    out = []
    for img_l, img_r, dmax in ((left, right, 10), (downsample(left), downsample(right), 5)):
        cost = cpu.ncc_cost_volume(img_l, img_r, dmax, 5, 1e-2)
        out.append(cpu.rbf_filter(cost, cpu.rbf_weights(img_l, 1.5, 12.0), 4))
    return out  # [fine, coarse]


def test_seeds_on_an_aggregated_volume_match_reference(aggregated_levels):
    for cost in aggregated_levels:
        got = cpu.decisive_seeds(cost, 1.2, 1e-3, 1, 0)
        np.testing.assert_array_equal(got, ref.ref_decisive_seeds(cost, 1.2, 1e-3, 1, 0))


def test_diffusion_and_inheritance_on_aggregated_volumes_match_reference(aggregated_levels):
    fine, coarse = aggregated_levels
    seeds = ref.ref_decisive_seeds(coarse, 1.2, 1e-3, 1, 0)
    assert (seeds >= 0).mean() > 0.5
    for max_gap in (-1.0, 0.05):
        got, sweeps = run_diffusion(coarse, seeds, max_gap=max_gap, tau=1, kappa_d=1, adversarial=True)
        want, want_sweeps = ref.ref_diffuse(coarse, seeds, max_gap, 1, 1, True)
        np.testing.assert_array_equal(got, want)
        assert sweeps == want_sweeps
    assert (got >= 0).mean() > 0.9
    inherited = cpu.inherit(fine, got, False, 1.05, 1e-3)
    np.testing.assert_array_equal(inherited, ref.ref_inherit(fine, got, False, 1.05, 1e-3))
    assert (inherited >= 0).mean() > 0.5
    got_fine, sweeps = run_diffusion(fine, inherited, max_gap=0.05, tau=1, kappa_d=1, adversarial=True)
    want_fine, want_sweeps = ref.ref_diffuse(fine, inherited, 0.05, 1, 1, True)
    np.testing.assert_array_equal(got_fine, want_fine)
    assert sweeps == want_sweeps


def test_inheritance_with_prc_on_an_aggregated_volume_matches_reference(aggregated_levels):
    fine, coarse = aggregated_levels
    seeds = ref.ref_decisive_seeds(coarse, 1.2, 1e-3, 1, 0)
    coarse_map, _ = run_diffusion(coarse, seeds, max_gap=0.05, tau=1, kappa_d=1, adversarial=True)
    got = cpu.inherit(fine, coarse_map, True, 1.05, 1e-3)
    np.testing.assert_array_equal(got, ref.ref_inherit(fine, coarse_map, True, 1.05, 1e-3))
