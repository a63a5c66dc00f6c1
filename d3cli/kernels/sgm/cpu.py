"""CPU driver of the semi-global smoothing of a banded volume (four paths, rows and
columns), a path step's cells as LLVM vectors of 8 disparities (one file: numba keys a
cached driver on its own file, so the inlined step lives beside it).  The contract:
:mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, prange, types
from numba.core import cgutils, errors
from numba.extending import intrinsic

from .. import cache as _cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import _pack, _unpack
from ..intrinsics import _prefetch_cells


# ----------------------------------------------------------------------------- semi-global smoothing
def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs (left, right, down, up) of a volume.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.sgm_smooth`.
    """
    flat, index, n_disp, dense = _unpack(cost)
    # not zeroed in a pass of its own: the row paths write every cell of a band and zero
    # those between the bands (stored, not visible), so every cell is defined
    acc = np.empty_like(flat)
    p1, p2 = np.float32(p1), np.float32(p2)
    _sgm_rows(flat, index, n_disp, p1, p2, acc)
    _sgm_columns(flat, index, n_disp, p1, p2, acc)
    return _pack(acc, index, n_disp, dense)


#: Columns per task of the column paths: each task walks its columns down (then up) row
#: by row, so the cells it reads lie side by side (8, 16 and 64 measured the same on
#: KITTI; the first kernel walked one column at a time, a cache line per pixel).
SGM_COLUMNS = 32


#: The column paths prefetch the cells of the pixel this many rows ahead: each task's
#: rows lie apart in the volume, where the hardware's prefetcher does not follow (2 rows
#: measured best).
SGM_PREFETCH_ROWS = 2


@njit(parallel=True, cache=True)
def _sgm_rows(cost, index, n_disp, p1, p2, acc):
    for v in prange(index.shape[0]):
        _zero_gaps(index, v, acc)
        # two path buffers, L(d) at d + 1, inf outside the band (sentinels at both ends)
        a = np.full(n_disp + 2, np.inf, np.float32)
        b = np.full(n_disp + 2, np.inf, np.float32)
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, 1, 0)  # left to right: the first path stores
        a[:] = np.inf
        b[:] = np.inf
        _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, -1, 1)  # right to left


@njit(cache=True, inline="always")
def _zero_gaps(index, v, acc):
    """Zero the cells of ``acc`` in no band, from the end of row v - 1's last band to
    that of row v (the last row: to the end); bands packed in pixel order, row after row
    (:mod:`d3cli.kernels.volume`)."""
    h, w = index.shape[0], index.shape[1]
    end = np.int64(0)
    for r in range(v - 1, -1, -1):  # the cell after the last band above (an empty row: the one before)
        u = w - 1
        while u >= 0 and index[r, u, 2] <= index[r, u, 1]:
            u -= 1
        if u >= 0:
            end = np.int64(index[r, u, 0]) + index[r, u, 2]
            break
    for u in range(w):
        lo, hi = index[v, u, 1], index[v, u, 2]
        if hi > lo:
            start = np.int64(index[v, u, 0]) + lo
            for c in range(end, start):
                acc[c] = 0
            end = max(end, start + (hi - lo))
    if v == h - 1:
        for c in range(end, acc.shape[0]):
            acc[c] = 0


@njit(cache=True, inline="always")
def _sgm_row_pass(cost, index, v, a, b, p1, p2, acc, step, mode):
    """One row path (``step`` 1 rightwards, -1 leftwards) along row v; ``a``, ``b`` the
    path buffers (all inf on entry)."""
    w = index.shape[1]
    pm = np.float32(np.inf)
    for i in range(w):
        u = i if step > 0 else w - 1 - i
        # the band that b (the buffer written now) holds from two pixels back
        olo, ohi = (index[v, u - 2 * step, 1], index[v, u - 2 * step, 2]) if i >= 2 else (0, 0)
        pm = _sgm_pixel(cost, index, v, u, a, 0, pm, b, 0, olo, ohi, p1, p2, acc, mode)
        a, b = b, a


@njit(parallel=True, cache=True)
def _sgm_columns(cost, index, n_disp, p1, p2, acc):
    w = index.shape[1]
    n_tasks = (w + SGM_COLUMNS - 1) // SGM_COLUMNS
    size = n_disp + 2
    for task in prange(n_tasks):
        u0 = task * SGM_COLUMNS
        u1 = min(w, u0 + SGM_COLUMNS)
        # per column two path buffers, column k's at k size of two arrays
        a = np.full(size * (u1 - u0), np.inf, np.float32)
        b = np.full(size * (u1 - u0), np.inf, np.float32)
        least = np.full(u1 - u0, np.inf, np.float32)  # per column the previous pixel's least path cost
        _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, 1, 1)  # down
        a[:] = np.inf
        b[:] = np.inf
        least[:] = np.inf
        _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, -1, 2)  # up: the last path scales


@njit(cache=True, inline="always")
def _sgm_column_pass(cost, index, u0, u1, a, b, least, size, p1, p2, acc, step, mode):
    """One column path (``step`` 1 down, -1 up) over columns u0..u1, row by row; column
    k's two path buffers at ``k size`` of ``a`` and ``b`` (all inf on entry), its previous
    pixel's least path cost at ``least[k]`` (inf on entry)."""
    h = index.shape[0]
    for i in range(h):
        v = i if step > 0 else h - 1 - i
        ahead = v + step * SGM_PREFETCH_ROWS
        for u in range(u0, u1):
            if 0 <= ahead < h:
                _prefetch_pixel(cost, acc, index, ahead, u)
            # the band that b (the buffer written now) holds from two rows back
            olo, ohi = (index[v - 2 * step, u, 1], index[v - 2 * step, u, 2]) if i >= 2 else (0, 0)
            k = (u - u0) * size
            least[u - u0] = _sgm_pixel(cost, index, v, u, a, k, least[u - u0], b, k, olo, ohi, p1, p2, acc, mode)
        a, b = b, a


@njit(cache=True, inline="always")
def _prefetch_pixel(cost, acc, index, v, u):
    """Prefetch the band of pixel (v, u) in the volume and in the sums."""
    c0 = index[v, u, 0] + index[v, u, 1]
    c1 = index[v, u, 0] + index[v, u, 2] - 1
    _prefetch_cells(cost, c0, c1)
    _prefetch_cells(acc, c0, c1)


# ----------------------------------------------------------------------------- a path step as vectors
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


def _vector_access(context, builder, signature, args, lanes):
    """LLVM IR helpers of a vector intrinsic over 1D float32 arrays: ``scalar(k, ty)``
    argument k cast to ``ty``; ``load(k, at, inside)`` and ``store(value, k, at,
    inside)`` the ``lanes`` cells of array argument k from cell ``at`` (an i64), masked
    by ``inside`` (a vector of i1) or, with None, plain."""
    vec = ir.VectorType(ir.FloatType(), lanes)
    bits = ir.VectorType(ir.IntType(1), lanes)
    i32 = ir.IntType(32)

    def scalar(k, ty):
        return context.cast(builder, args[k], signature.args[k], ty)

    def ptr(k, at):
        ary = context.make_array(signature.args[k])(context, builder, args[k])
        return builder.gep(ary.data, [at])

    ptr_t = ptr(0, ir.IntType(64)(0)).type
    m_load = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [ptr_t, i32, bits, vec]),
                                            f"llvm.masked.load.v{lanes}f32.p0")
    m_store = cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), [vec, ptr_t, i32, bits]),
                                             f"llvm.masked.store.v{lanes}f32.p0")

    def load(k, at, inside):
        if inside is not None:
            return builder.call(m_load, [ptr(k, at), i32(4), inside, ir.Constant(vec, [0.0] * lanes)])
        return builder.load(builder.bitcast(ptr(k, at), vec.as_pointer()), align=4)

    def store(value, k, at, inside):
        if inside is not None:
            builder.call(m_store, [value, ptr(k, at), i32(4), inside])
        else:
            builder.store(value, builder.bitcast(ptr(k, at), vec.as_pointer()), align=4)

    return scalar, load, store


@intrinsic
def _sgm_band(typingctx, cost, acc, pbuf, cbuf, cells, below, out, n, pm, p1, p2, mode):
    """The ``n`` cells of one path step (the recurrence of
    :meth:`d3cli.kernels.backend.Backend.sgm_smooth`) in blocks of :data:`SGM_LANES` disparities: cell i's cost at
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
        scalar, load, store = _vector_access(context, builder, signature, args, lanes)
        infs = ir.Constant(vec, [math.inf] * lanes)
        n = scalar(7, types.int64)
        pm = scalar(8, types.float32)
        pm_v = _splat(builder, pm, f32, lanes)
        p1 = _splat(builder, scalar(9, types.float32), f32, lanes)
        jump = _splat(builder, builder.fadd(pm, scalar(10, types.float32)), f32, lanes)
        started = builder.fcmp_unordered("!=", pm, ir.Constant(f32, math.inf))  # else the path's first pixel: L = C
        least = cgutils.alloca_once_value(builder, infs)

        def block(start, inside, fresh=None):
            """Cells start .. start + lanes - 1: masked loads and stores for ``inside``;
            ``fresh`` (an overlapping last block): the sums of the other lanes, done by
            the block before, are written back as they are."""
            def at(k, shift=0):
                return builder.add(builder.add(scalar(k, types.int64), start), i64(shift))

            el = load(0, at(4), inside)
            x = load(2, at(5, 1), inside)  # L(q, d)
            b = builder.select(builder.fcmp_ordered("<", x, jump), x, jump)
            y = builder.fadd(load(2, at(5), inside), p1)  # L(q, d - 1) + P1
            b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
            y = builder.fadd(load(2, at(5, 2), inside), p1)  # L(q, d + 1) + P1
            b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
            el = builder.select(started, builder.fadd(el, builder.fsub(b, pm_v)), el)
            store(el, 3, at(6), inside)  # an overlapping block writes its path costs again, the same
            old = load(1, at(4), inside) if how or fresh is not None else None
            if how == 1:
                total = builder.fadd(old, el)
            elif how == 2:
                total = builder.fmul(builder.fadd(old, el), ir.Constant(vec, [0.25] * lanes))
            else:
                total = el
            store(total if fresh is None else builder.select(fresh, total, old), 1, at(4), inside)
            el = el if inside is None else builder.select(inside, el, infs)
            m = builder.load(least)
            builder.store(builder.select(builder.fcmp_ordered("<", el, m), el, m), least)

        whole = builder.ashr(n, i64(lanes.bit_length() - 1))  # blocks of all lanes (SGM_LANES: a power of two)
        with cgutils.for_range(builder, whole) as loop:
            block(builder.mul(loop.index, i64(lanes)), None)
        start = builder.mul(whole, i64(lanes))
        ivec = ir.VectorType(i64, lanes)
        with builder.if_then(builder.icmp_signed("<", start, n)):
            # the rest: a block ending at the band's end where the band has a whole block
            # (plain loads and stores), else masked ones
            with builder.if_else(builder.icmp_signed(">=", n, i64(lanes))) as (overlap, short):
                with overlap:
                    last = builder.sub(n, i64(lanes))
                    ids = builder.add(_splat(builder, last, i64, lanes), ir.Constant(ivec, list(range(lanes))))
                    block(last, None, builder.icmp_signed(">=", ids, _splat(builder, start, i64, lanes)))
                with short:
                    ids = builder.add(_splat(builder, start, i64, lanes), ir.Constant(ivec, list(range(lanes))))
                    block(start, builder.icmp_signed("<", ids, _splat(builder, n, i64, lanes)))
        return _least(builder, builder.load(least), lanes)

    sig = types.float32(cost, acc, pbuf, cbuf, cells, below, out, n, pm, p1, p2, mode)
    return sig, codegen


@njit(cache=True, error_model="numpy", inline="always")
def _sgm_pixel(cost, index, v, u, pbuf, pbase, pm, cbuf, cbase, olo, ohi, p1, p2, acc, mode):
    """One pixel of one path (L(d) at ``base + d + 1`` of a buffer of n_disp + 2 cells) in
    blocks of :data:`SGM_LANES` disparities; ``pm`` the least path cost of the previous
    pixel (inf at the path's start).  Returns the least of this pixel's path costs: the
    next step's ``pm``, taken from the blocks as they are written instead of a scan of
    the band (a serial chain of compares that took a fifth of the smoothing's time).

    The buffers hold inf outside the band last written into them: ``cbuf`` still holds the
    band ``[olo, ohi)`` of the pixel two steps back (empty: all inf), and only its cells
    outside this pixel's band go back to inf (resetting the whole previous band cost more:
    neighbouring bands mostly overlap)."""
    off = index[v, u, 0]
    lo = index[v, u, 1]
    hi = index[v, u, 2]
    cells = off + lo
    below = pbase + lo  # L(q, d - 1) of the band's first d
    out = cbase + lo + 1
    least = _sgm_band(cost, acc, pbuf, cbuf, cells, below, out, hi - lo, pm, p1, p2, mode)
    for d in range(olo, min(ohi, lo)):
        cbuf[np.uint64(cbase + d + 1)] = np.inf
    for d in range(max(olo, hi), ohi):
        cbuf[np.uint64(cbase + d + 1)] = np.inf
    return least
