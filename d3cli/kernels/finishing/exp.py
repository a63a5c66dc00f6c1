"""NumPy's float32 ``exp`` inside numba kernels, bit for bit: the range weights of the smoothing.

:func:`numpy_expf` transcribes NumPy's SIMD algorithm (equal on all 2^32 arguments, NaN
payloads included); the C library's ``expf``, which numba's ``math.exp`` calls, differs in
the last bit for about a third of the arguments.  Its body is written once for the CPU and
CUDA (:func:`d3cli.kernels.finishing.pixel_smoothing.build_expf`); the two LLVM intrinsics the
CPU build needs (a single-rounding FMA, an int64 -> float64 bit cast) live here.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from .pixel_smoothing import build_expf


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


@njit(cache=True, inline="always")
def _mul_f32(a, b):
    """``a * b`` (the CPU compiler fuses no multiply into an add: a plain product)."""
    return a * b


# The body is written once for the CPU and CUDA (pixel_smoothing.build_expf): NumPy's SIMD
# algorithm, equal to ``np.exp`` on all 2^32 float32 values, NaN payloads included
# (``tests/kernels/finishing/test_exp.py`` checks a sample of every range).  Why not numba's
# ``math.exp``: it calls the C library's ``expf``, which differs from NumPy's in the last bit
# for about a third of the arguments, and the smoothing's reference (and so every map the
# package writes) uses ``np.exp``.
numpy_expf = build_expf(njit(cache=True, inline="always", error_model="numpy"), _fma_f32, _mul_f32,
                        _int64_as_float64)


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
