"""Band search (docs/design.md, 'Pyramid and bands'): the band rules against a NumPy reference, and every
visible cell of a banded level equal to the full-range volume's cell."""

from __future__ import annotations

import numpy as np
import pytest
from tests.helpers import textured_pair
from tests.reference import ref_band_indexes
from tests.volumes import sparse_map

from d3cli import D3Stereo, load_config
from d3cli.kernels import cpu
from d3cli.kernels.volume import to_dense
from d3cli.kernels.host import band_indexes
from d3cli.method.cost import aggregation_halo, level_cost


@pytest.mark.parametrize("shape,tile,halo", [((13, 17), 4, 1), ((20, 9), 8, 4), ((7, 30), 4, 5), ((16, 16), 16, 2)])
def test_band_indexes_match_reference(shape, tile, halo):
    rng = np.random.default_rng(tile + halo)
    n_disp = 11
    coarse = sparse_map(rng, ((shape[0] + 1) // 2, (shape[1] + 1) // 2), 6, share=0.4)
    coarse[:2, :] = -1  # whole tiles left undecided: full range there
    store, visible, n_cells = band_indexes(coarse, shape, n_disp=n_disp, margin=2, tile=tile, halo=halo)
    want_store, want_vis = ref_band_indexes(coarse, shape, n_disp, 2, tile, halo)
    np.testing.assert_array_equal(store[:, :, 1:], want_store)
    np.testing.assert_array_equal(visible[:, :, 1:], want_vis)
    np.testing.assert_array_equal(visible[:, :, 0], store[:, :, 0])
    sizes = (want_store[:, :, 1] - want_store[:, :, 0]).ravel()
    np.testing.assert_array_equal(store[:, :, 0].ravel() + want_store[:, :, 0].ravel(),
                                  np.concatenate([[0], np.cumsum(sizes)[:-1]]))
    assert n_cells == sizes.sum()


@pytest.mark.parametrize("overrides", [
    [],                                                   # NCC + RBF
    ["cost.window=9", "aggregation.t_max=6"],            # wider window, more passes than a small tile
    ["aggregation.rbf=false", "aggregation.kappa_a=3"],  # the plain bilateral filter
])
def test_visible_cells_equal_the_full_range_volume(overrides):
    # A coarse map with random disparities (some tiles empty) gives ragged bands; every
    # visible cell after aggregation must hold the full-range value (to float rounding
    # of the window sums), though the neighbours' bands differ.
    # the semi-global smoothing (on by default) runs along paths through the band, so it is
    # off here: this test is about the window sums and the filters
    cfg = load_config(None, ["pyramid.band_tile=8", "pyramid.band_margin=2", "aggregation.sgm_p1=0",
                             "aggregation.sgm_p2=0", "aggregation.finest_t_max=null"] + overrides)
    left, right, _ = textured_pair(5, (37, 53), seed=4)
    left = left.astype(np.float32)
    right = right.astype(np.float32)
    dmax = 24
    n_disp = dmax + 1
    full = level_cost(left, right, level=0, max_disparity=dmax, cfg=cfg, backend=cpu)
    rng = np.random.default_rng(1)
    coarse = np.broadcast_to(2 + np.arange(27) // 5, (19, 27)).astype(np.int32)  # steps of 1 every 5 columns
    coarse = np.where(rng.random(coarse.shape) < 0.1, -1, coarse).astype(np.int32)
    coarse[:4, :4] = -1  # a tile the coarser level left undecided: the full range around it
    bands = band_indexes(coarse, left.shape, n_disp=n_disp, margin=2, tile=8, halo=aggregation_halo(cfg, 0))
    part = level_cost(left, right, level=0, max_disparity=dmax, cfg=cfg, backend=cpu, bands=bands)
    assert part.cost.size == bands[2] < full.cost.size
    dense_full = to_dense(full.cost, full.index, n_disp)
    dense_part = to_dense(part.cost, part.index, n_disp)
    seen = ~np.isnan(dense_part)
    assert seen.sum() < seen.size  # the bands do leave cells out
    np.testing.assert_allclose(dense_part[seen], dense_full[seen], rtol=0, atol=2e-6)


def test_band_search_on_a_constant_shift_finds_it_with_far_fewer_cells():
    left, right, gt = textured_pair(9, (64, 128), seed=2)
    results = {}
    for band in (True, False):
        cfg = load_config(None, [f"pyramid.band={str(band).lower()}", "pyramid.levels=3", "run.backend=cpu"])
        results[band] = D3Stereo(cfg).compute(left, right, max_disparity=40)
    on, off = results[True], results[False]
    inside = np.isfinite(gt)
    for res in (on, off):
        assert np.median(np.abs(res.disparity[inside] - 9)) < 0.25
    cells = [lvl.get("band_cells") for lvl in on.info["per_level"]]
    assert cells[0] is None and all(c is not None for c in cells[1:])
    assert cells[-1] < 0.5 * 64 * 128 * 41
    assert all("band_cells" not in lvl for lvl in off.info["per_level"])
