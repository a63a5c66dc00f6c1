"""The per-pixel bodies of the smoothing, written once for the CPU and for CUDA.

:func:`build_expf` defines NumPy's float32 ``exp`` (:mod:`d3cli.kernels.finishing.exp`)
with a given ``jit`` and the target's primitives (an FMA rounded once, a float32 multiply
that is never fused into a following add, an int64 -> float64 bit cast); :func:`build`
defines the steps of the box and of the Gaussian range smoothing over it.  Compiled with
``numba.njit`` for the CPU tasks of :mod:`d3cli.kernels.finishing.exp`,
:mod:`d3cli.kernels.finishing.smoothing` and :mod:`d3cli.kernels.finishing.range_box`, and
with ``numba.cuda.jit(device=True)`` for the kernels of
:mod:`d3cli.kernels.finishing.cuda_smoothing`: the same float32/float64 operations in the
same order, so the values are the CPU's.

May import: numpy.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

_F32_ZERO = np.float32(0.0)
_F32_ONE = np.float32(1.0)
_F32_INF = np.float32(np.inf)
_F32_NAN = np.float32(np.nan)
_F32_EPS = np.float32(1e-6)


def _f32(bits: int) -> np.float32:
    """The float32 with these bits."""
    return np.array([bits], np.uint32).view(np.float32)[0]


# Constants of NumPy's SIMD float32 exp (numpy/_core/src/umath/npy_simd_data.h and the
# limits of simd_exp_FLOAT in loops_exponent_log.dispatch.c.src), as bit patterns
_EXP_LN2_HI = _f32(0xBF317200)  # NPY_CODY_WAITE_LOGE_2_HIGHf, -ln 2 high part
_EXP_LN2_LO = _f32(0xB5BFBE8E)  # NPY_CODY_WAITE_LOGE_2_LOWf
_EXP_MAGIC = _f32(0x4B400000)  # NPY_RINT_CVT_MAGICf, 1.5 * 2^23: adding it rounds to an integer
_EXP_LOG2E = _f32(0x3FB8AA3B)  # NPY_LOG2Ef
_EXP_P0, _EXP_P1, _EXP_P2, _EXP_P3, _EXP_P4, _EXP_P5 = (
    _f32(b) for b in (0x3F800000, 0x3F39CBD5, 0x3E7D4C58, 0x3D517D8C, 0x3BDD7159, 0x3A053DD8))
_EXP_Q0, _EXP_Q1, _EXP_Q2 = (_f32(b) for b in (0x3F800000, 0xBE8C6857, 0x3CB0E832))
_EXP_XMAX = _f32(0x42B17218)  # 88.72283935546875: inf at and above
_EXP_XMIN = _f32(0xC2CFF1B5)  # -103.97208404541015625: 0 at and below


def build_expf(jit, fma_f32, mul_f32, int64_as_float64):
    """NumPy's float32 ``exp`` compiled with ``jit``.

    Parameters
    ----------
    jit : callable
        ``numba.njit(...)`` or ``numba.cuda.jit(device=True)``.
    fma_f32 : callable
        ``a * b + c`` of three float32 rounded once.
    mul_f32 : callable
        ``a * b`` of two float32, rounded on its own (a GPU compiler fuses a plain multiply
        with the add after it; the rint by the magic constant needs both roundings).
    int64_as_float64 : callable
        The float64 whose bits are an int64.

    Returns
    -------
    callable
        ``numpy_expf(x)``.
    """

    @jit
    def numpy_expf(x):
        """``np.exp`` of a float32, bit for bit, as NumPy computes it on x86 with AVX2+FMA3 or
        AVX512F (``simd_exp_FLOAT``): Cody-Waite reduction ``r = x - k ln 2`` with
        ``k = rint(x log2 e)``, the rational minimax ``P5(r) / Q2(r)`` by FMA (Horner), times
        ``2^k`` rounded once (AVX512's ``scalef``; the AVX2 path's integer exponent add and
        its division for subnormal results round the same).  Branch-free (selects), so that
        loops over it vectorise."""
        nan = x != x
        big = x >= _EXP_XMAX
        small = x <= _EXP_XMIN
        x = _F32_ZERO if (nan or big or small) else x
        k = mul_f32(x, _EXP_LOG2E)
        k = k + _EXP_MAGIC
        k = k - _EXP_MAGIC
        r = fma_f32(k, _EXP_LN2_HI, x)
        r = fma_f32(k, _EXP_LN2_LO, r)
        r = fma_f32(k, _F32_ZERO, r)  # NumPy's third Cody-Waite step (c3 = 0); kept for -0
        num = fma_f32(_EXP_P5, r, _EXP_P4)
        num = fma_f32(num, r, _EXP_P3)
        num = fma_f32(num, r, _EXP_P2)
        num = fma_f32(num, r, _EXP_P1)
        num = fma_f32(num, r, _EXP_P0)
        den = fma_f32(_EXP_Q2, r, _EXP_Q1)
        den = fma_f32(den, r, _EXP_Q0)
        poly = num / den
        # poly * 2^k, k in [-150, 128]: exact in float64 (2^k built from its exponent bits),
        # then one rounding to float32, subnormal results included
        out = np.float32(np.float64(poly) * int64_as_float64((np.int64(k) + np.int64(1023)) << np.int64(52)))
        out = _F32_NAN if nan else out
        out = _F32_INF if big else out
        return _F32_ZERO if small else out

    return numpy_expf


def build(jit, numpy_expf, mul_f64):
    """The smoothing's per-pixel bodies compiled with ``jit``.

    Parameters
    ----------
    jit : callable
    numpy_expf : callable
        :func:`build_expf`'s function for the same target.
    mul_f64 : callable
        ``a * b`` of two float64, rounded on its own (see :func:`build_expf`).

    Returns
    -------
    types.SimpleNamespace
        ``at_least_zero``; the box kernel's ``box_residual``, ``box_row_terms``,
        ``box_mean``, ``box_pixel``, ``box_output``; the Gaussian's ``residual_at``,
        ``range_params``, ``level_position``, ``level_value``, ``range_weight``,
        ``level_estimate``, ``combine_at``.
    """

    @jit
    def at_least_zero(x):
        """``x``, or 0 where ``x < 0`` (NaN and -0 stay): the finished map's disparities are
        >= 0."""
        return _F32_ZERO if x < _F32_ZERO else x

    # ------------------------------------------------------------------ box range kernel
    @jit
    def box_residual(d, b, ok):
        """A pixel's residual ``d - b`` (inf where ``d`` is not finite) and its masked value
        (the residual where ``ok``, else NaN: NaN fails every range test)."""
        if math.isfinite(d):
            r = d - b
            return r, (r if ok else _F32_NAN)
        return _F32_INF, _F32_NAN

    @jit
    def box_row_terms(masked, y, u, r, radius, thr, tot, cnt):
        """The terms of source row y to the sums of column u (centre residual ``r``): the
        offsets inside the row, left to right, each in range ``|q - r| <= thr`` added to
        ``tot`` and counted in ``cnt`` (float32); returns both."""
        w = masked.shape[1]
        for dx in range(max(-radius, -u), min(radius, w - 1 - u) + 1):
            q = masked[y, u + dx]
            inside = abs(q - r) <= thr
            tot += q if inside else _F32_ZERO
            cnt += _F32_ONE if inside else _F32_ZERO
        return tot, cnt

    @jit
    def box_mean(rp, tot, cnt):
        """The smoothed residual: the mean of the terms, or ``rp`` where it is not finite or
        has no term."""
        return rp if (not math.isfinite(rp) or cnt == _F32_ZERO) else tot / cnt

    @jit
    def box_pixel(resid, masked, y, u, radius, thr):
        """The smoothed residual of pixel (y, u): its box's rows top down (float32 sums, the
        CPU kernel's order)."""
        h = resid.shape[0]
        tot = _F32_ZERO
        cnt = _F32_ZERO
        r = resid[y, u]
        for yy in range(max(0, y - radius), min(h - 1, y + radius) + 1):
            tot, cnt = box_row_terms(masked, yy, u, r, radius, thr, tot, cnt)
        return box_mean(r, tot, cnt)

    @jit
    def box_output(smoothed, d, b, non_negative):
        """The output pixel: the smoothed residual plus the plane ``b`` where ``d`` is finite,
        else ``d``; clamped at 0 with ``non_negative`` (+ 0 without a plane: -0 becomes +0 as
        in NumPy)."""
        x = smoothed + b if math.isfinite(d) else d
        return at_least_zero(x) if non_negative else x

    # ------------------------------------------------------------- Gaussian range kernel
    @jit
    def level_position(r, lo, step, top, top_plus_1):
        """Lower range level ``k = clip(floor((r - lo) / step), 0, top).astype(int32)`` of a
        residual (float32 arithmetic; NaN casts to INT32_MIN) and its interpolation weight
        ``t = pos - k`` (float64 difference rounded to float32, as NumPy promotes it).  Selects
        only (the cast of a clamped value), so that loops over it vectorise."""
        pos = (r - lo) / step
        inside = pos if pos < top_plus_1 else top
        k = np.int32(inside if pos >= _F32_ZERO else _F32_ZERO)
        k = k if pos == pos else np.int32(-2147483648)
        return k, np.float32(np.float64(pos) - np.float64(k))

    @jit
    def level_value(lo, step, k):
        """Level k's residual ``lo + k step`` in float64 (the host's Python floats), rounded
        to float32."""
        return np.float32(lo + mul_f64(np.float64(k), step))

    @jit
    def range_weight(r, ok, level, neg_inv2s2):
        """``exp(neg_inv2s2 (r - level)^2)`` (NumPy's float32 ``exp``), +0 where not ``ok``
        (its exponent -inf), NaN where the exponent is NaN: the reference's ``use * exp(x)``."""
        a = r - level
        x = neg_inv2s2 * (a * a)
        return numpy_expf(x if (ok or x != x) else -_F32_INF)

    @jit
    def level_estimate(s0n, s0d, r):
        """A level's estimate ``num / den`` from its float64 box sums rounded to float32 (the
        residual ``r`` where ``den <= 1e-6``: the reference's ``np.maximum(den, 1e-6)`` is
        ``den`` where it is used)."""
        num = np.float32(s0n)
        den = np.float32(s0d)
        return num / den if den > _F32_EPS else r

    @jit
    def combine_at(low, up, b, d, non_negative):
        """The smoothed pixel: ``((0 + low) + up) + b`` where ``d`` is finite (the blend's
        float32 sum started at zero, lower share first), else ``d``; clamped at 0 with
        ``non_negative``."""
        x = ((_F32_ZERO + low) + up) + b if math.isfinite(d) else d
        return at_least_zero(x) if non_negative else x

    @jit
    def residual_at(d, b):
        """The Gaussian's residual ``d - b``, 0 where ``d`` is not finite."""
        return d - b if math.isfinite(d) else _F32_ZERO

    @jit
    def range_params(lo, hi, sigma, max_levels):
        """The range levels of residuals in [lo, hi] (float64, the host's Python floats):
        ``step = max(sigma, (hi - lo) / (max_levels - 1))`` and ``n_levels =
        floor((hi - lo) / step) + 2``."""
        spread = (hi - lo) / np.float64(max_levels - 1)
        step = spread if spread > sigma else sigma
        return step, np.int64(math.floor((hi - lo) / step)) + 2

    return SimpleNamespace(at_least_zero=at_least_zero, box_residual=box_residual, box_row_terms=box_row_terms,
                           box_mean=box_mean, box_pixel=box_pixel, box_output=box_output,
                           level_position=level_position, level_value=level_value, range_weight=range_weight,
                           level_estimate=level_estimate, combine_at=combine_at, residual_at=residual_at,
                           range_params=range_params)
