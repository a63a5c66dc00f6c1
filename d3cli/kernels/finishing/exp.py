"""NumPy's float32 ``exp`` inside numba kernels, bit for bit: the range weights of the smoothing.

:func:`numpy_expf` transcribes NumPy's SIMD algorithm (equal on all 2^32 arguments, NaN
payloads included); the C library's ``expf``, which numba's ``math.exp`` calls, differs in
the last bit for about a third of the arguments.  The two LLVM intrinsics it needs (a
single-rounding FMA, an int64 -> float64 bit cast) live here with it.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

_F32_ZERO = np.float32(0.0)
_F32_INF = np.float32(np.inf)


@intrinsic
def _fma_f32(typingctx, a, b, c):
    """``a * b + c`` rounded once (``llvm.fma.f32``: the CPU's FMA instruction, or a correctly
    rounded library call where there is none)."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f32], ir.FunctionType(f32, [f32, f32, f32]))
        return builder.call(fn, args)

    return sig, codegen


@intrinsic
def _int64_as_float64(typingctx, a):
    """The float64 whose bits are the int64 ``a``."""
    sig = types.float64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


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
_F32_NAN = np.float32(np.nan)


@njit(cache=True, inline="always", error_model="numpy")
def numpy_expf(x):
    """``np.exp`` of a float32, bit for bit, as NumPy computes it on x86 with AVX2+FMA3 or
    AVX512F (``simd_exp_FLOAT``): Cody-Waite reduction ``r = x - k ln 2`` with
    ``k = rint(x log2 e)``, the rational minimax ``P5(r) / Q2(r)`` by FMA (Horner), times
    ``2^k`` rounded once (AVX512's ``scalef``; the AVX2 path's integer exponent add and
    its division for subnormal results round the same).  Checked equal to ``np.exp`` on
    all 2^32 float32 values, NaN payloads included (``tests/kernels/finishing/test_exp.py``
    checks a sample of every range).  Branch-free (selects), so that loops over it
    vectorise.

    Why not numba's ``math.exp``: it calls the C library's ``expf``, which differs from
    NumPy's in the last bit for about a third of the arguments, and the smoothing's
    reference (and so every map the package writes) uses ``np.exp``.
    """
    nan = x != x
    big = x >= _EXP_XMAX
    small = x <= _EXP_XMIN
    x = _F32_ZERO if (nan or big or small) else x
    k = x * _EXP_LOG2E
    k = k + _EXP_MAGIC
    k = k - _EXP_MAGIC
    r = _fma_f32(k, _EXP_LN2_HI, x)
    r = _fma_f32(k, _EXP_LN2_LO, r)
    r = _fma_f32(k, _F32_ZERO, r)  # NumPy's third Cody-Waite step (c3 = 0); kept for -0
    num = _fma_f32(_EXP_P5, r, _EXP_P4)
    num = _fma_f32(num, r, _EXP_P3)
    num = _fma_f32(num, r, _EXP_P2)
    num = _fma_f32(num, r, _EXP_P1)
    num = _fma_f32(num, r, _EXP_P0)
    den = _fma_f32(_EXP_Q2, r, _EXP_Q1)
    den = _fma_f32(den, r, _EXP_Q0)
    poly = num / den
    # poly * 2^k, k in [-150, 128]: exact in float64 (2^k built from its exponent bits),
    # then one rounding to float32, subnormal results included
    out = np.float32(np.float64(poly) * _int64_as_float64((np.int64(k) + np.int64(1023)) << np.int64(52)))
    out = _F32_NAN if nan else out
    out = _F32_INF if big else out
    return _F32_ZERO if small else out


@njit(cache=True, nogil=True, error_model="numpy")
def _exp_task(task, tasks, values, out):
    n = values.shape[0]
    i0, i1 = (task * n) // tasks, ((task + 1) * n) // tasks
    for i in range(i0, i1):
        out[i] = numpy_expf(values[i])


def numpy_exp(values):
    """:func:`numpy_expf` of a flat float32 array (a new array); the test hook of the kernel."""
    values = np.ascontiguousarray(values, np.float32).reshape(-1)
    out = np.empty_like(values)
    _exp_task(0, 1, values, out)
    return out


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_exp_task,)
