"""The semi-global smoothing switch (docs/design.md, 'Semi-global smoothing'): where the pipeline applies it, and what
it does to a pair with a known disparity."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tests.helpers import textured_pair

from d3cli import D3Stereo, load_config
from d3cli.kernels import cpu
from d3cli.method.cost import level_cost

SGM = ["aggregation.sgm_p1=0.3", "aggregation.sgm_p2=1.2"]
OFF = ["aggregation.sgm_p1=0", "aggregation.sgm_p2=0"]


def _pair():
    left, right, gt = textured_pair(6, (40, 64), seed=3)
    return left.astype(np.float32), right.astype(np.float32), gt


def test_the_finest_level_cost_is_the_smoothed_aggregated_cost():
    left, right, _ = _pair()
    plain = level_cost(left, right, level=0, max_disparity=16, cfg=load_config(None, OFF), backend=cpu)
    smoothed = level_cost(left, right, level=0, max_disparity=16, cfg=load_config(None, SGM), backend=cpu)
    want = cpu.sgm_smooth(plain, 0.3, 1.2)
    np.testing.assert_array_equal(smoothed.index, plain.index)
    np.testing.assert_array_equal(smoothed.cost, want.cost)
    assert not np.array_equal(smoothed.cost, plain.cost)


def test_coarser_levels_are_not_smoothed():
    left, right, _ = _pair()
    half = (left[::2, ::2].copy(), right[::2, ::2].copy())
    plain = level_cost(*half, level=1, max_disparity=16, cfg=load_config(None, OFF), backend=cpu)
    other = level_cost(*half, level=1, max_disparity=16, cfg=load_config(None, SGM), backend=cpu)
    np.testing.assert_array_equal(other.cost, plain.cost)


def test_a_textured_constant_shift_is_still_found_exactly():
    left, right, gt = _pair()
    result = D3Stereo(load_config(None, SGM)).compute(left, right, max_disparity=16)
    inside = result.valid[:, 16:]
    assert inside.mean() > 0.9
    np.testing.assert_allclose(result.disparity[:, 16:][inside], gt[:, 16:][inside], atol=0.25)


def test_kitti_config_turns_it_on():
    cfg = load_config(Path(__file__).resolve().parents[2] / "d3cli" / "presets" / "kitti.yaml")
    assert (cfg.aggregation.sgm_p1, cfg.aggregation.sgm_p2) == (0.6, 1.2)
    assert (load_config(None).aggregation.sgm_p1, load_config(None).aggregation.sgm_p2) == (0.1, 1.2)
    # where the smoothing runs (full resolution) the shipped configs run no RBF passes before it
    assert cfg.level_t_max(0) == load_config(None).level_t_max(0) == 0
    assert cfg.level_t_max(1) == load_config(None).level_t_max(1) == 4


def test_paper_config_turns_it_off():
    cfg = load_config("paper")
    assert (cfg.aggregation.sgm_p1, cfg.aggregation.sgm_p2) == (0.0, 0.0)
    assert [cfg.level_t_max(level) for level in range(4)] == [4, 4, 4, 4]  # RBF at every level, as published


def test_the_smoothing_is_a_step_of_its_own_in_the_timings():
    left, right, _ = _pair()
    on = D3Stereo(load_config(None, SGM)).compute(left, right, max_disparity=16)
    off = D3Stereo(load_config(None, OFF)).compute(left, right, max_disparity=16)
    assert on.timings["sgm"] > 0 and "sgm" not in off.timings
    assert set(on.timings) - set(off.timings) == {"sgm"}
    # the steps share the total: "cost" no longer holds the smoothing's seconds
    steps = sum(v for k, v in on.timings.items() if k != "total")
    assert steps <= on.timings["total"]
    assert on.info["per_level"][-1]["time_sgm"] == on.timings["sgm"]
