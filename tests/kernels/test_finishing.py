"""The numba kernels of step 8 (``d3cli.kernels.finishing``, called by
``d3cli.method.refinement``) against the NumPy/OpenCV formulation they replaced.

The references below are that formulation, kept verbatim: ``np.maximum.at`` for the
uniqueness test, cumulative maxima for the row-wise filling, ``np.nanmedian`` over four
directions, and the piecewise-linear bilateral filter with one pair of
``cv2.boxFilter`` calls per range level.  The kernels must give the same bytes (not just
close values) on random inputs and on the edge cases: rows with nothing valid, nothing or
everything valid, inf and NaN estimates, half-integer matches (ties of the rounding),
widths and heights 1..5, box radii 1 and 2 (OpenCV sums 3 and 5 taps directly) and
larger, more than 256 range levels (wider level spacing, several level groups).
"""

from __future__ import annotations

import warnings

import cv2
import numba
import numpy as np
import pytest

from d3cli.kernels import finishing, range_box
from d3cli.method.perspective import (RoadModel, match_in_right_image, restored_shares, restored_validity,
                                      restored_validity_counts, shift_map)
from d3cli.method.refinement import (drop_occluded, drop_speckles, fill_holes, occluded_by_uniqueness, out_of_view,
                                     smooth_disparity)


# ----------------------------------------------------------------------------- references
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
    """What ``D3Stereo._finish`` did before the fused pass (issue 10)."""
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


def ref_restored_validity(valid, narrow, restored, *, narrow_range):
    """``restored_validity`` before its kernel (issue 10), and the pipeline's masking."""
    with np.errstate(invalid="ignore"):
        ends = valid & ((narrow <= 0) | (narrow >= narrow_range))
        negative = valid & ~(restored >= 0)
    outside = valid & ~match_in_right_image(restored)
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


# ----------------------------------------------------------------------------- occlusion tests
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("integers", [False, True])
def test_uniqueness_matches_reference(shape, integers):
    rng = np.random.default_rng(hash((shape, integers)) % 2**32)
    for share in (0.0, 0.5, 0.9, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=min(shape[1], 8), integers=integers)
        for tolerance in (0.0, 0.5, 1.0):
            got = occluded_by_uniqueness(disp, valid, tolerance=tolerance)
            want = ref_occluded_by_uniqueness(disp, valid, tolerance=tolerance)
            np.testing.assert_array_equal(got, want, err_msg=f"{shape} {share} {tolerance}")


def test_uniqueness_with_inf_and_nan_marked_valid_matches_reference():
    """Non-finite estimates flagged valid: NumPy casts their target to int64 min, which
    clips to column 0; a NaN wins the maximum there (np.maximum propagates it)."""
    rng = np.random.default_rng(3)
    disp, _ = random_map(rng, (9, 17), spread=6)
    valid = np.ones(disp.shape, bool)
    disp[2, 5] = np.inf
    disp[3, 0] = -np.inf
    disp[4, 7] = np.nan
    disp[5, 2] = 1e30
    disp[5, 3] = -1e30
    got = occluded_by_uniqueness(disp, valid)
    np.testing.assert_array_equal(got, ref_occluded_by_uniqueness(disp, valid))


@pytest.mark.parametrize("shape", SHAPES)
def test_out_of_view_matches_reference(shape):
    rng = np.random.default_rng(hash(shape) % 2**32)
    for share in (0.0, 0.3, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=shape[1] + 2)
        for max_disparity in range(0, shape[1] + 3):
            got = out_of_view(disp, valid, max_disparity=max_disparity)
            want = ref_out_of_view(disp, valid, max_disparity=max_disparity)
            np.testing.assert_array_equal(got, want, err_msg=f"{shape} {share} {max_disparity}")


def test_fixed_point_16_matches_the_numpy_formulation():
    """The speckle filter's 1/16 px fixed point: ties of the rounding (half to even), both
    ends of the int16 range, negative and huge estimates, holes."""
    rng = np.random.default_rng(8)
    disp = np.concatenate([rng.random(50_000) * 2100, np.arange(-64, 64) / 32.0, np.arange(0, 2100, 1 / 32),
                           [2047.96875, 2047.97, 2048.0, 1e30, 3e38, -5.0, -0.0, 1e-40]]).astype(np.float32)
    valid = rng.random(disp.size) < 0.9
    with np.errstate(over="ignore"):
        want = np.where(valid, np.clip(np.round(disp * 16.0), 0, 32767), -1).astype(np.int16)
    got = finishing.fixed_point_16(disp.reshape(1, -1), valid.reshape(1, -1))
    np.testing.assert_array_equal(got.ravel(), want)


# ----------------------------------------------------------------------------- hole filling
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("inside", [False, True])
def test_fill_holes_matches_reference(shape, smooth, inside):
    rng = np.random.default_rng(hash((shape, smooth, inside)) % 2**32)
    for share in (0.0, 0.05, 0.5, 0.95, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share)
        occluded = (rng.random(shape) < 0.4) & ~valid if inside else None
        got = fill_holes(disp, valid, smooth=smooth, occluded=occluded)
        want = ref_fill_holes(disp, valid, smooth=smooth, occluded=occluded)
        assert_same_bytes(got, want, f"{shape} {share} smooth={smooth} inside={inside}")


def test_fill_rows_runs_ties_and_signed_zeros_match_reference():
    """Runs of holes at both row ends, single holes, and ties of -0 and +0 between the two
    sides (np.minimum's choice), filled by whole runs."""
    rng = np.random.default_rng(8)
    disp = rng.choice(np.array([-0.0, 0.0, 1.0, 2.0], np.float32), size=(40, 23))
    valid = rng.random(disp.shape) < 0.45
    valid[:, :3] = False  # a run at the left end
    valid[::2, -4:] = False  # and at the right end
    valid[5] = False  # a row without a valid pixel
    disp[~valid & (rng.random(disp.shape) < 0.5)] = np.inf
    got = fill_holes(disp, valid, smooth=False)
    assert_same_bytes(got, ref_fill_holes(disp, valid, smooth=False), "ties")


def test_fill_inside_on_ties_and_signed_zeros_equals_the_insertion_sort():
    """The branch-free sorting network of ``fill_inside`` against the formulation it
    replaced (an insertion sort of the finite values in the order left, right, up, down;
    the row neighbours from the reference's scans): many equal values and both signed
    zeros, so that the order of equals and which neighbour a value came from show in the
    bits."""
    rng = np.random.default_rng(4)
    shape = (40, 50)
    choices = np.array([-0.0, 0.0, 1.0, 2.0, 2.5], np.float32)
    up_down = np.array([-0.0, 0.0, 1.0, 2.0, np.inf], np.float32)
    for share in (0.0, 0.2, 0.7, 1.0):
        disp = choices[rng.integers(0, 5, shape)]
        valid = rng.random(shape) < share
        occluded = (rng.random(shape) < 0.2) & ~valid
        left, right = (x.astype(np.float32) for x in ref_nearest_along_rows(disp, valid))
        up, down = (up_down[rng.integers(0, 5, shape)] for _ in range(2))
        want = np.empty(shape, np.float32)
        for y in range(shape[0]):
            for u in range(shape[1]):
                if valid[y, u]:
                    want[y, u] = disp[y, u]
                    continue
                side = left[y, u] if left[y, u] < right[y, u] else right[y, u]
                buf = []
                for v in (left[y, u], right[y, u], up[y, u], down[y, u]):
                    if np.isfinite(v):
                        i = len(buf)
                        while i > 0 and buf[i - 1] > v:
                            i -= 1
                        buf.insert(i, v)
                n = len(buf)
                if occluded[y, u] or n == 0:
                    want[y, u] = side
                elif n % 2:
                    want[y, u] = buf[n // 2]
                else:
                    want[y, u] = (buf[n // 2 - 1] + buf[n // 2]) / np.float32(2.0)
        assert_same_bytes(finishing.fill_inside(disp, valid, occluded, up, down), want, f"fill_inside {share}")


@pytest.mark.parametrize("shape", SHAPES)
def test_nearest_along_columns_equals_reference(shape):
    """The up/down neighbours of ``fill_inside`` against the reference's row scan of the
    transposed map (ties and both signed zeros)."""
    rng = np.random.default_rng(hash(shape) % 2**32)
    choices = np.array([-0.0, 0.0, 1.0, 2.0, 2.5], np.float32)
    for share in (0.0, 0.2, 0.7, 1.0):
        disp = choices[rng.integers(0, 5, shape)]
        valid = rng.random(shape) < share
        up, down = (x.T for x in ref_nearest_along_rows(disp.T, valid.T))
        up_k, down_k = finishing.nearest_along_columns(disp, valid)
        assert_same_bytes(up_k, np.ascontiguousarray(up, np.float32), f"up {shape} {share}")
        assert_same_bytes(down_k, np.ascontiguousarray(down, np.float32), f"down {shape} {share}")


def test_fill_holes_empty_rows_copy_the_nearest_row_upper_on_a_tie():
    disp = np.full((7, 4), np.inf, np.float32)
    valid = np.zeros((7, 4), bool)
    disp[1] = 1.0
    disp[5] = 5.0
    valid[[1, 5]] = True
    got = fill_holes(disp, valid, smooth=False)
    np.testing.assert_array_equal(got[:, 0], [1, 1, 1, 1, 5, 5, 5])  # row 3: tie, upper row 1
    assert_same_bytes(got, ref_fill_holes(disp, valid, smooth=False))


def _numpy_exp_is_simd():
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
    if _numpy_exp_is_simd():
        assert_same_bytes(got, want, what)
    else:
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6, err_msg=what)


# ----------------------------------------------------------------------------- smoothing
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("radius", [1, 2, 3, 7])
def test_smooth_disparity_matches_reference(shape, radius):
    rng = np.random.default_rng(hash((shape, radius)) % 2**32)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w]
    plane = (3.0 + 0.3 * xx + 0.2 * yy).astype(np.float32)
    for share, sigma, with_plane in ((1.0, 1.5, True), (0.8, 0.5, False), (0.5, 2.0, True), (0.0, 1.0, False)):
        disp = (plane + rng.normal(0, 1.5, shape) + 6 * (xx > w // 2)).astype(np.float32)
        valid = rng.random(shape) < share
        disp[rng.random(shape) < 0.1] = np.inf  # no estimate: stays, never averaged
        kw = dict(radius=radius, sigma=sigma, plane=plane if with_plane else None)
        got = smooth_disparity(disp, valid, **kw)
        want = ref_smooth_disparity(disp, valid, **kw)
        assert_same_smoothing(got, want, f"{shape} radius={radius} share={share} sigma={sigma}")


@pytest.mark.parametrize("radius", [2, 15])
def test_smooth_disparity_many_levels_matches_reference(radius):
    """A range of 1000 px at sigma 1: 257 levels spaced wider than sigma, filtered in
    several groups; a few pixels far below the rest (denormal and zero weights)."""
    rng = np.random.default_rng(radius)
    disp = (rng.random((37, 53)) * 1000).astype(np.float32)
    disp[5, 5] = -3000.0
    disp[6, 6] = 1e-30
    valid = rng.random(disp.shape) < 0.9
    got = smooth_disparity(disp, valid, radius=radius, sigma=1.0)
    assert_same_smoothing(got, ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0))


def test_smooth_disparity_on_a_road_like_map_matches_reference():
    """A 96x160 slanted road with noise and a pothole, radius 15, sigma 1.5 (configs/road.yaml)."""
    rng = np.random.default_rng(11)
    yy, xx = np.mgrid[0:96, 0:160]
    plane = (20.0 + 0.4 * yy - 0.05 * xx).astype(np.float32)
    disp = (plane + rng.normal(0, 0.6, plane.shape)).astype(np.float32)
    disp[40:60, 70:100] -= 3.0
    valid = np.isfinite(disp)
    got = smooth_disparity(disp, valid, radius=15, sigma=1.5, plane=plane)
    assert_same_smoothing(got, ref_smooth_disparity(disp, valid, radius=15, sigma=1.5, plane=plane))


def test_range_levels_flags_rows_and_zeroes_the_shares_of_nan_residuals():
    """The levels of the reference's clip(floor(pos)) per row; a NaN residual has none
    (INT32_MIN) and its shares, which no level writes, are set to 0; others untouched."""
    rng = np.random.default_rng(3)
    resid = (rng.random((9, 14)) * 6).astype(np.float32)
    resid[4, 5] = np.nan
    low = np.full(resid.shape, 7.0, np.float32)
    up = low.copy()
    used, row_lower = finishing.range_levels(resid, np.float32(0.5), np.float32(1.5), 5, low, up)
    with np.errstate(invalid="ignore"):
        k0 = np.clip(np.floor((resid - np.float32(0.5)) / np.float32(1.5)), 0, 3).astype(np.int32)
    want = np.zeros((9, 5), bool)
    for y, u in zip(*np.nonzero(~np.isnan(resid))):
        want[y, k0[y, u]] = True
    np.testing.assert_array_equal(row_lower, want)
    np.testing.assert_array_equal(used, want.any(axis=0) | np.r_[False, want.any(axis=0)[:-1]])
    assert low[4, 5] == 0 and up[4, 5] == 0
    assert (np.delete(low.ravel(), 4 * 14 + 5) == 7).all() and (np.delete(up.ravel(), 4 * 14 + 5) == 7).all()


@pytest.mark.skipif(not _numpy_exp_is_simd(), reason="NumPy's float32 exp is the C library's here")
def test_numpy_expf_equals_np_exp_bit_for_bit():
    """All float32 values were checked once (2^32, equal, NaN payloads included); here
    every 4099th bit pattern, the arguments of the smoothing (-100..0), the ends of the
    range (overflow, subnormal and zero results) and the special values."""
    rng = np.random.default_rng(0)
    sweep = np.arange(0, 2**32, 4099, dtype=np.uint64).astype(np.uint32).view(np.float32)
    weights = -(rng.random(500_000) ** 2 * 100).astype(np.float32)
    ends = []
    for edge in (-103.97208404541015625, -87.33654, -0.0, 88.72283935546875):
        centre = np.array([edge], np.float32).view(np.uint32)[0].astype(np.int64)
        ends.append((centre + np.arange(-3000, 3001)).astype(np.uint32).view(np.float32))
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 1e-45, -1e-45, 3.4e38, -3.4e38], np.float32)
    payloads = np.array([0x7FC00001, 0xFFC12345, 0x7F800001], np.uint32).view(np.float32)
    x = np.concatenate([sweep, weights, *ends, special, payloads])
    with np.errstate(all="ignore"):
        want = np.exp(x)
    got = finishing.numpy_exp(x)
    assert_same_bytes(got, want, "numpy_expf")


@pytest.mark.parametrize("max_group", [1, 2, 3, 5])
@pytest.mark.parametrize("radius", [1, 2, 6])
def test_smooth_groups_of_any_size_match_the_reference(max_group, radius):
    """Levels grouped one, two (one pair of running sums), three (a pair and a single) or
    five to a task give the reference's bytes; so does every thread count (below)."""
    rng = np.random.default_rng(100 * max_group + radius)
    yy, xx = np.mgrid[0:41, 0:67]
    plane = (5.0 + 0.2 * yy + 0.03 * xx).astype(np.float32)
    disp = (plane + rng.normal(0, 2.0, plane.shape) + 5 * (xx > 30)).astype(np.float32)
    valid = rng.random(disp.shape) < 0.85
    disp[rng.random(disp.shape) < 0.05] = np.inf
    want = ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0, plane=plane)
    base = plane
    grid = _unit_levels(disp, base, valid)
    assert len(grid["levels"]) >= 6
    low, up = grid["low"], grid["up"]
    finishing.smooth_groups(*grid["args"], np.float32(-0.5), radius, low, up, max_group=max_group)
    assert_same_smoothing(finishing.combine_shares(low, up, base, disp), want, f"group {max_group}")


def _unit_levels(disp, base, valid):
    """The steps before :func:`finishing.smooth_groups` with range levels 1.0 apart: the
    residuals, the used levels, the share maps (zeroed where no level writes) and the
    arguments of smooth_groups up to ``neg_inv2s2``."""
    resid, use, row_lo, row_hi, _ = finishing.residual_and_range(disp, base, valid)
    lo, hi = float(row_lo.min()), float(row_hi.max())
    n_levels = int(np.floor(hi - lo)) + 2
    low, up = np.empty(disp.shape, np.float32), np.empty(disp.shape, np.float32)
    used, row_lower = finishing.range_levels(resid, np.float32(lo), np.float32(1.0), n_levels, low, up)
    levels = np.flatnonzero(used)
    values = np.array([lo + int(k) * 1.0 for k in levels], np.float64).astype(np.float32)
    args = (resid, use, np.float32(lo), np.float32(1.0), n_levels, levels, values, row_lower)
    return {"levels": levels, "row_lower": row_lower, "low": low, "up": up, "args": args}


@pytest.mark.parametrize("max_group", [1, 2, 4])
@pytest.mark.parametrize("radius", [2, 7, 15])
def test_smooth_groups_stop_each_level_after_its_last_row(max_group, radius):
    """A ramp down the rows: each level is used by a band of rows only, so the levels stop
    at different rows (the running sums of the rows above still count) and rows outside
    a level's band store no share; the tasks' groups split the rows unevenly.  The
    reference's bytes with one thread and with all."""
    rng = np.random.default_rng(radius)
    yy, xx = np.mgrid[0:80, 0:45]
    disp = (2.0 + 0.15 * yy + rng.normal(0, 0.4, yy.shape)).astype(np.float32)
    disp[30:38, 10:20] += 6.0  # a bump: levels used by a few rows in the middle only
    disp[rng.random(disp.shape) < 0.05] = np.inf
    valid = rng.random(disp.shape) < 0.9
    want = ref_smooth_disparity(disp, valid, radius=radius, sigma=1.0)
    base = np.zeros(disp.shape, np.float32)
    grid = _unit_levels(disp, base, valid)
    levels, row_lower, low, up = grid["levels"], grid["row_lower"], grid["low"], grid["up"]
    last = [np.flatnonzero(row_lower[:, k] | (row_lower[:, k - 1] if k else False)).max() for k in levels]
    assert len(levels) >= 6 and min(last) < 40
    before = numba.get_num_threads()
    try:
        for n in sorted({1, before}):
            numba.set_num_threads(n)
            shares = low.copy(), up.copy()  # each run fills copies of the same maps
            finishing.smooth_groups(*grid["args"], np.float32(-0.5), radius, *shares, max_group=max_group)
            got = finishing.combine_shares(*shares, base, disp)
            assert_same_smoothing(got, want, f"group {max_group}, {n} threads")
    finally:
        numba.set_num_threads(before)


# ----------------------------------------------------------------------------- fused passes of the pipeline
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("in_place", [False, True])
def test_drop_occluded_matches_the_two_tests_and_the_masking(shape, in_place):
    rng = np.random.default_rng(hash((shape, in_place, 1)) % 2**32)
    # (rows with more than 1/8 holes take the kernel's select loop, the others its branches)
    for share in (0.0, 0.5, 0.9, 1.0):
        for integers in (False, True):
            disp, valid = random_map(rng, shape, valid_share=share, spread=min(shape[1], 8), integers=integers)
            for max_disparity in (0, 1, shape[1] // 2, shape[1] + 2):
                occ, want_valid, want_out, share_want = ref_drop_occluded(disp, valid, max_disparity=max_disparity)
                got_valid = valid.copy()
                src = disp.copy()
                got_occ, count, got_out = drop_occluded(src, got_valid, max_disparity=max_disparity,
                                                        out=src if in_place else None)
                msg = f"{shape} {share} {max_disparity}"
                np.testing.assert_array_equal(got_occ, occ, err_msg=msg)
                np.testing.assert_array_equal(got_valid, want_valid, err_msg=msg)
                assert_same_bytes(got_out, want_out, msg)
                assert count / disp.size == share_want and (got_out is src) == in_place


def test_drop_occluded_with_inf_and_nan_marked_valid_matches_reference():
    rng = np.random.default_rng(4)
    disp, _ = random_map(rng, (9, 17), spread=6)
    valid = np.ones(disp.shape, bool)
    disp[2, 5], disp[3, 0], disp[4, 7], disp[5, 2], disp[5, 3] = np.inf, -np.inf, np.nan, 1e30, -1e30
    occ, want_valid, want_out, _ = ref_drop_occluded(disp, valid, max_disparity=4)
    got_occ, _, got_out = drop_occluded(disp, valid, max_disparity=4)
    np.testing.assert_array_equal(got_occ, occ)
    np.testing.assert_array_equal(valid, want_valid)
    assert_same_bytes(got_out, want_out)


@pytest.mark.parametrize("shape", [(1, 1), (5, 5), (23, 31), (40, 64)])
@pytest.mark.parametrize("max_size", [0, 1, 4, 30])
def test_drop_speckles_matches_the_speckle_filter_and_the_masking(shape, max_size):
    rng = np.random.default_rng(hash((shape, max_size)) % 2**32)
    for share in (0.0, 0.6, 1.0):
        disp, valid = random_map(rng, shape, valid_share=share, spread=6)
        disp = np.where(rng.random(shape) < 0.5, np.round(disp), disp).astype(np.float32)  # plateaus
        valid |= ~np.isfinite(disp) & (rng.random(shape) < 0.3)  # valid but inf/NaN: never a speckle
        for max_diff, in_place in ((0.5, True), (2.0, True), (2.0, False)):
            want_valid, want_out, share_want = ref_drop_speckles(disp, valid, max_size=max_size, max_diff=max_diff)
            got_valid = valid.copy()
            src = disp.copy()
            count, got_out = drop_speckles(src, got_valid, max_size=max_size, max_diff=max_diff,
                                           out=src if in_place else None)
            np.testing.assert_array_equal(got_valid, want_valid)
            assert_same_bytes(got_out, want_out, f"{shape} {share} {max_diff}")
            assert count / disp.size == share_want and (got_out is src) == in_place
            assert_same_bytes(src, disp if not in_place else want_out, "the input map")


@pytest.mark.parametrize("narrow_dtype", [np.int32, np.float32, np.float64])
@pytest.mark.parametrize("narrow_range", [18, 18.0, 17.3, np.float64(17.3)])
def test_restored_validity_kernel_matches_the_numpy_formulation(narrow_dtype, narrow_range):
    rng = np.random.default_rng(11)
    h, w = 37, 53
    narrow = (rng.random((h, w)) * 21 - 1).astype(np.float32)
    narrow[rng.random((h, w)) < 0.3] = 17.3
    narrow = narrow.astype(narrow_dtype)
    restored = (rng.random((h, w)) * 70 - 10).astype(np.float32)
    cols = np.arange(w, dtype=np.float32)
    restored[:, 5] = cols[5] + 0.5  # exactly half a pixel left of the image: kept
    restored[:, 6] = np.nextafter(cols[6] + np.float32(0.5), np.float32(np.inf))
    restored[1, :] = np.inf
    restored[2, :] = -np.inf
    restored[3, :] = np.nan
    restored[4, :] = -0.0
    valid = rng.random((h, w)) < 0.8
    want_valid, want_shares, want_masked = ref_restored_validity(valid, narrow, restored, narrow_range=narrow_range)
    got_valid, got_shares = restored_validity(valid, narrow, restored, narrow_range=narrow_range)
    np.testing.assert_array_equal(got_valid, want_valid)
    assert got_shares == want_shares and all(type(v) is float for v in got_shares.values())
    kept, counts, masked = restored_validity_counts(valid, narrow, restored, narrow_range=narrow_range, masked=True)
    np.testing.assert_array_equal(kept, want_valid)
    assert restored_shares(counts, kept.size) == want_shares
    assert_same_bytes(masked, want_masked)
    # other dtypes of the restored map keep the NumPy formulation
    restored64 = restored.astype(np.float64)
    got64, shares64 = restored_validity(valid, narrow, restored64, narrow_range=narrow_range)
    want64, want_shares64, _ = ref_restored_validity(valid, narrow, restored64, narrow_range=narrow_range)
    np.testing.assert_array_equal(got64, want64)
    assert shares64 == want_shares64


@pytest.mark.parametrize("shape", [(1, 1), (5, 7), (40, 64)])
@pytest.mark.parametrize("with_plane", [False, True])
def test_box_smoothing_glue_matches_the_numpy_formulation(shape, with_plane):
    rng = np.random.default_rng(hash((shape, with_plane)) % 2**32)
    disp, valid = random_map(rng, shape, spread=10)
    disp[rng.random(shape) < 0.1] = -0.0  # -0 + 0 is +0: the sum back keeps the NumPy order
    disp[rng.random(shape) < 0.05] = -np.inf
    plane = (rng.random(shape) * 4 - 2).astype(np.float32) if with_plane else None
    for radius in (1, 3):
        want = ref_box_smoothing_glue(disp, valid, plane,
                                      lambda r, u: range_box.box_range_smooth(r, u, radius, 1.5))
        got = smooth_disparity(disp, valid, radius=radius, sigma=1.5, plane=plane, kernel="box")
        assert_same_bytes(got, want, f"{shape} {radius}")


@pytest.mark.parametrize("kernel", ["gaussian", "box"])
def test_smoothing_without_a_validity_map_uses_every_finite_pixel(kernel):
    rng = np.random.default_rng(12)
    disp, _ = random_map(rng, (31, 45), spread=10)
    plane = (rng.random(disp.shape) * 4 - 2).astype(np.float32)
    for p in (None, plane):
        want = smooth_disparity(disp, np.isfinite(disp), radius=3, sigma=1.5, plane=p, kernel=kernel)
        assert_same_bytes(smooth_disparity(disp, None, radius=3, sigma=1.5, plane=p, kernel=kernel), want, kernel)


@pytest.mark.parametrize("kernel", ["gaussian", "box"])
def test_smoothing_non_negative_is_the_clamp_after_it(kernel):
    """``non_negative`` clamps in the smoothing's last pass: the bytes of clamp_negative
    after it (a plane below zero, -0, -inf, NaN and holes included)."""
    rng = np.random.default_rng(21)
    disp, valid = random_map(rng, (33, 47), spread=3)
    plane = (rng.random(disp.shape) * 4 - 3).astype(np.float32)
    disp = (disp - 2.5).astype(np.float32)
    disp[rng.random(disp.shape) < 0.05] = -0.0
    disp[rng.random(disp.shape) < 0.03] = -np.inf
    disp[rng.random(disp.shape) < 0.03] = np.nan
    for p in (None, plane):
        plain = smooth_disparity(disp, valid, radius=3, sigma=1.5, plane=p, kernel=kernel)
        assert (plain < 0).any()
        got = smooth_disparity(disp, valid, radius=3, sigma=1.5, plane=p, kernel=kernel, non_negative=True)
        assert_same_bytes(got, finishing.clamp_negative(plain.copy()), kernel)
    got = smooth_disparity(disp, valid, radius=0, sigma=1.5, kernel=kernel, non_negative=True)
    assert_same_bytes(got, finishing.clamp_negative(disp.copy()), "radius 0")


def test_shift_plane_and_clamp_match_the_numpy_formulation():
    for a0, b1, b2 in ((3.25, 0.0137, -0.00211), (-40.1, 0.1, 0.3), (0.0, 1e-7, -1e-9)):
        model = RoadModel(a0=a0, b1=b1, b2=b2, a1=0.0, theta=0.0, inlier_share=1.0, n_points=0)
        for margin in (0.0, 8.0):
            want = shift_map(model, (31, 47), margin=margin).astype(np.float32)
            assert_same_bytes(finishing.shift_plane_f32(a0, b1, b2, margin, (31, 47)), want)
    a = np.array([[-1.0, -0.0, 0.0, np.nan, -np.inf, np.inf, 2.5, -1e-30]], np.float32)
    with np.errstate(invalid="ignore"):
        want = np.where(a < 0, np.float32(0.0), a)
    assert_same_bytes(finishing.clamp_negative(a.copy()), want)


# ----------------------------------------------------------------------------- threads
def test_kernels_give_the_same_bytes_with_one_thread_and_with_all():
    rng = np.random.default_rng(5)
    disp, valid = random_map(rng, (61, 77), spread=30)
    occluded = (rng.random(disp.shape) < 0.3) & ~valid
    yy, xx = np.mgrid[0:61, 0:77]
    plane = (2.0 + 0.1 * yy).astype(np.float32)

    def run():
        return [
            occluded_by_uniqueness(disp, valid),
            out_of_view(disp, valid, max_disparity=20),
            *drop_occluded(disp, valid.copy(), max_disparity=20)[::2],
            drop_speckles(disp, valid.copy(), max_size=20, max_diff=1.0)[1],
            fill_holes(disp, valid, smooth=True),
            fill_holes(disp, valid, smooth=True, occluded=occluded),
            smooth_disparity(fill_holes(disp, valid), valid, radius=5, sigma=1.5, plane=plane),
            smooth_disparity(fill_holes(disp, valid), valid, radius=3, sigma=1.5, plane=plane, kernel="box"),
        ]

    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = run()
    finally:
        numba.set_num_threads(threads)
    for a, b in zip(single, run()):
        assert_same_bytes(a, b)


def test_finishing_kernels_are_cached_and_release_the_gil():
    """Compiled once and cached on disk (a read-only install uses the user cache folder
    that importing d3cli.kernels.cpu chose); nogil, so that the pool threads run them
    side by side."""
    assert len(finishing.KERNELS) >= 10
    for kernel in finishing.KERNELS + range_box.KERNELS:
        assert isinstance(kernel, numba.core.registry.CPUDispatcher), kernel
        assert kernel.targetoptions.get("nogil") is True, kernel.py_func.__name__
        assert type(kernel._cache).__name__ == "FunctionCache", kernel.py_func.__name__


def test_run_tasks_runs_every_task_once_and_raises_a_task_error():
    seen = []
    finishing.run_tasks(lambda i, n, out: out.append((i, n)), 7, seen)
    assert sorted(seen) == [(i, 7) for i in range(7)]

    def fail(i, n):
        if i == 3:
            raise ValueError("task 3")

    with pytest.raises(ValueError, match="task 3"):
        finishing.run_tasks(fail, 5)


def test_run_tasks_loads_a_kernel_in_the_calling_thread_before_fanning_out():
    import threading

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two threads")
    numba.set_num_threads(2)
    try:
        calls = []

        def task(i, n, out):
            out.append((i, threading.current_thread() is threading.main_thread()))

        finishing.run_tasks(task, 6, calls)
        assert calls[0] == (0, True)  # the first call: task 0 here, before any pool thread
        assert sorted(i for i, _ in calls) == list(range(6))
        calls.clear()
        finishing.run_tasks(task, 6, calls)  # afterwards the calling thread and the pool share them
        assert sorted(i for i, _ in calls) == list(range(6))
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
