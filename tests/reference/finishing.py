"""The NumPy/OpenCV formulation the finishing kernels replaced, kept verbatim as their reference.

``np.maximum.at`` for the uniqueness test, cumulative maxima for the row-wise filling,
``np.nanmedian`` over four directions, and the piecewise-linear bilateral filter with one
pair of ``cv2.boxFilter`` calls per range level; with the helpers the finishing tests
(``tests/kernels/finishing/``) share (byte comparison, random maps with holes, inf and NaN).
"""

from __future__ import annotations

import warnings
from collections import deque

import cv2
import numpy as np
import pytest


def ref_occluded_by_uniqueness(disparity, valid, *, tolerance=1.0):
    h, w = disparity.shape
    v, u = np.nonzero(valid)
    d = disparity[v, u]
    with np.errstate(invalid="ignore"):  # inf/NaN estimates cast to int64
        xr = np.clip(np.rint(u - d).astype(np.int64), 0, w - 1)
    flat = v.astype(np.int64) * w + xr
    best = np.full(h * w, -np.inf)
    np.maximum.at(best, flat, d)
    occluded = np.zeros((h, w), bool)
    with np.errstate(invalid="ignore"):
        occluded[v, u] = d < best[flat] - tolerance
    return occluded


def ref_out_of_view(disparity, valid, *, max_disparity):
    h, w = disparity.shape
    start = min(int(max_disparity), w - 1)
    sub_valid = valid[:, start:]
    has = sub_valid.any(axis=1)
    first = np.argmax(sub_valid, axis=1) + start
    b = np.where(has, disparity[np.arange(h), first], -np.inf)[:, None]
    cols = np.arange(w)[None, :]
    with np.errstate(invalid="ignore"):
        return valid & (cols < b) & (disparity < b - 1)


def ref_nearest_along_rows(disp, valid):
    h, w = disp.shape
    cols = np.broadcast_to(np.arange(w), (h, w))
    left_idx = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    right_idx = np.minimum.accumulate(np.where(valid, cols, w)[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(h)[:, None]
    left_val = np.where(left_idx >= 0, disp[rows, np.clip(left_idx, 0, w - 1)], np.inf)
    right_val = np.where(right_idx < w, disp[rows, np.clip(right_idx, 0, w - 1)], np.inf)
    return left_val, right_val


def ref_fill_holes(disparity, valid, *, smooth=True, occluded=None):
    disp = np.asarray(disparity, dtype=np.float32)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(disp)
    if not valid.any():
        return np.full(disp.shape, np.inf, np.float32)
    if valid.all():
        return disp.copy()
    left_val, right_val = ref_nearest_along_rows(disp, valid)
    fill_value = np.minimum(left_val, right_val)
    if occluded is not None:
        up_val, down_val = (x.T for x in ref_nearest_along_rows(disp.T, valid.T))
        four = np.stack([left_val, right_val, up_val, down_val])
        four = np.where(np.isfinite(four), four, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            inside = np.nanmedian(four, axis=0)
        use_inside = ~occluded & np.isfinite(inside)
        fill_value = np.where(use_inside, inside, fill_value)
    filled = np.where(valid, disp, fill_value).astype(np.float32)
    empty_rows = ~valid.any(axis=1)
    if empty_rows.any():
        good = np.flatnonzero(~empty_rows)
        for r in np.flatnonzero(empty_rows):
            filled[r] = filled[good[np.argmin(np.abs(good - r))]]
    if smooth and min(disp.shape) >= 5:
        median = cv2.medianBlur(filled, 5)
        filled = np.where(valid, filled, median).astype(np.float32)
    return filled


def ref_smooth_disparity(disparity, valid, *, radius, sigma, plane=None):
    disp = np.asarray(disparity, dtype=np.float32)
    finite = np.isfinite(disp)
    use = np.asarray(valid, dtype=bool) & finite
    if radius <= 0 or not use.any():
        return disp.copy()
    base = np.zeros(disp.shape, np.float32) if plane is None else np.asarray(plane, dtype=np.float32)
    resid = np.where(finite, disp - base, 0.0).astype(np.float32)
    lo, hi = float(resid[finite].min()), float(resid[finite].max())
    step = max(float(sigma), (hi - lo) / (256 - 1))
    n_levels = int(np.floor((hi - lo) / step)) + 2
    pos = (resid - lo) / step
    k0 = np.clip(np.floor(pos), 0, n_levels - 2).astype(np.int32)
    t = (pos - k0).astype(np.float32)
    weight0 = use.astype(np.float32)
    ksize = (2 * int(radius) + 1, 2 * int(radius) + 1)
    acc = np.zeros(disp.shape, np.float32)
    inv2s2 = 0.5 / float(sigma) ** 2
    for k in range(n_levels):
        lower, upper = k0 == k, k0 + 1 == k
        if not (lower.any() or upper.any()):
            continue
        level = lo + k * step
        w = weight0 * np.exp(-inv2s2 * (resid - level) ** 2).astype(np.float32)
        num = cv2.boxFilter(w * resid, -1, ksize, normalize=False, borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(w, -1, ksize, normalize=False, borderType=cv2.BORDER_CONSTANT)
        est = np.where(den > 1e-6, num / np.maximum(den, 1e-6), resid)
        acc += np.where(lower, 1.0 - t, 0.0) * est + np.where(upper, t, 0.0) * est
    return np.where(finite, acc + base, disp).astype(np.float32)


def ref_drop_occluded(disparity, valid, *, max_disparity):
    """What ``D3Stereo._finish`` did before the fused pass."""
    occluded = ref_occluded_by_uniqueness(disparity, valid) | ref_out_of_view(disparity, valid,
                                                                              max_disparity=max_disparity)
    valid = valid & ~occluded
    return occluded, valid, np.where(valid, disparity, np.inf).astype(np.float32), float(occluded.mean())


def ref_drop_speckles(disparity, valid, *, max_size, max_diff):
    """``speckles`` and the masking of ``D3Stereo._finish`` before the fused passes."""
    use = valid & np.isfinite(disparity)
    if max_size <= 0 or not use.any():
        speck = np.zeros(disparity.shape, bool)
    else:
        with np.errstate(over="ignore", invalid="ignore"):
            fixed = np.where(use, np.clip(np.round(disparity * 16.0), 0, 32767), -1).astype(np.int16)
        cv2.filterSpeckles(fixed, -1, int(max_size), max(1, int(round(float(max_diff) * 16.0))))
        speck = use & (fixed == -1)
    valid = valid & ~speck
    return valid, np.where(valid, disparity, np.inf).astype(np.float32), float(speck.mean())


def ref_right_image(disparity):
    """The road model's right-image rule over a map, as NumPy writes it: ``u - d >= -0.5``
    (columns in float32: float32 arithmetic on a float32 map)."""
    cols = np.arange(disparity.shape[1], dtype=np.float32)[None, :]
    with np.errstate(invalid="ignore"):
        return cols - disparity >= -0.5


def ref_shift_plane(a0, b1, b2, margin, shape):
    """The road model's shift ``s(u, v) = a0 + b1 v + b2 u - margin`` as NumPy writes it,
    float64 (H, W)."""
    h, w = shape
    return a0 + b1 * np.arange(h, dtype=np.float64)[:, None] + b2 * np.arange(w)[None, :] - margin


def ref_restored_validity(valid, narrow, restored, *, narrow_range):
    """``restored_validity`` before its kernel, and the pipeline's masking."""
    with np.errstate(invalid="ignore"):
        ends = valid & ((narrow <= 0) | (narrow >= narrow_range))
        negative = valid & ~(restored >= 0)
    outside = valid & ~ref_right_image(restored)
    shares = {"range_end_share": float(ends.mean()), "outside_share": float(outside.mean()),
              "negative_share": float((negative & ~ends & ~outside).mean())}
    kept = valid & ~ends & ~outside & ~negative
    return kept, shares, np.where(kept, restored, np.inf).astype(np.float32)


def ref_box_smoothing_glue(disparity, valid, plane, smooth):
    """The box kernel's residual and sum back as NumPy did them (``smooth`` the kernel)."""
    base = np.zeros(disparity.shape, np.float32) if plane is None else np.asarray(plane, np.float32)
    finite = np.isfinite(disparity)
    resid = np.where(finite, disparity - base, np.float32(np.inf)).astype(np.float32)
    smoothed = smooth(resid, valid & finite)
    return np.where(finite, smoothed + base, disparity).astype(np.float32)


def assert_same_bytes(got, want, msg=""):
    """Equal dtype, shape and bytes (-0.0 differs from 0.0, NaN payloads count)."""
    assert got.dtype == want.dtype and got.shape == want.shape, msg
    if got.tobytes() != want.tobytes():
        diff = np.flatnonzero(got.ravel().view(np.uint8) != want.ravel().view(np.uint8))
        worst = np.nanmax(np.abs(got.astype(np.float64) - want)) if got.dtype.kind == "f" else "n/a"
        pytest.fail(f"{msg}: {diff.size} bytes differ, first at byte {diff[0]}; max abs difference {worst}")


SHAPES = [(1, 1), (1, 5), (5, 1), (2, 3), (3, 4), (4, 2), (5, 5), (7, 13), (23, 31), (40, 64)]


def random_map(rng, shape, *, valid_share=0.7, spread=20.0, integers=False):
    """Disparities in [0, spread), with a share of invalid pixels, all-invalid rows and
    inf/NaN estimates among the invalid ones."""
    h, w = shape
    disp = (rng.random(shape) * spread).astype(np.float32)
    if integers:
        disp = (np.round(disp * 2) / 2).astype(np.float32)  # half-integers: rounding ties
    valid = rng.random(shape) < valid_share
    if h > 2:
        valid[rng.integers(h)] = False  # a row with nothing valid
    holes = ~valid
    disp[holes & (rng.random(shape) < 0.5)] = np.inf
    disp[holes & (rng.random(shape) < 0.1)] = np.nan
    return disp, valid


def numpy_exp_is_simd():
    """NumPy's float32 exp is its AVX2+FMA3 / AVX512F kernel (what numpy_expf reproduces)."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # NumPy 1.x
        from numpy.core import _multiarray_umath as umath
    features = getattr(umath, "__cpu_features__", {})
    return bool(features.get("AVX512F") or (features.get("AVX2") and features.get("FMA3")))


def assert_same_smoothing(got, want, what=""):
    """The smoothing's bytes equal the NumPy reference's where NumPy's float32 exp is its
    SIMD kernel (x86 with AVX2+FMA3 or AVX512F: what numpy_expf reproduces); elsewhere
    (aarch64, old x86) np.exp is the C library's and may differ in the last bit."""
    if numpy_exp_is_simd():
        assert_same_bytes(got, want, what)
    else:
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6, err_msg=what)


def ref_speckles(disp, valid, max_size, max_diff):
    """Regions of 4-connected valid pixels whose neighbours differ by <= max_diff; True on
    the pixels of regions of at most max_size pixels (plain breadth-first search)."""
    h, w = disp.shape
    label = np.full((h, w), -1, np.int64)
    out = np.zeros((h, w), bool)
    for v0 in range(h):
        for u0 in range(w):
            if not valid[v0, u0] or label[v0, u0] >= 0:
                continue
            label[v0, u0] = 1
            members = [(v0, u0)]
            queue = deque(members)
            while queue:
                v, u = queue.popleft()
                for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0)):
                    y, x = v + dv, u + du
                    if 0 <= y < h and 0 <= x < w and valid[y, x] and label[y, x] < 0 \
                            and abs(float(disp[y, x]) - float(disp[v, u])) <= max_diff:
                        label[y, x] = 1
                        members.append((y, x))
                        queue.append((y, x))
            if len(members) <= max_size:
                for v, u in members:
                    out[v, u] = True
    return out


def ref_range_box_float32(resid, use, radius, threshold):
    """The kernel's own arithmetic in NumPy: every pixel adds its float32 terms row after
    row, offset after offset (left to right), from +0 (adding +0 for an offset outside the
    map changes no sum: none is -0)."""
    h, w = resid.shape
    masked = np.full((h + 2 * radius, w + 2 * radius), np.nan, np.float32)
    masked[radius:radius + h, radius:radius + w] = np.where(use, resid, np.float32(np.nan))
    total = np.zeros((h, w), np.float32)
    count = np.zeros((h, w), np.float32)
    thr = np.float32(threshold)
    with np.errstate(invalid="ignore"):
        for dy in range(2 * radius + 1):
            for dx in range(2 * radius + 1):
                q = masked[dy:dy + h, dx:dx + w]
                inside = np.abs(q - resid) <= thr
                total += np.where(inside, q, np.float32(0))
                count += inside.astype(np.float32)
        return np.where(~np.isfinite(resid) | (count == 0), resid, total / count).astype(np.float32)
