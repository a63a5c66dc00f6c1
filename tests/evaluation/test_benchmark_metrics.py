"""KITTI D1 and Middlebury bad-x / invalid / avgerr / rms / A-quantiles against loops written
after the benchmarks' own code (the KITTI devkit's io_disp.h and evaluate_scene_flow.cpp, the
MiddEval3 SDK's evaldisp.cpp), pixel by pixel."""

import math

import numpy as np
import pytest

from d3cli.evaluation.metrics import benchmark_metrics


def devkit_interpolate(pred):
    """``DisparityImage::interpolateBackground()``, loop for loop (-1 = invalid, as read from a PNG)."""
    h, w = pred.shape
    d = [[float(pred[v, u]) if math.isfinite(pred[v, u]) and pred[v, u] > 0 else -1.0 for u in range(w)]
         for v in range(h)]
    for v in range(h):
        count = 0
        for u in range(w):
            if d[v][u] >= 0:
                if count >= 1:
                    u1, u2 = u - count, u - 1
                    if u1 > 0 and u2 < w - 1:
                        ipol = min(d[v][u1 - 1], d[v][u2 + 1])
                        for uc in range(u1, u2 + 1):
                            d[v][uc] = ipol
                count = 0
            else:
                count += 1
        for u in range(w):
            if d[v][u] >= 0:
                for u2 in range(u):
                    d[v][u2] = d[v][u]
                break
        for u in range(w - 1, -1, -1):
            if d[v][u] >= 0:
                for u2 in range(u + 1, w):
                    d[v][u2] = d[v][u]
                break
    for u in range(w):
        for v in range(h):
            if d[v][u] >= 0:
                for v2 in range(v):
                    d[v2][u] = d[v][u]
                break
        for v in range(h - 1, -1, -1):
            if d[v][u] >= 0:
                for v2 in range(v + 1, h):
                    d[v2][u] = d[v][u]
                break
    return np.array(d)


def devkit_d1(ipol, gt, sel):
    """``disparityErrorsOutlier``: outliers among the selected pixels with valid ground truth."""
    errors = pixels = 0
    for (v, u), use in np.ndenumerate(sel):
        if use:
            err = abs(gt[v, u] - ipol[v, u])
            errors += err > 3.0 and err / abs(gt[v, u]) > 0.05
            pixels += 1
    return 100.0 * errors / pixels


def sdk_figures(pred, gt, sel, maxdisp=99999):
    """evaldisp's counts for every threshold, and the RMS / quantiles over avgErr's pixels."""
    n = invalid = 0
    errs = []
    for (v, u), use in np.ndenumerate(sel):
        if not use:
            continue
        n += 1
        d = pred[v, u]
        if not math.isfinite(d):
            invalid += 1
            continue
        errs.append(abs(max(0.0, min(maxdisp, d)) - gt[v, u]))
    out = {f"bad_{t:g}": 100.0 * sum(e > t for e in errs) / n for t in (0.5, 1, 2, 4)}
    out["invalid"] = 100.0 * invalid / n
    out["avgerr"] = sum(errs) / (n - invalid)
    out["rms"] = math.sqrt(sum(e * e for e in errs) / len(errs))
    s = sorted(errs)
    for q in (50, 90, 95, 99):
        out[f"a{q}"] = s[math.ceil(q / 100 * len(s)) - 1]
    out["n_px"] = n
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("holes", [0.0, 0.4])  # a dense and a sparse map
def test_random_maps_match_the_benchmarks_code(seed, holes):
    rng = np.random.default_rng(seed)
    gt = rng.uniform(0.5, 120.0, (17, 23))
    gt[rng.random(gt.shape) < 0.2] = np.inf  # no ground truth
    gt[rng.random(gt.shape) < 0.1] = 0.0
    noc_gt = np.where(rng.random(gt.shape) < 0.7, gt, np.inf)  # disp_noc: a part of disp_occ ...
    noc_gt[rng.random(gt.shape) < 0.05] += 7.0  # ... with values of its own at a few pixels
    pred = gt + rng.normal(0, 4.0, gt.shape)
    pred[~np.isfinite(pred)] = rng.uniform(1, 100)
    pred[rng.random(gt.shape) < holes] = np.nan  # no estimate
    pred[rng.random(gt.shape) < holes / 4] = -1.0  # a hole for KITTI, 0 for Middlebury
    pred[4] = np.inf  # an empty row between filled ones
    obj = (rng.random(gt.shape) < 0.3).astype(np.uint8) * 3
    noc_mask = np.isfinite(noc_gt) & (noc_gt > 0)
    r = benchmark_metrics(pred, gt, noc_mask=noc_mask, noc_gt=noc_gt, object_map=obj)
    ipol = devkit_interpolate(pred)
    valid = np.isfinite(gt) & (gt > 0)
    for name, truth, sel in (("all", gt, valid), ("noc", noc_gt, noc_mask)):
        assert r[f"d1_{name}"] == pytest.approx(devkit_d1(ipol, truth, sel)), name
        for key, value in sdk_figures(pred, truth, sel).items():
            assert r[f"{key}_{name}"] == pytest.approx(value), (key, name)
    assert r["d1_bg"] == pytest.approx(devkit_d1(ipol, gt, valid & (obj == 0)))
    assert r["d1_fg"] == pytest.approx(devkit_d1(ipol, gt, valid & (obj > 0)))
    assert r["n_px_noc"] < r["n_px_all"]
    clipped = benchmark_metrics(pred, gt, max_disparity=60)
    for key, value in sdk_figures(pred, gt, valid, maxdisp=60).items():
        assert clipped[f"{key}_all"] == pytest.approx(value), key


def test_without_noc_mask_the_noc_figures_are_nan_not_the_all_figures():
    gt = np.full((4, 4), 10.0)
    pred = gt + 5.0
    r = benchmark_metrics(pred, gt)
    assert r["d1_all"] == pytest.approx(100.0)
    assert math.isnan(r["d1_noc"]) and math.isnan(r["invalid_noc"]) and r["n_px_noc"] == 0
    assert "d1_fg" not in r
