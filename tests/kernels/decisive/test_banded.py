"""The decisive drivers on banded volumes against the same driver on the full-range volume whose
missing cells hold +inf (tests/kernels/test_volume.py says why that must hold)."""

from __future__ import annotations

import numpy as np
import pytest
from tests.kernels.banded import case
from tests.volumes import DIFFUSION_SETTINGS, sparse_map

from d3cli.kernels import cpu
from d3cli.kernels.cpu_common import ops
from d3cli.kernels.decisive.cpu_seeds import right_wta_row


def test_banded_min_cost_equals_the_full_range_with_inf(case):
    _, vol, with_inf = case
    np.testing.assert_array_equal(cpu.min_cost(vol), cpu.min_cost(with_inf))


@pytest.mark.parametrize("exclusion", [0, 1])
def test_banded_seeds_equal_the_full_range_with_inf(case, exclusion):
    _, vol, with_inf = case
    got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, exclusion)
    np.testing.assert_array_equal(got, cpu.decisive_seeds(with_inf, 1.05, 1e-3, 1, exclusion))


def test_seeds_skip_the_pixels_already_decided(case):
    rng, vol, _ = case
    full = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, 0)
    skip = sparse_map(rng, vol.shape, vol.n_disp, share=0.5)
    got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, 0, skip=skip)
    np.testing.assert_array_equal(got, np.where(skip >= 0, -1, full))


def test_right_view_wta_table_of_a_row_equals_the_scan_of_each_column(case):
    """The seeds' row table (one pass over the cells) against pixel.right_wta,
    which scans the disparities of one right pixel; ties and columns without a cell included."""
    _, vol, _ = case
    flat, index, n_disp = vol.cost, vol.index, vol.n_disp
    flat = np.round(flat * 4) / 4  # coarse values: many ties
    h, w = vol.shape
    for v in range(h):
        want = [ops.right_wta(flat, index, n_disp, v, x) for x in range(w)]
        np.testing.assert_array_equal(right_wta_row(flat, index, v), want)


@pytest.mark.parametrize("share", [0.0, 0.5, 0.95])
def test_seeds_with_few_or_many_candidates_per_row_equal_the_reference(case, share):
    """Rows with many candidate seeds take the right view's WTA from the row table, rows
    with few scan it per candidate: both give the per-pixel seed_at's seeds."""
    rng, vol, _ = case
    skip = sparse_map(rng, vol.shape, vol.n_disp, share=share)
    h, w = vol.shape
    for exclusion in (0, 1):
        want = np.array([[-1 if skip[v, u] >= 0 else
                          ops.seed_at(vol.cost, vol.index, vol.n_disp, v, u, 1.05, 1e-3, 1, exclusion)
                          for u in range(w)] for v in range(h)])
        got = cpu.decisive_seeds(vol, 1.05, 1e-3, 1, exclusion, skip=skip)
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS)
def test_banded_diffusion_equals_the_full_range_with_inf(case, settings):
    rng, vol, with_inf = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.2)
    disp[disp >= 0] = np.clip(disp[disp >= 0], 0, vol.n_disp - 1)
    got, sweeps = cpu.diffuse(vol, disp, cpu.min_cost(vol), max_sweeps=1000, **settings)
    want, want_sweeps = cpu.diffuse(with_inf, disp, cpu.min_cost(with_inf), max_sweeps=1000, **settings)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps


@pytest.mark.parametrize("settings", DIFFUSION_SETTINGS)
def test_banded_diffusion_finding_the_least_costs_itself_equals_them_given(case, settings):
    # min_cost None: pixel.diffuse_at finds the least cost over the band where it needs it
    rng, vol, _ = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.2)
    disp[disp >= 0] = np.clip(disp[disp >= 0], 0, vol.n_disp - 1)
    got, sweeps = cpu.diffuse(vol, disp, None, max_sweeps=1000, **settings)
    want, want_sweeps = cpu.diffuse(vol, disp, cpu.min_cost(vol), max_sweeps=1000, **settings)
    np.testing.assert_array_equal(got, want)
    assert sweeps == want_sweeps


@pytest.mark.parametrize("prc", [True, False])
def test_banded_inheritance_equals_the_full_range_with_inf(case, prc):
    rng, vol, with_inf = case
    h, w = vol.shape
    coarse = sparse_map(rng, ((h + 1) // 2, (w + 1) // 2), (vol.n_disp + 1) // 2, share=0.8)
    got = cpu.inherit(vol, coarse, prc, 1.05, 1e-3)
    np.testing.assert_array_equal(got, cpu.inherit(with_inf, coarse, prc, 1.05, 1e-3))


def test_banded_subpixel_equals_the_full_range_with_inf(case):
    rng, vol, with_inf = case
    disp = sparse_map(rng, vol.shape, vol.n_disp, share=0.9)
    lo, hi = vol.index[:, :, 1], vol.index[:, :, 2]
    disp = np.where(disp >= 0, np.clip(disp, lo, hi - 1), -1).astype(np.int32)  # decided inside the band
    got = cpu.subpixel(vol, disp)
    np.testing.assert_array_equal(got, cpu.subpixel(with_inf, disp))
    # next to a band end the integer disparity is kept, as at the ends of the range
    at_end = (disp >= 0) & ((disp == lo) | (disp == hi - 1))
    np.testing.assert_array_equal(got[at_end], disp[at_end].astype(np.float32))
