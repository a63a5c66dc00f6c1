"""The vector (16-lane LLVM) row machinery of the CPU recursive filter: blocks of
cells of one row filtered at once, grouped by run of equal bands."""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils, errors
from numba.extending import intrinsic

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from .cpu_rows import _rbf_cells
from ..intrinsics import splat16


#: The widest block of :func:`_rbf_run` (six vectors of 16); the rings of
#: :func:`rbf_passes` have this many cells more, so that a block reading past the last
#: row stays in its ring.
RBF_MAX_LANES = 96


@intrinsic
def _rbf_cells_vec(typingctx, out, db, ring, offs, sb, band, weights, v, ux, uy, uz, vectors):
    """:func:`_rbf_cells` over the ``16 vectors`` cells ``out[db ..]`` (``vectors`` a
    literal), source k's from ``ring[offs[k] + sb]``, of up to three pixels of ``band``
    cells each: cell i < band takes the weights ``weights[v, ux]``, i < 2 band those of
    ``uy``, the others ``uz``'s (one pixel's weights repeated for fewer pixels).  Same
    terms in the same order per cell (float32 multiply, then add: no fused
    multiply-add), written as vectors of 16: LLVM's vectoriser leaves the loop that picks
    a weight per cell scalar.  The arrays and offsets, not slices of them: the slices
    per run and the weights view per block cost 2-9 % of the filter (measured)."""
    if not isinstance(vectors, types.IntegerLiteral):
        raise errors.RequireLiteralValue("vectors")
    n_vec = vectors.literal_value

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        i64 = ir.IntType(64)
        vec = ir.VectorType(f32, 16)
        out_t, offs_t, weights_t = signature.args[0], signature.args[3], signature.args[6]
        out_ary = context.make_array(out_t)(context, builder, args[0])
        ring_ary = context.make_array(signature.args[2])(context, builder, args[2])
        weights_ary = context.make_array(weights_t)(context, builder, args[6])

        def as_i64(k):
            return context.cast(builder, args[k], signature.args[k], types.int64)

        sb = as_i64(4)
        starts = [builder.add(context.cast(builder, builder.extract_value(args[3], k), offs_t.types[k], types.int64),
                              sb) for k in range(9)]
        width = as_i64(5)
        ends = (splat16(builder, width, i64), splat16(builder, builder.mul(width, i64(2)), i64))
        weights = [[splat16(builder, builder.load(cgutils.get_item_pointer(
            context, builder, weights_t, weights_ary, [as_i64(7), as_i64(8 + g), i64(k)])), f32) for k in range(9)]
            for g in range(3)]
        for n in range(n_vec):
            lanes = ir.Constant(ir.VectorType(i64, 16), list(range(16 * n, 16 * n + 16)))
            first = builder.icmp_signed("<", lanes, ends[0])
            second = builder.icmp_signed("<", lanes, ends[1])
            a = ir.Constant(vec, [0.0] * 16)
            for k in range(9):
                w = builder.select(first, weights[0][k], builder.select(second, weights[1][k], weights[2][k]))
                at = builder.gep(ring_ary.data, [builder.add(starts[k], i64(16 * n))])
                q = builder.load(builder.bitcast(at, vec.as_pointer()), align=4)
                a = builder.fadd(a, builder.fmul(w, q))
            at = builder.gep(out_ary.data, [builder.add(as_i64(1), i64(16 * n))])
            builder.store(a, builder.bitcast(at, vec.as_pointer()), align=4)
        return context.get_dummy_value()

    return types.void(out, db, ring, offs, sb, band, weights, v, ux, uy, uz, vectors), codegen


@intrinsic
def _rbf_cells_borrowing(typingctx, out, d0, ring, own, nbr, weights, v, u, c0, band):
    """Cells ``c0 .. c0 + 15`` (those below ``band``) of a pixel whose neighbours lack
    some of its disparities: ``out[d0 + c]`` from the 3x3 neighbours' cells, neighbour k
    at ``ring[nbr[3k] + c]`` for ``nbr[3k + 1] <= c < nbr[3k + 2]``, the pixel's own
    cell ``ring[own + c]`` elsewhere, weighted by ``weights[v, u, k]`` and added in slot
    order (float32 multiply, then add).  Masked loads and a masked store: no cell
    outside the bands is read, none past the pixel written."""

    def codegen(context, builder, signature, args):
        f32 = ir.FloatType()
        i64 = ir.IntType(64)
        vec = ir.VectorType(f32, 16)
        ivec = ir.VectorType(i64, 16)
        bits = ir.VectorType(ir.IntType(1), 16)
        ring_t, out_t, nbr_t, weights_t = signature.args[2], signature.args[0], signature.args[4], signature.args[5]
        ring_ary = context.make_array(ring_t)(context, builder, args[2])
        out_ary = context.make_array(out_t)(context, builder, args[0])
        nbr_ary = context.make_array(nbr_t)(context, builder, args[4])
        weights_ary = context.make_array(weights_t)(context, builder, args[5])

        def as_i64(k):
            return context.cast(builder, args[k], signature.args[k], types.int64)

        ptr_t = ring_ary.data.type
        load = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [ptr_t, ir.IntType(32), bits, vec]),
                                              "llvm.masked.load.v16f32.p0")
        store = cgutils.get_or_insert_function(builder.module,
                                               ir.FunctionType(ir.VoidType(), [vec, ptr_t, ir.IntType(32), bits]),
                                               "llvm.masked.store.v16f32.p0")
        c0 = as_i64(8)
        lanes = builder.add(splat16(builder, c0, i64), ir.Constant(ivec, list(range(16))))
        inside = builder.icmp_signed("<", lanes, splat16(builder, as_i64(9), i64))
        zero = ir.Constant(vec, [0.0] * 16)
        own_cells = builder.call(load, [builder.gep(ring_ary.data, [builder.add(as_i64(3), c0)]), ir.IntType(32)(4),
                                        inside, zero])
        a = zero
        for k in range(9):
            at, lo_k, hi_k = (builder.load(cgutils.get_item_pointer(context, builder, nbr_t, nbr_ary, [i64(3 * k + j)]))
                              for j in range(3))
            theirs = builder.and_(builder.icmp_signed(">=", lanes, splat16(builder, lo_k, i64)),
                                  builder.icmp_signed("<", lanes, splat16(builder, hi_k, i64)))
            cells = builder.call(load, [builder.gep(ring_ary.data, [builder.add(at, c0)]), ir.IntType(32)(4),
                                        builder.and_(theirs, inside), own_cells])
            wk = builder.load(cgutils.get_item_pointer(context, builder, weights_t, weights_ary,
                                                       [as_i64(6), as_i64(7), i64(k)]))
            a = builder.fadd(a, builder.fmul(splat16(builder, wk, f32), cells))
        builder.call(store, [a, builder.gep(out_ary.data, [builder.add(as_i64(1), c0)]), ir.IntType(32)(4), inside])
        return context.get_dummy_value()

    return types.void(out, d0, ring, own, nbr, weights, v, u, c0, band), codegen


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, group, vectors):
    """:func:`_rbf_run` with blocks of ``16 vectors`` cells that hold ``group`` pixels
    (literals; ``group band <= 16 vectors``)."""
    lanes = 16 * vectors
    step = group * band
    n_fast = min(m // group, (room - lanes) // step + 1) if room >= lanes else 0
    b = 0
    for g in range(n_fast):
        p = u0 + g * group
        _rbf_cells_vec(out, d0 + b, ring, offs, b, band, weights, v, p, p + (group > 1), p + group - 1, vectors)
        b += step
    p_fast = min(m, (room - lanes) // band + 1) if room >= lanes else 0
    for p in range(n_fast * group, p_fast):
        _rbf_cells_vec(out, d0 + b, ring, offs, b, band, weights, v, u0 + p, u0 + p, u0 + p, vectors)
        b += band
    for p in range(max(n_fast * group, p_fast), m):
        _rbf_cells(out, d0 + b, ring, offs, b, band, weights, v, u0 + p)
        b += band


@njit(cache=True, error_model="numpy")
def _rbf_run(out, d0, ring, o0, o1, o2, o3, o4, o5, o6, o7, o8, weights, v, u0, u1, band, room):
    """New values of a run of pixels u0 .. u1 - 1 of row v with one band B: cell (p, i)
    is ``out[d0 + p B + i]``, from the sources ``ring[ok + p B + i]`` (k = 0 .. 8)
    weighted by ``weights[v, u0 + p, k]``; ``room`` cells of ``out`` from ``d0`` (to the
    end of the row) may be written.  It takes the arrays and offsets, not slices of
    them, and hands them on so: a slice costs reference counting, and the covered pixels
    outside the runs call it for one pixel each (offsets measured faster than slices).

    A loop over the B cells of a pixel vectorises only where it is long, and the bands
    are 4-130 wide (PT bands: 4-16).  The cells are computed in blocks of one to six
    vectors of 16 (:func:`_rbf_cells_vec`, 16 .. 96 cells) instead: a block holds one
    pixel, or two or three pixels of a narrow band (each cell with its own pixel's
    weights), so that a band of 5 fills 15 lanes of a vector instead of 5.  The cells of
    a block past its pixels are the next pixels' of the row: they are computed
    afterwards and overwrite them (the sources' cells past the run are read, and
    dropped).  The pixels at the end of the row, whose block would leave it, and bands
    over 96 take the plain loop.  Same terms in the same order per cell, so the same
    values.  Each (pixels, vectors) pair below is compiled on its own, which lengthens a
    cold first compile; hence only these eight (bands of 9 and 10, rare, go one pixel a
    vector).
    """
    offs = (np.int64(o0), np.int64(o1), np.int64(o2), np.int64(o3), np.int64(o4), np.int64(o5), np.int64(o6),
            np.int64(o7), np.int64(o8))
    m = u1 - u0
    d0 = np.int64(d0)
    if band <= 5:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 3, 1)
    elif band <= 8:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 2, 1)
    elif band <= 16:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 1, 1)
    elif band <= 24:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 2, 3)
    elif band <= 32:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 1, 2)
    elif band <= 48:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 1, 3)
    elif band <= 64:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 1, 4)
    elif band <= 96:
        _rbf_groups(out, d0, ring, offs, weights, v, u0, m, band, room, 1, 6)
    else:
        b = 0
        for p in range(m):
            _rbf_cells(out, d0 + b, ring, offs, b, band, weights, v, u0 + p)
            b += band


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_pixel_borrowing(out, at, ring, ra, rh, rb, own, row_start, index, nbr, weights, v, u, lo, hi):
    """One pixel of :func:`_rbf_row` some of whose neighbours lack a disparity of its band:
    where the nine neighbours' cells lie and which disparities each holds (``nbr``), then
    the cells in vectors of 16 (:func:`_rbf_cells_borrowing`)."""
    h, w, _ = index.shape
    band = hi - lo
    for k in range(9):
        y = min(max(v + k // 3 - 1, 0), h - 1)
        x = min(max(u + k % 3 - 1, 0), w - 1)
        r = ra if k < 3 else (rh if k < 6 else rb)
        # [a0, a1): the disparities the neighbour holds; its cells at disparities
        # lo .. hi - 1 would lie from nbr[3k] on
        a0 = min(max(lo, index[y, x, 1]), hi)
        a1 = max(min(hi, index[y, x, 2]), a0)
        nbr[3 * k] = r + index[y, x, 0] - row_start[y] + lo
        nbr[3 * k + 1] = a0 - lo
        nbr[3 * k + 2] = a1 - lo
    for c0 in range(0, band, 16):
        _rbf_cells_borrowing(out, at, ring, own, nbr, weights, v, u, c0, band)


@njit(cache=True, error_model="numpy")
def _rbf_row(out, shift, v, ring, ra, rh, rb, row_start, index, covered, run_end, weights):
    """New values of row v, written into ``out`` (cell ``(v, u, d)`` at ``out[shift +
    off + d]``: the volume itself with ``shift`` 0, or a ring row), from the old rows
    v - 1, v, v + 1 (clamped at the image border) held in ``ring`` rows ``ra``, ``rh``,
    ``rb``.

    ``ring`` is flat (one source array of layout C: the loops vectorise) and ``ra``,
    ``rh``, ``rb`` are the starts of the rows in it: cell (y, x, d) of an old row is
    ``ring[r + index[y, x, 0] + d - row_start[y]]``.  The
    nine terms are added in slot order k = 0..8 in float32.  Neighbours outside the image
    have weight 0 and read a clamped, in-image cell: adding +0.0 leaves the
    (non-negative) sum unchanged, so the result is the same as skipping them.  Where
    every neighbour's band contains the pixel's (``covered``: all but thin lines along
    the tile borders) :func:`_rbf_run` does it, for a run of pixels at once where their
    neighbours all have their band (``run_end``, :func:`_run_ends`: the end of each
    run), else for the pixel alone.  Elsewhere, where a
    neighbour's band lacks a disparity of the pixel's band, the pixel's own cell stands
    in (:func:`_rbf_cells_borrowing`, vectors of 16 cells, faster than a scalar loop per
    slot and part of the band): the bands are built (:mod:`d3cli.kernels.cost.band`) so that
    this never happens for a cell the later steps read, it only keeps the halo cells
    finite.
    """
    h, w, _ = index.shape
    ym = max(v - 1, 0)
    yp = min(v + 1, h - 1)
    sh_a = row_start[ym]
    sh_h = row_start[v]
    sh_b = row_start[yp]
    nbr = np.empty(27, np.int64)
    u = 0
    while u < w:
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        if hi <= lo:
            u += 1
            continue
        band = hi - lo
        if covered[v, u] == 2 and 0 < u < w - 1:
            # a run of interior pixels whose neighbours all hold this band: their cells,
            # and each neighbour row's, follow one another B apart, so each of the nine
            # sources is one offset into the ring and the per-pixel work is nine weights
            # (_rbf_run)
            u1 = run_end[v, u]
            room = row_start[v + 1] - off - lo  # the cells to the row's end
            ba = ra + index[ym, u - 1, 0] - sh_a + lo
            bh = rh + index[v, u - 1, 0] - sh_h + lo
            bb = rb + index[yp, u - 1, 0] - sh_b + lo
            _rbf_run(out, shift + off + lo, ring, ba, ba + band, ba + 2 * band, bh, bh + band, bh + 2 * band, bb,
                     bb + band, bb + 2 * band, weights, v, u, u1, band, room)
            u = u1
            continue
        o4 = off - sh_h
        if covered[v, u]:
            # one pixel, its neighbours' cells anywhere: a run of one
            xm = max(u - 1, 0)
            xp = min(u + 1, w - 1)
            o0 = ra + index[ym, xm, 0] - sh_a + lo
            o1 = ra + index[ym, u, 0] - sh_a + lo
            o2 = ra + index[ym, xp, 0] - sh_a + lo
            o3 = rh + index[v, xm, 0] - sh_h + lo
            o5 = rh + index[v, xp, 0] - sh_h + lo
            o6 = rb + index[yp, xm, 0] - sh_b + lo
            o7 = rb + index[yp, u, 0] - sh_b + lo
            o8 = rb + index[yp, xp, 0] - sh_b + lo
            room = row_start[v + 1] - off - lo
            _rbf_run(out, shift + off + lo, ring, o0, o1, o2, o3, rh + o4 + lo, o5, o6, o7, o8, weights, v, u, u + 1,
                     band, room)
            u += 1
            continue
        _rbf_pixel_borrowing(out, shift + off + lo, ring, ra, rh, rb, rh + o4 + lo, row_start, index, nbr, weights,
                             v, u, lo, hi)
        u += 1


@njit(cache=True, error_model="numpy")
def _run_ends(run_end, covered, index):
    """For the pixels of a row that start a run in :func:`_rbf_row` (interior,
    ``covered`` 2), the end of the run: the first pixel past it that is not interior,
    not ``covered`` 2 or has another band.  Found once per call, not once per pass and
    halo row."""
    w = covered.shape[0]
    for u in range(w - 2, 0, -1):
        if covered[u] == 2:
            if (u + 1 < w - 1 and covered[u + 1] == 2 and index[u + 1, 1] == index[u, 1]
                    and index[u + 1, 2] == index[u, 2]):
                run_end[u] = run_end[u + 1]
            else:
                run_end[u] = u + 1
