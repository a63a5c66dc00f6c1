"""CUDA driver of the finishing's smoothing (the box and the Gaussian range kernels): the
per-pixel bodies of the CPU (``pixel_smoothing.py``, built with
``numba.cuda.jit(device=True)``), so the values are the CPU's bit for bit where the device
rounds each operation as the host does.  The road plane is computed per pixel from its
coefficients (the road model's ``pt_shift``, :mod:`d3cli.kernels.road_model`), not uploaded.
The result stays on the device.  The contract: :meth:`d3cli.kernels.backend.Backend.smooth_map`.

Rounding on a GPU: the CUDA build takes libdevice's rounded multiplies (``fmul_rn``,
``dmul_rn``) where a product feeds an add (the exponential's rint, the levels' values), so
the compiler cannot fuse them into FMAs, and ``cuda.fma`` where the exponential wants one
rounding; the road plane's float64 ``a0 + b1 v + b2 u`` may be fused (its float32 rounding
hides that but for a tie).  Under the simulator (``NUMBA_ENABLE_CUDASIM=1``) the FMA is an
exactly rounded Python one (:func:`fma_f32_exact`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import config, cuda

from ..cuda_launch import grid_1d, grid_2d, on_device
from ..road_model import build as build_road_model
from .pixel_smoothing import build as build_bodies
from .pixel_smoothing import build_expf

#: The most range levels of the Gaussian smoothing (its host driver's limit plus one: levels
#: ``0 .. floor((hi - lo) / step) + 1`` with ``step >= (hi - lo) / 255``).
MAX_LEVELS = 257
#: Threads per row (row sums) and per column (column sums) of the Gaussian's levels: thread
#: ``lane`` takes the launch's levels ``lane, lane + LEVEL_LANES, ...``.
LEVEL_LANES = 16
#: Device bytes of the row sums of the levels filtered in one pair of launches (float64 ``w r``
#: and ``w`` per level and pixel): a 1280x720 map takes 36 levels a pair.
LEVEL_BYTES = 1 << 29


def fma_f32_exact(a, b, c):
    """``a * b + c`` of three float32 rounded once, in Python: the product is exact in
    float64, the sum's float64 rounding error (TwoSum) turns it into the round-to-odd sum,
    whose rounding to float32 is the exact sum's (53 >= 24 + 2 bits)."""
    p = float(a) * float(b)
    cf = float(c)
    s = p + cf
    if math.isfinite(s):
        bb = s - p
        e = (p - (s - bb)) + (cf - bb)
        if e != 0.0 and not np.float64(s).view(np.int64) & 1:  # an even last bit
            s = math.nextafter(s, math.inf if e > 0.0 else -math.inf)
    return np.float32(s)


if config.ENABLE_CUDASIM:  # the simulator runs device functions as Python
    @cuda.jit(device=True)
    def _fma_f32(a, b, c):
        return fma_f32_exact(a, b, c)

    @cuda.jit(device=True)
    def _mul(a, b):
        return a * b

    @cuda.jit(device=True)
    def _int64_as_float64(a):
        return np.array([a], np.int64).view(np.float64)[0]

    _mul_f32 = _mul_f64 = _mul
else:
    from numba.cuda import libdevice

    @cuda.jit(device=True)
    def _fma_f32(a, b, c):
        return cuda.fma(a, b, c)

    @cuda.jit(device=True)
    def _mul_f32(a, b):
        return libdevice.fmul_rn(a, b)

    @cuda.jit(device=True)
    def _mul_f64(a, b):
        return libdevice.dmul_rn(a, b)

    @cuda.jit(device=True)
    def _int64_as_float64(a):
        return libdevice.longlong_as_double(a)


_b = build_bodies(cuda.jit(device=True), build_expf(cuda.jit(device=True), _fma_f32, _mul_f32, _int64_as_float64),
                  _mul_f64)
_pt_shift = build_road_model(cuda.jit(device=True)).pt_shift
_at_least_zero = _b.at_least_zero
_box_residual = _b.box_residual
_box_pixel = _b.box_pixel
_box_output = _b.box_output
_level_position = _b.level_position
_level_value = _b.level_value
_range_weight = _b.range_weight
_level_estimate = _b.level_estimate
_combine_at = _b.combine_at
_residual_at = _b.residual_at
_range_params = _b.range_params

_F32_ZERO = np.float32(0.0)
_F32_ONE = np.float32(1.0)
_F32_INF = np.float32(np.inf)


@cuda.jit(device=True)
def _plane_at(has_plane, a0, b1, b2, y, u):
    """The road plane at (y, u), the host's ``shift_plane_f32(a0, b1, b2, 0, shape)``: the
    float64 shift rounded once to float32; +0 without a plane (the host's zero plane)."""
    return np.float32(_pt_shift(a0, b1, b2, np.float64(0.0), np.float64(y), np.float64(u))) if has_plane \
        else _F32_ZERO


@cuda.jit(cache=True)
def _smooth_copy_kernel(disp, non_negative, out):
    u, y = cuda.grid(2)
    if y < disp.shape[0] and u < disp.shape[1]:
        d = disp[y, u]
        out[y, u] = _at_least_zero(d) if non_negative else d


@cuda.jit(cache=True)
def _smooth_box_residual_kernel(disp, has_plane, a0, b1, b2, resid, masked):
    u, y = cuda.grid(2)
    if y < disp.shape[0] and u < disp.shape[1]:
        r, m = _box_residual(disp[y, u], _plane_at(has_plane, a0, b1, b2, y, u), True)
        resid[y, u] = r
        masked[y, u] = m


@cuda.jit(cache=True)
def _smooth_box_kernel(disp, resid, masked, radius, thr, has_plane, a0, b1, b2, non_negative, out):
    u, y = cuda.grid(2)
    if y < disp.shape[0] and u < disp.shape[1]:
        smoothed = _box_pixel(resid, masked, y, u, radius, thr)
        out[y, u] = _box_output(smoothed, disp[y, u], _plane_at(has_plane, a0, b1, b2, y, u), non_negative)


@cuda.jit(cache=True)
def _smooth_residual_kernel(disp, has_plane, a0, b1, b2, resid, use, row_lo, row_hi, row_use):
    y = cuda.grid(1)
    if y < disp.shape[0]:
        lo = _F32_INF
        hi = -_F32_INF
        any_use = False
        for u in range(disp.shape[1]):
            d = disp[y, u]
            r = _residual_at(d, _plane_at(has_plane, a0, b1, b2, y, u))
            resid[y, u] = r
            ok = math.isfinite(d)  # every finite pixel is used (no validity map)
            use[y, u] = ok
            if ok:
                lo = min(lo, r)
                hi = max(hi, r)
                any_use = True
        row_lo[y] = lo
        row_hi[y] = hi
        row_use[y] = any_use


@cuda.jit(cache=True)
def _smooth_range_kernel(row_lo, row_hi, row_use, sigma, params, ints, used):
    # one thread: the residual's range over the rows, the level spacing and count (the
    # host driver's float64 arithmetic), the level flags cleared
    if cuda.grid(1) == 0:
        lo = _F32_INF
        hi = -_F32_INF
        any_use = False
        for y in range(row_lo.shape[0]):
            lo = min(lo, row_lo[y])
            hi = max(hi, row_hi[y])
            any_use = any_use or row_use[y]
        ints[1] = 1 if any_use else 0
        ints[0] = 2
        params[0] = np.float64(lo)
        params[1] = sigma
        if any_use:
            step, n_levels = _range_params(np.float64(lo), np.float64(hi), sigma, MAX_LEVELS - 1)
            params[1] = step
            ints[0] = n_levels
        for k in range(used.shape[0]):
            used[k] = 0


@cuda.jit(cache=True)
def _smooth_levels_kernel(resid, params, ints, used, low, up):
    u, y = cuda.grid(2)
    if y < resid.shape[0] and u < resid.shape[1] and ints[1]:
        n_levels = ints[0]
        k, _ = _level_position(resid[y, u], np.float32(params[0]), np.float32(params[1]),
                               np.float32(n_levels - 2), np.float32(n_levels - 1))
        if k >= 0:  # the pixel's two levels are filtered (every thread writes 1)
            used[k] = 1
            used[k + 1] = 1
        else:  # NaN residual: no level writes its shares
            low[y, u] = _F32_ZERO
            up[y, u] = _F32_ZERO


@cuda.jit(device=True)
def _pad_terms(resid, use, y, p, radius, level, neg_inv2s2):
    """Position p of row y's zero-padded weight rows: ``w r`` and ``w`` in float64 (the float32
    product widened), 0 outside the row."""
    u = p - radius
    if 0 <= u < resid.shape[1]:
        r = resid[y, u]
        e = _range_weight(r, use[y, u], level, neg_inv2s2)
        return np.float64(e * r), np.float64(e)
    return 0.0, 0.0


@cuda.jit(device=True)
def _row_sums(resid, use, y, g, level, neg_inv2s2, radius, rows_n, rows_d):
    """Row y of a level's row pass of cv2.boxFilter (BORDER_CONSTANT, unnormalised) of ``w r``
    and ``w`` into slot g, as the CPU computes it: direct 3- and 5-tap sums, else float64
    running sums (the entering minus the leaving element added)."""
    w = resid.shape[1]
    kk = 2 * radius + 1
    if kk == 3 or kk == 5:
        for i in range(w):
            n0, d0 = _pad_terms(resid, use, y, i, radius, level, neg_inv2s2)
            n1, d1 = _pad_terms(resid, use, y, i + 1, radius, level, neg_inv2s2)
            n2, d2 = _pad_terms(resid, use, y, i + 2, radius, level, neg_inv2s2)
            sn = n0 + n1 + n2
            sd = d0 + d1 + d2
            if kk == 5:
                n3, d3 = _pad_terms(resid, use, y, i + 3, radius, level, neg_inv2s2)
                n4, d4 = _pad_terms(resid, use, y, i + 4, radius, level, neg_inv2s2)
                sn = sn + n3 + n4
                sd = sd + d3 + d4
            rows_n[g, y, i] = sn
            rows_d[g, y, i] = sd
        return
    sn = 0.0
    sd = 0.0
    for j in range(kk):
        pn, pd = _pad_terms(resid, use, y, j, radius, level, neg_inv2s2)
        sn += pn
        sd += pd
    rows_n[g, y, 0] = sn
    rows_d[g, y, 0] = sd
    for i in range(w - 1):
        en, ed = _pad_terms(resid, use, y, i + kk, radius, level, neg_inv2s2)
        ln, ld = _pad_terms(resid, use, y, i, radius, level, neg_inv2s2)
        sn += en - ln
        sd += ed - ld
        rows_n[g, y, i + 1] = sn
        rows_d[g, y, i + 1] = sd


@cuda.jit(cache=True)
def _smooth_row_sums_kernel(resid, use, params, ints, used, j0, lanes, neg_inv2s2, radius, rows_n, rows_d):
    # a thread per (row, lane): the lane's used levels j0 + g (g = lane, lane + lanes, ...
    # below the launch's slots), found in one scan of the level flags
    y, lane = cuda.grid(2)
    if y >= resid.shape[0] or lane >= lanes or not ints[1]:
        return
    c = 0
    for k in range(ints[0]):
        if used[k]:
            g = c - j0
            if 0 <= g < rows_n.shape[0] and g % lanes == lane:
                _row_sums(resid, use, y, g, _level_value(params[0], params[1], k), neg_inv2s2, radius, rows_n,
                          rows_d)
            c += 1


@cuda.jit(device=True)
def _column_sums(resid, params, n_levels, k, g, u, radius, rows_n, rows_d, low, up):
    """Column u of level k (slot g): the float64 running column sums from the top
    (cv2.boxFilter's column pass, the CPU's order), the estimate at each row and the pixel's
    share where the level is its lower (upper) one."""
    h = resid.shape[0]
    lo = np.float32(params[0])
    step = np.float32(params[1])
    top = np.float32(n_levels - 2)
    top_plus_1 = np.float32(n_levels - 1)
    sn = 0.0
    sd = 0.0
    for j in range(2 * radius):  # padded rows 0 .. 2 radius - 1 (image rows -radius .. radius-1)
        y = j - radius
        if 0 <= y < h:
            sn += rows_n[g, y, u]
            sd += rows_d[g, y, u]
        else:
            sn += 0.0
            sd += 0.0
    for y in range(h):
        yp = y + radius  # entering row
        ym = y - radius  # leaving row
        pn = rows_n[g, yp, u] if yp < h else 0.0
        pd = rows_d[g, yp, u] if yp < h else 0.0
        mn = rows_n[g, ym, u] if ym >= 0 else 0.0
        md = rows_d[g, ym, u] if ym >= 0 else 0.0
        s0n = sn + pn
        s0d = sd + pd
        sn = s0n - mn
        sd = s0d - md
        r = resid[y, u]
        k0, t = _level_position(r, lo, step, top, top_plus_1)
        if k0 == k:
            low[y, u] = (_F32_ONE - t) * _level_estimate(s0n, s0d, r)
        elif k0 == k - 1:
            up[y, u] = t * _level_estimate(s0n, s0d, r)


@cuda.jit(cache=True)
def _smooth_column_kernel(resid, params, ints, used, j0, lanes, radius, rows_n, rows_d, low, up):
    # a thread per (column, lane), the lanes' levels as in _smooth_row_sums_kernel
    u, lane = cuda.grid(2)
    if u >= resid.shape[1] or lane >= lanes or not ints[1]:
        return
    c = 0
    for k in range(ints[0]):
        if used[k]:
            g = c - j0
            if 0 <= g < rows_n.shape[0] and g % lanes == lane:
                _column_sums(resid, params, ints[0], k, g, u, radius, rows_n, rows_d, low, up)
            c += 1


@cuda.jit(cache=True)
def _smooth_combine_kernel(disp, up, ints, has_plane, a0, b1, b2, non_negative, low):
    # the smoothed map written over low (each thread reads its own cell first)
    u, y = cuda.grid(2)
    if y < disp.shape[0] and u < disp.shape[1]:
        d = disp[y, u]
        if ints[1]:
            low[y, u] = _combine_at(low[y, u], up[y, u], _plane_at(has_plane, a0, b1, b2, y, u), d, non_negative)
        else:  # no finite pixel: the map as it is
            low[y, u] = _at_least_zero(d) if non_negative else d


def levels_per_launch(h, w):
    """Levels the Gaussian filters per pair of launches: what :data:`LEVEL_BYTES` holds, at
    most :data:`MAX_LEVELS` and at most two per pixel (each pixel interpolates from two)."""
    return int(max(1, min(MAX_LEVELS, 2 * h * w, int(LEVEL_BYTES) // (16 * h * w))))


def _gaussian(d_disp, radius, sigma, plane_args, non_negative):
    """The Gaussian range smoothing (piecewise-linear bilateral filter) of a device map."""
    h, w = d_disp.shape
    resid = cuda.device_array((h, w), np.float32)
    use = cuda.device_array((h, w), np.bool_)
    row_lo = cuda.device_array(h, np.float32)
    row_hi = cuda.device_array(h, np.float32)
    row_use = cuda.device_array(h, np.bool_)
    blocks, threads = grid_1d(h)
    _smooth_residual_kernel[blocks, threads](d_disp, *plane_args, resid, use, row_lo, row_hi, row_use)
    params = cuda.device_array(2, np.float64)  # lo, step
    ints = cuda.device_array(2, np.int64)  # n_levels, whether any pixel is used
    used = cuda.device_array(MAX_LEVELS + 1, np.int32)
    _smooth_range_kernel[1, 1](row_lo, row_hi, row_use, np.float64(sigma), params, ints, used)
    low = cuda.device_array((h, w), np.float32)
    up = cuda.device_array((h, w), np.float32)
    blocks, threads = grid_2d(w, h)
    _smooth_levels_kernel[blocks, threads](resid, params, ints, used, low, up)
    # Which levels and how many are on the device: each pair of launches takes the next
    # ``g`` used levels (a thread finds its levels itself), a pair for every ``g`` levels
    # there may be; a launch past the last used level finds none.
    g = levels_per_launch(h, w)
    rows_n = cuda.device_array((g, h, w), np.float64)
    rows_d = cuda.device_array((g, h, w), np.float64)
    neg_inv2s2 = np.float32(-(0.5 / float(sigma) ** 2))
    lanes = np.int64(min(int(LEVEL_LANES), g))
    for j0 in range(0, min(MAX_LEVELS, 2 * h * w), g):
        blocks, threads = grid_2d(h, lanes)
        _smooth_row_sums_kernel[blocks, threads](resid, use, params, ints, used, np.int64(j0), lanes, neg_inv2s2,
                                                 np.int64(radius), rows_n, rows_d)
        blocks, threads = grid_2d(w, lanes)
        _smooth_column_kernel[blocks, threads](resid, params, ints, used, np.int64(j0), lanes, np.int64(radius),
                                               rows_n, rows_d, low, up)
    blocks, threads = grid_2d(w, h)
    _smooth_combine_kernel[blocks, threads](d_disp, up, ints, *plane_args, bool(non_negative), low)
    return low


def smooth_map(disparity, radius, sigma, kernel, plane, non_negative):
    """The finishing's smoothing of a map on the device (:func:`d3cli.kernels.finishing.smooth_map`
    on the CPU): ``box`` two launches, a thread per pixel; ``gaussian`` a thread per row for
    the residual, one for the range, a thread per pixel for the levels, per group of levels
    (:func:`levels_per_launch`) :data:`LEVEL_LANES` threads per row for the row sums and as
    many per column for the column sums and shares, a thread per pixel for the blend.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.smooth_map`.
    """
    d_disp = on_device(disparity)
    h, w = d_disp.shape
    has_plane = plane is not None
    a0, b1, b2 = (float(c) for c in plane) if has_plane else (0.0, 0.0, 0.0)
    plane_args = (has_plane, np.float64(a0), np.float64(b1), np.float64(b2))
    if kernel not in ("box", "gaussian"):
        raise ValueError(f"smoothing kernel must be gaussian or box, got {kernel!r}")
    if int(radius) <= 0 or h * w == 0:
        out = cuda.device_array((h, w), np.float32)
        if h * w:
            blocks, threads = grid_2d(w, h)
            _smooth_copy_kernel[blocks, threads](d_disp, bool(non_negative), out)
        return out
    if kernel == "gaussian":
        return _gaussian(d_disp, int(radius), float(sigma), plane_args, non_negative)
    resid = cuda.device_array((h, w), np.float32)
    masked = cuda.device_array((h, w), np.float32)
    out = cuda.device_array((h, w), np.float32)
    blocks, threads = grid_2d(w, h)
    _smooth_box_residual_kernel[blocks, threads](d_disp, *plane_args, resid, masked)
    _smooth_box_kernel[blocks, threads](d_disp, resid, masked, np.int64(radius), np.float32(sigma), *plane_args,
                                        bool(non_negative), out)
    return out
