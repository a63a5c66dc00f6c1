"""KITTI D1 and Middlebury bad-x / avgerr / rms / A-quantiles against independent NumPy code."""

import math

import numpy as np
import pytest

from d3cli.evaluation.metrics import benchmark_metrics, standard_errors


def reference(pred, gt, sel):
    """Independent loop-based computation of the benchmark figures over ``sel``."""
    errs, gts = [], []
    for (y, x), use in np.ndenumerate(sel):
        if not use:
            continue
        d = pred[y, x] if math.isfinite(pred[y, x]) else 0.0
        errs.append(abs(d - gt[y, x]))
        gts.append(gt[y, x])
    n = len(errs)
    out = {"d1": 100.0 * sum(e > 3 and e > 0.05 * g for e, g in zip(errs, gts)) / n}
    for t in (0.5, 1, 2, 4):
        out[f"bad_{t:g}"] = 100.0 * sum(e > t for e in errs) / n
    out["avgerr"] = sum(errs) / n
    out["rms"] = math.sqrt(sum(e * e for e in errs) / n)
    s = sorted(errs)
    for q in (50, 90, 95, 99):
        out[f"a{q}"] = s[math.ceil(q / 100 * n) - 1]
    out["n_px"] = n
    return out


def test_hand_computed_d1_uses_both_rules():
    gt = np.array([100.0, 100.0, 10.0, 10.0])
    err = np.array([4.0, 6.0, 3.5, 2.0])  # 4 < 5 % of 100; 6 > 5; 3.5 > 3 and > 0.5; 2 < 3
    r = standard_errors(err, gt)
    assert r["d1"] == pytest.approx(50.0)
    assert r["bad_4"] == pytest.approx(25.0)  # only 6 (4 is not > 4)
    assert r["bad_2"] == pytest.approx(75.0)
    assert r["avgerr"] == pytest.approx(3.875)
    assert r["rms"] == pytest.approx(math.sqrt((16 + 36 + 12.25 + 4) / 4))
    assert r["a50"] == pytest.approx(3.5)  # sorted 2, 3.5, 4, 6: ceil(0.5*4)-1 = index 1
    assert r["a90"] == pytest.approx(6.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_maps_match_the_reference(seed):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(0.5, 120.0, (17, 23))
    gt[rng.random(gt.shape) < 0.2] = np.inf  # no ground truth
    gt[rng.random(gt.shape) < 0.1] = 0.0
    pred = gt + rng.normal(0, 4.0, gt.shape)
    pred[rng.random(gt.shape) < 0.1] = np.nan  # no estimate
    noc = rng.random(gt.shape) < 0.7
    obj = (rng.random(gt.shape) < 0.3).astype(np.uint8) * 3
    r = benchmark_metrics(pred, gt, noc_mask=noc, object_map=obj)
    valid = np.isfinite(gt) & (gt > 0)
    for name, sel in (("all", valid), ("noc", valid & noc)):
        ref = reference(pred, gt, sel)
        for key, value in ref.items():
            assert r[f"{key}_{name}"] == pytest.approx(value), (key, name)
    assert r["d1_bg"] == pytest.approx(reference(pred, gt, valid & (obj == 0))["d1"])
    assert r["d1_fg"] == pytest.approx(reference(pred, gt, valid & (obj > 0))["d1"])
    assert r["n_px_noc"] < r["n_px_all"]


def test_without_noc_mask_the_noc_figures_are_nan_not_the_all_figures():
    gt = np.full((4, 4), 10.0)
    pred = gt + 5.0
    r = benchmark_metrics(pred, gt)
    assert r["d1_all"] == pytest.approx(100.0)
    assert math.isnan(r["d1_noc"]) and r["n_px_noc"] == 0
    assert "d1_fg" not in r
