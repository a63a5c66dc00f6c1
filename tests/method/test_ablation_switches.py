"""What each switch of the paper's ablation (Table I) changes in the pipeline.

- ``pyramid.ars`` false is DFM's linear structure: seeds at the coarsest level only (no
  fresh seeds below it, whatever ``seeds.every_level`` says) and diffusion only at the
  finest level;
- ``inheritance.prc`` false is DFM's PKRN test in the patch;
- ``inheritance.candidates`` selects the candidate sets the inheritance kernel tests;
- ``aggregation.rbf`` false is one plain bilateral pass of radius kappa_a whose sigma_1
  is scaled with the radius (``bilateral_sigma_space``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from tests.helpers import textured_pair

from d3cli import D3Stereo, load_config
from d3cli.errors import ConfigError
from d3cli.kernels import cpu
from d3cli.method.cost import aggregate, aggregation_halo, bilateral_sigma_space


def cfg(*overrides):
    return load_config(overrides=["run.backend=cpu", "pyramid.levels=3", *overrides])


@pytest.fixture(scope="module")
def pair():
    left, right, _ = textured_pair(6, (64, 96), seed=4)
    return left, right


def per_level(pair, *overrides):
    result = D3Stereo(cfg(*overrides)).compute(*pair, max_disparity=12)
    return result.info["per_level"]  # coarsest first


def test_alternating_structure_diffuses_and_seeds_at_every_level(pair):
    levels = per_level(pair, "pyramid.ars=true", "seeds.every_level=true")
    assert [s["level"] for s in levels] == [3, 2, 1]
    assert all(s["sweeps"] > 0 for s in levels)
    assert all("seeds" in s for s in levels)  # fresh seeds below the coarsest level too


@pytest.mark.parametrize("every_level", [True, False])
def test_linear_structure_seeds_only_at_the_coarsest_level_and_diffuses_only_at_the_finest(pair, every_level):
    levels = per_level(pair, "pyramid.ars=false", f"seeds.every_level={str(every_level).lower()}")
    assert levels[0]["seeds"] > 0 and levels[0]["sweeps"] == 0
    assert levels[1]["sweeps"] == 0 and "seeds" not in levels[1]
    assert levels[2]["sweeps"] > 0 and "seeds" not in levels[2]
    # without diffusion, level 2 holds only what inheritance kept
    h, w = levels[1]["shape"]
    assert levels[1]["decided_share"] == pytest.approx(levels[1]["inherited"] / (h * w))


def test_every_level_false_keeps_the_alternating_structure_without_fresh_seeds(pair):
    levels = per_level(pair, "pyramid.ars=true", "seeds.every_level=false")
    assert all(s["sweeps"] > 0 for s in levels)
    assert all("seeds" not in s for s in levels[1:])


@pytest.mark.parametrize("candidates, mode", [("symmetric", 0), ("paper", 1)])
@pytest.mark.parametrize("prc", [True, False])
def test_inheritance_gets_the_configured_test_and_candidates(pair, monkeypatch, candidates, mode, prc):
    calls = []
    real = cpu.inherit

    def spy(cost, coarse, prc_arg, dfm_pkrn_min, epsilon, candidates_arg=0):
        calls.append((prc_arg, dfm_pkrn_min, candidates_arg))
        return real(cost, coarse, prc_arg, dfm_pkrn_min, epsilon, candidates_arg)

    monkeypatch.setattr(cpu, "inherit", spy)
    per_level(pair, f"inheritance.candidates={candidates}", f"inheritance.prc={str(prc).lower()}",
              "inheritance.dfm_pkrn_min=1.2")
    assert calls == [(prc, 1.2, mode)] * 2  # levels 2 and 1


def test_paper_candidates_change_what_is_inherited(pair):
    sym = per_level(pair, "inheritance.candidates=symmetric")
    paper = per_level(pair, "inheritance.candidates=paper")
    assert sym[0]["seeds"] == paper[0]["seeds"]  # the coarsest level does not inherit
    # two candidates per pixel instead of three: fewer pixels pass
    assert paper[1]["inherited"] < sym[1]["inherited"]


def test_bilateral_sigma_is_scaled_with_the_radius():
    assert bilateral_sigma_space(1.5, 4) == 6.0
    assert bilateral_sigma_space(1.5, 1) == 1.5
    # the weight at the window's edge (distance kappa_a) and corner equal the 3x3 kernel's
    # at distance 1 and at its corner
    for kappa in (2, 4, 7):
        s = bilateral_sigma_space(1.5, kappa)
        assert math.exp(-(kappa**2) / s**2) == pytest.approx(math.exp(-1 / 1.5**2))
        assert math.exp(-2 * kappa**2 / s**2) == pytest.approx(math.exp(-2 / 1.5**2))


@pytest.mark.parametrize("rbf", [True, False])
def test_aggregation_switch_runs_rbf_passes_or_one_scaled_bilateral_pass(pair, monkeypatch, rbf):
    calls = []
    real_bf, real_rbf = cpu.bilateral_filter, cpu.rbf_filter

    def bf(cost, img, radius, sigma_space, sigma_color):
        calls.append(("bf", radius, sigma_space, sigma_color))
        return real_bf(cost, img, radius, sigma_space, sigma_color)

    def rbf_filter(cost, weights, t_max, **kw):
        calls.append(("rbf", t_max))
        return real_rbf(cost, weights, t_max, **kw)

    monkeypatch.setattr(cpu, "bilateral_filter", bf)
    monkeypatch.setattr(cpu, "rbf_filter", rbf_filter)
    per_level(pair, f"aggregation.rbf={str(rbf).lower()}", "aggregation.t_max=3", "aggregation.kappa_a=3",
              "aggregation.sigma_space=1.25", "aggregation.sigma_color=10")
    if rbf:
        # coarsest level first; none at full resolution (aggregation.finest_t_max 0 by default)
        assert calls == [("rbf", 3)] * 2
    else:
        assert calls == [("bf", 3, 3.75, 10.0)] * 3


def rbf_passes(monkeypatch):
    """The passes of every RBF call the CPU backend gets from now on, in a list."""
    calls = []
    real_rbf = cpu.rbf_filter

    def rbf_filter(cost, weights, t_max, **kw):
        calls.append(t_max)
        return real_rbf(cost, weights, t_max, **kw)

    monkeypatch.setattr(cpu, "rbf_filter", rbf_filter)
    return calls


@pytest.mark.parametrize("finest, passes", [("null", [3, 3, 3]), ("0", [3, 3]), ("2", [3, 3, 2])])
def test_finest_t_max_sets_the_passes_at_full_resolution_only(pair, monkeypatch, finest, passes):
    calls = rbf_passes(monkeypatch)
    per_level(pair, "aggregation.t_max=3", f"aggregation.finest_t_max={finest}")
    assert calls == passes


@pytest.mark.parametrize("per_level_passes, passes", [("[1,2,0]", [2, 1]), ("[5]", [5, 5, 5]), ("[0,4]", [4, 4])])
def test_level_t_max_sets_the_passes_of_each_level(pair, monkeypatch, per_level_passes, passes):
    """Finest first, its last value for every coarser level; it overrides t_max and
    finest_t_max (the calls come coarsest level first; 0 passes: no call)."""
    calls = rbf_passes(monkeypatch)
    per_level(pair, "aggregation.t_max=3", "aggregation.finest_t_max=null",
              f"aggregation.level_t_max={per_level_passes}")
    assert calls == passes
    cfg = load_config(None, [f"aggregation.level_t_max={per_level_passes}"])
    assert [aggregation_halo(cfg, level) for level in range(3)] == [cfg.level_t_max(level) for level in range(3)]


def test_level_t_max_rejects_passes_out_of_range():
    with pytest.raises(ConfigError, match=r"aggregation\.level_t_max.*a list of integers in \[0, 64\]"):
        load_config(None, ["aggregation.level_t_max=[2,65]"])


@pytest.mark.parametrize("finest, halo", [("null", 3), ("0", 0), ("2", 2)])
def test_the_band_halo_at_full_resolution_follows_its_passes(finest, halo):
    cfg = load_config(None, ["aggregation.t_max=3", f"aggregation.finest_t_max={finest}"])
    assert aggregation_halo(cfg, 0) == halo
    assert aggregation_halo(cfg, 1) == 3
    assert aggregation_halo(load_config(None, ["aggregation.rbf=false", "aggregation.kappa_a=5"]), 0) == 5


def test_bilateral_sigma_override_and_its_effect():
    rng = np.random.default_rng(0)
    cost = rng.random((12, 20, 5)).astype(np.float32)
    img = rng.uniform(0, 255, (12, 20)).astype(np.float32)
    common = dict(rbf=False, t_max=4, sigma_space=1.5, sigma_color=1e6, kappa_a=4, backend=cpu)
    scaled = aggregate(cost.copy(), img, **common)
    explicit = aggregate(cost.copy(), img, bf_sigma_space=6.0, **common)
    narrow = aggregate(cost.copy(), img, bf_sigma_space=1.5, **common)
    np.testing.assert_array_equal(scaled, explicit)
    # with a huge colour sigma the filter is a spatial Gaussian: the scaled one averages
    # 81 cells almost evenly, so it leaves far less variance than the narrow one
    inner = (slice(4, -4), slice(4, -4))
    assert scaled[inner].std() < 0.5 * narrow[inner].std()


@pytest.mark.parametrize("finest, tiles", [("null", [8, 8]), ("4", [8, 4]), ("16", [8, 16])])
def test_finest_band_tile_sets_the_tile_at_full_resolution_only(pair, monkeypatch, finest, tiles):
    from d3cli.kernels import cpu  # the backend the pipeline builds the bands with here

    calls = []
    real = cpu.band_indexes

    def band_indexes(coarse, shape, **kw):
        calls.append(kw["tile"])
        return real(coarse, shape, **kw)

    monkeypatch.setattr(cpu, "band_indexes", band_indexes)
    per_level(pair, "pyramid.band_tile=8", f"pyramid.finest_band_tile={finest}")
    assert calls == tiles  # the two levels below the coarsest, finest last


def test_finest_band_tile_of_the_shipped_configs():
    assert [load_config(None).level_band_tile(level) for level in range(4)] == [16, 32, 32, 32]
    assert [load_config("kitti").level_band_tile(level) for level in range(4)] == [24, 32, 32, 32]
    assert load_config("middlebury").level_band_tile(0) == 16


def test_finest_band_tile_changes_the_finest_bands_only(pair):
    # a narrower tile at full resolution: the coarser levels' maps are the same, the
    # finest level searches fewer cells
    wide = per_level(pair, "pyramid.band_tile=16", "pyramid.finest_band_tile=null")
    narrow = per_level(pair, "pyramid.band_tile=16", "pyramid.finest_band_tile=4")
    assert [s["band_cells"] for s in wide[1:-1]] == [s["band_cells"] for s in narrow[1:-1]]
    assert narrow[-1]["band_cells"] < wide[-1]["band_cells"]
