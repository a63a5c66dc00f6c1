"""The vector (8-lane LLVM) cells of one semi-global path step on the CPU: a pixel's band
in blocks of 8 disparities, and the least of its new path costs taken on the way."""

from __future__ import annotations

import math

import numpy as np

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils, errors
from numba.extending import intrinsic

from .. import cache as _cache  # noqa: F401  (chooses the numba cache folder first)

#: Disparities per block: one AVX register of float32 (a band of 35 fills 5 blocks, 40
#: lanes; blocks of 16 would fill 48).
SGM_LANES = 8


def _splat(builder, x, ty, lanes):
    """LLVM IR: a vector of ``lanes`` lanes of ``ty``, each ``x``."""
    undef = ir.Constant(ir.VectorType(ty, lanes), ir.Undefined)
    first = builder.insert_element(undef, x, ir.IntType(32)(0))
    return builder.shuffle_vector(first, undef, ir.Constant(ir.VectorType(ir.IntType(32), lanes), [0] * lanes))


def _least(builder, x, lanes):
    """LLVM IR: the least lane of the float vector ``x`` (compare and select, exact)."""
    undef = ir.Constant(x.type, ir.Undefined)
    width = lanes
    while width > 1:
        width //= 2
        upper = builder.shuffle_vector(x, undef, ir.Constant(ir.VectorType(ir.IntType(32), lanes),
                                                             [width + k if k < width else k for k in range(lanes)]))
        x = builder.select(builder.fcmp_ordered("<", upper, x), upper, x)
    return builder.extract_element(x, ir.IntType(32)(0))


@intrinsic
def _sgm_band(typingctx, cost, acc, pbuf, cbuf, cells, below, out, n, pm, p1, p2, mode):
    """The ``n`` cells of one path step, :func:`d3cli.kernels.sgm.pixel.build`'s
    ``sgm_step`` loop in blocks of :data:`SGM_LANES` disparities: cell i's cost at
    ``cost[cells + i]``, the previous pixel's path costs of d - 1, d, d + 1 at
    ``pbuf[below + i + (0, 1, 2)]``, the new one written to ``cbuf[out + i]`` and into
    ``acc[cells + i]`` as ``mode`` (a literal) says.  The same float32 operations in the
    same order per cell (compare-and-select minima, then ``C + (b - pm)``).  Returns the
    least new path cost, kept per lane over the blocks and reduced once.  Whole blocks
    take plain loads and stores, the last partial one masked ones: no cell past ``n`` is
    read or written."""
    if not isinstance(mode, types.IntegerLiteral):
        raise errors.RequireLiteralValue("mode")
    how = mode.literal_value
    lanes = SGM_LANES

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        i64 = ir.IntType(64)
        vec = ir.VectorType(f32, lanes)
        bits = ir.VectorType(ir.IntType(1), lanes)

        def scalar(k, ty):
            return context.cast(builder, args[k], signature.args[k], ty)

        def ptr(k, at):  # pointer to cell ``at`` of the (1D, C) array argument k
            ary = context.make_array(signature.args[k])(context, builder, args[k])
            return builder.gep(ary.data, [at])

        ptr_t = ptr(0, i64(0)).type
        m_load = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [ptr_t, ir.IntType(32), bits, vec]),
                                                f"llvm.masked.load.v{lanes}f32.p0")
        m_store = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [vec, ptr_t, ir.IntType(32), bits]),
            f"llvm.masked.store.v{lanes}f32.p0")
        zero = ir.Constant(vec, [0.0] * lanes)
        infs = ir.Constant(vec, [math.inf] * lanes)
        n = scalar(7, types.int64)
        pm = scalar(8, types.float32)
        pm_v = _splat(builder, pm, f32, lanes)
        p1 = _splat(builder, scalar(9, types.float32), f32, lanes)
        jump = _splat(builder, builder.fadd(pm, scalar(10, types.float32)), f32, lanes)
        started = builder.fcmp_unordered("!=", pm, ir.Constant(f32, math.inf))  # else the path's first pixel: L = C
        least = cgutils.alloca_once_value(builder, infs)

        def block(start, inside):
            def load(k, base, shift):
                p = ptr(k, builder.add(builder.add(scalar(base, types.int64), start), i64(shift)))
                if inside is not None:
                    return builder.call(m_load, [p, ir.IntType(32)(4), inside, zero])
                return builder.load(builder.bitcast(p, vec.as_pointer()), align=4)

            def store(value, k, base):
                p = ptr(k, builder.add(scalar(base, types.int64), start))
                if inside is not None:
                    builder.call(m_store, [value, p, ir.IntType(32)(4), inside])
                else:
                    builder.store(value, builder.bitcast(p, vec.as_pointer()), align=4)

            el = load(0, 4, 0)
            x = load(2, 5, 1)  # L(q, d)
            b = builder.select(builder.fcmp_ordered("<", x, jump), x, jump)
            y = builder.fadd(load(2, 5, 0), p1)  # L(q, d - 1) + P1
            b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
            y = builder.fadd(load(2, 5, 2), p1)  # L(q, d + 1) + P1
            b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
            el = builder.select(started, builder.fadd(el, builder.fsub(b, pm_v)), el)
            store(el, 3, 6)
            if how == 0:
                store(el, 1, 4)
            elif how == 1:
                store(builder.fadd(load(1, 4, 0), el), 1, 4)
            else:
                store(builder.fmul(builder.fadd(load(1, 4, 0), el), ir.Constant(vec, [0.25] * lanes)), 1, 4)
            if inside is not None:
                el = builder.select(inside, el, infs)
            m = builder.load(least)
            builder.store(builder.select(builder.fcmp_ordered("<", el, m), el, m), least)

        whole = builder.sdiv(n, i64(lanes)) if lanes & (lanes - 1) else builder.ashr(n, i64(lanes.bit_length() - 1))
        with cgutils.for_range(builder, whole) as loop:
            block(builder.mul(loop.index, i64(lanes)), None)
        start = builder.mul(whole, i64(lanes))
        with builder.if_then(builder.icmp_signed("<", start, n)):
            ids = builder.add(_splat(builder, start, i64, lanes), ir.Constant(ir.VectorType(i64, lanes), list(range(lanes))))
            block(start, builder.icmp_signed("<", ids, _splat(builder, n, i64, lanes)))
        return _least(builder, builder.load(least), lanes)

    sig = types.float32(cost, acc, pbuf, cbuf, cells, below, out, n, pm, p1, p2, mode)
    return sig, codegen


@njit(cache=True, error_model="numpy", inline="always")
def _sgm_pixel(cost, index, v, u, pbuf, pbase, plo, phi, pm, cbuf, cbase, p1, p2, acc, mode):
    """One pixel of one path (``pixel.sgm_step``'s arithmetic and buffer layout) in
    blocks of :data:`SGM_LANES` disparities; ``pm`` the least path cost of the previous
    pixel (inf at the path's start).  Returns the least of this pixel's path costs: the
    next step's ``pm``, taken from the blocks as they are written instead of a scan of
    the band (a serial chain of compares that took a fifth of the smoothing's time)."""
    off = index[v, u, 0]
    lo = index[v, u, 1]
    hi = index[v, u, 2]
    cells = off + lo
    below = pbase + lo  # L(q, d - 1) of the band's first d
    out = cbase + lo + 1
    least = _sgm_band(cost, acc, pbuf, cbuf, cells, below, out, hi - lo, pm, p1, p2, mode)
    seen = pbase + plo + 1  # the previous pixel's band back to inf (pixel.sgm_step's layout)
    for i in range(phi - plo):
        pbuf[np.uint64(seen + i)] = np.inf
    return least
