"""CPU driver of the semi-global smoothing of a banded volume (four paths, rows and
columns, in two sweeps of two paths each), a path step's cells as LLVM vectors of 8
disparities (one file: numba keys a cached driver on its own file, so the inlined step
lives beside it).  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils, errors
from numba.extending import intrinsic

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import pack_volume, unpack_volume
from ..intrinsics import load_acquire, prefetch_cells, spin_pause, store_release
from ..pool import run_tasks, threads


# ----------------------------------------------------------------------------- semi-global smoothing
def sgm_smooth(cost, p1, p2):
    """Mean of four semi-global path costs (left, down, right, up) of a volume.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.sgm_smooth`.

    Two sweeps over the volume, each walking two paths at once: the first top to bottom
    and left to right (the left path, then the down path, at each cell), the second bottom
    to top and right to left (right, then up).  A sweep cuts the columns into one segment
    per thread; a segment's down (up) paths are its own, its rows' left (right) paths come
    in from the segment before it, which hands each row's last path costs over as it
    finishes the row (a wavefront: segment j works on row v while segment j - 1 works
    further down).  Two paths per visit of a cell instead of one: each cell's cost is read
    twice instead of four times, the sums read and written twice instead of four times, a
    pixel's band set up half as often.  A driver that walks the row paths by rows and the
    column paths by strips of columns takes about 15 % longer on a KITTI finest volume
    (15.4 M cells, 2 threads; ``scripts/bench_speed.py``).
    """
    flat, index, n_disp, dense = unpack_volume(cost)
    # not zeroed in a pass of its own: the first sweep writes every cell of a band and
    # zeroes those between the bands (stored, not visible), so every cell is defined
    acc = np.empty_like(flat)
    p1, p2 = np.float32(p1), np.float32(p2)
    bounds = segment_bounds(index, SGM_SEGMENTS or threads())
    n_seg = bounds.shape[0] - 1
    # per boundary and row the path costs (and their least) handed to the next segment
    hand = np.empty((max(n_seg - 1, 1), index.shape[0], n_disp + 2), np.float32)
    hand_least = np.empty((max(n_seg - 1, 1), index.shape[0]), np.float32)
    for backward in (False, True):
        done = np.zeros(n_seg, np.int64)  # per segment the rows finished in this sweep
        abort = np.zeros(1, np.int64)  # set by run_tasks when a thread stops with an error
        task = _backward_task if backward else forward_task
        run_tasks(task, n_seg, flat, index, bounds, p1, p2, acc, hand, hand_least, done, abort, abort=abort)
    return pack_volume(acc, index, n_disp, dense)


#: Segments per sweep; None: one per thread (the tests set more, to cross many boundaries
#: on small volumes; more segments than threads are taken in turn and still agree).
SGM_SEGMENTS = None


#: Columns per segment at least: fewer segments than threads on narrow images, since each
#: boundary costs a hand-over per row.
SGM_MIN_SEGMENT = 64


#: The sweeps prefetch the cells of the pixel this many steps ahead on its row (in the
#: volume and in the sums): a segment's stretch of a row is contiguous, but the hardware's
#: prefetcher loses it at each page (without it a KITTI volume takes 70 ms instead of 39-44;
#: 8 to 16 pixels give the same time, 24 and 32 a little more, a row ahead 43).
SGM_PREFETCH_PIXELS = 8


#: Rounds of a waiting loop between two ``sched_yield`` calls.
SGM_SPINS = 64


def segment_bounds(index, n_threads):
    """Column bounds of the sweeps' segments (int64, first 0, last W): one per thread (at
    most W / :data:`SGM_MIN_SEGMENT`), cut where the band cells summed over columns reach
    equal shares, so that the segments take equal time."""
    w = index.shape[1]
    n_seg = max(1, min(n_threads, w // SGM_MIN_SEGMENT))
    if n_seg == 1:
        return np.array([0, w], np.int64)
    cells = np.cumsum(_column_cells(index))
    bounds = np.zeros(n_seg + 1, np.int64)
    bounds[1:-1] = np.searchsorted(cells, cells[-1] * np.arange(1, n_seg) / n_seg) + 1
    bounds[-1] = w
    for k in range(1, n_seg):  # at least a column each
        bounds[k] = min(max(bounds[k], bounds[k - 1] + 1), w - (n_seg - k))
    return bounds


#: Rows between two rows counted for the segments' shares of the cells (the bands change
#: from tile to tile, not from row to row: counting every row takes 0.85 ms on KITTI, every 8th 0.15).
SGM_SHARE_ROWS = 8


@njit(cache=True, error_model="numpy")
def _column_cells(index):
    """Band cells per column in every :data:`SGM_SHARE_ROWS`-th row (float64, for the
    cumulative share)."""
    out = np.zeros(index.shape[1], np.float64)
    for v in range(0, index.shape[0], SGM_SHARE_ROWS):
        for u in range(index.shape[1]):
            out[u] += max(0, index[v, u, 2] - index[v, u, 1])
    return out


@njit(nogil=True, cache=True, error_model="numpy")
def forward_task(i, n, cost, index, bounds, p1, p2, acc, hand, hand_least, done, abort):
    """Segment i of the first sweep: the left path stores, the down path adds."""
    _sweep_segment(i, n, cost, index, bounds, p1, p2, acc, hand, hand_least, done, abort, 1, 1)


@njit(nogil=True, cache=True, error_model="numpy")
def _backward_task(i, n, cost, index, bounds, p1, p2, acc, hand, hand_least, done, abort):
    """Segment n - 1 - i of the second sweep (tasks start at the right): the right path
    adds, the up path adds and scales by a quarter."""
    _sweep_segment(n - 1 - i, n, cost, index, bounds, p1, p2, acc, hand, hand_least, done, abort, -1, 2)


@njit(cache=True, inline="always", error_model="numpy")
def _sweep_segment(j, n, cost, index, bounds, p1, p2, acc, hand, hand_least, done, abort, step, mode):
    """The rows of segment j, in sweep order (``step`` 1: top down, left to right; -1:
    bottom up, right to left), each pixel's row path step then its column path step.

    Row v's path comes in from the segment upstream (j - step) once that one has finished
    the row (``done``); this segment hands its own on (``hand[boundary, v]``, the least in
    ``hand_least``) and counts the row done.  Tasks are taken in sweep order, so the
    segment waited for is always being worked on: no wait can deadlock, whatever the
    number of threads.  Unless it failed, or was never taken (Ctrl-C between two tasks):
    then :func:`d3cli.kernels.pool.run_tasks` sets ``abort[0]``, and a waiting segment
    stops where it is (the call raises that error; nothing of this volume is used)."""
    h, w = index.shape[0], index.shape[1]
    size = hand.shape[2]
    u0, u1 = bounds[j], bounds[j + 1]
    width = u1 - u0
    up = j - step  # the segment the row paths come from
    has_up = 0 <= up < n
    has_down = 0 <= j + step < n
    # the boundary between j and j + step: hand[min(j, j + step)]
    give = j if step > 0 else j - 1
    take = j - 1 if step > 0 else j
    # per column two path buffers, column k's at k size; per column the previous pixel's least
    ca = np.full(size * width, np.inf, np.float32)
    cb = np.full(size * width, np.inf, np.float32)
    least = np.full(width, np.inf, np.float32)
    x = np.empty(size, np.float32)  # the row path's two buffers
    y = np.empty(size, np.float32)
    for i in range(h):
        v = i if step > 0 else h - 1 - i
        if step > 0 and j == 0:
            _zero_gaps(index, v, acc)
        pm = np.float32(np.inf)
        x[:] = np.inf
        if has_up:
            spins = 0
            while load_acquire(done, up) <= i:
                if load_acquire(abort, 0) != 0:
                    return
                spins += 1
                spin_pause(spins % SGM_SPINS == 0)
            x[:] = hand[take, v]
            pm = hand_least[take, v]
        y[:] = np.inf
        pa, pb = (ca, cb) if i % 2 == 0 else (cb, ca)
        for k in range(width):
            u = u0 + k if step > 0 else u1 - 1 - k
            if 0 <= u + step * SGM_PREFETCH_PIXELS < w:
                _prefetch_pixel(cost, acc, index, v, u + step * SGM_PREFETCH_PIXELS)
            # the band the buffer written now holds from two steps back: on the row path
            # none for the segment's first pixel (fresh), the one handed over for its second
            back = u - 2 * step
            row_back = (index[v, back, 1], index[v, back, 2]) if k >= 1 and 0 <= back < w else (0, 0)
            column_back = (index[v - 2 * step, u, 1], index[v - 2 * step, u, 2]) if i >= 2 else (0, 0)
            c = u - u0
            pm, least[c] = _sgm_pixel(cost, index, v, u, p1, p2, acc, mode, x, 0, pm, y, row_back,
                                      pa, c * size, least[c], pb, column_back)
            x, y = y, x
        if has_down:
            hand[give, v] = x  # x: the path costs of the row's last pixel here
            hand_least[give, v] = pm
            store_release(done, j, i + 1)


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
def _prefetch_pixel(cost, acc, index, v, u):
    """Prefetch the band of pixel (v, u) in the volume and in the sums."""
    c0 = index[v, u, 0] + index[v, u, 1]
    c1 = index[v, u, 0] + index[v, u, 2] - 1
    prefetch_cells(cost, c0, c1)
    prefetch_cells(acc, c0, c1)


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
def _sgm_band(typingctx, cost, acc, cells, n, p1, p2, mode,
              pbuf_a, cbuf_a, below_a, out_a, pm_a, pbuf_b, cbuf_b, below_b, out_b, pm_b):
    """The ``n`` cells of one pixel's step on two paths, a and b (the recurrence of
    :meth:`d3cli.kernels.backend.Backend.sgm_smooth`), in blocks of :data:`SGM_LANES`
    disparities: cell i's cost at ``cost[cells + i]``; path a's previous pixel's path costs
    of d - 1, d, d + 1 at ``pbuf_a[below_a + i + (0, 1, 2)]``, its new one written to
    ``cbuf_a[out_a + i]``; path b's likewise.  ``mode`` (a literal) 1: the first sweep,
    ``acc[cells + i] = L_a + L_b``; 2: the second, ``acc = ((acc + L_a) + L_b) / 4``.  The
    same float32 operations in the same order per cell as the reference (compare-and-select
    minima, then ``C + (b - pm)``).  Returns the least new path cost of each path, kept per
    lane over the blocks and reduced once.  Whole blocks take plain loads and stores, the
    last partial one masked ones: no cell past ``n`` is read or written."""
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
        n = scalar(3, types.int64)
        p1 = _splat(builder, scalar(4, types.float32), f32, lanes)
        paths = []
        for first in (7, 12):  # the arguments of path a, then b: pbuf, cbuf, below, out, pm
            pm = scalar(first + 4, types.float32)
            paths.append(dict(
                pbuf=first, cbuf=first + 1, below=first + 2, out=first + 3,
                pm=_splat(builder, pm, f32, lanes),
                jump=_splat(builder, builder.fadd(pm, scalar(5, types.float32)), f32, lanes),
                started=builder.fcmp_unordered("!=", pm, ir.Constant(f32, math.inf)),  # else L = C
                least=cgutils.alloca_once_value(builder, infs)))

        def block(start, inside, fresh=None):
            """Cells start .. start + lanes - 1: masked loads and stores for ``inside``;
            ``fresh`` (an overlapping last block): the sums of the other lanes, done by
            the block before, are written back as they are."""
            def at(k, shift=0):
                return builder.add(builder.add(scalar(k, types.int64), start), i64(shift))

            c = load(0, at(2), inside)
            new = []
            for path in paths:
                x = load(path["pbuf"], at(path["below"], 1), inside)  # L(q, d)
                b = builder.select(builder.fcmp_ordered("<", x, path["jump"]), x, path["jump"])
                y = builder.fadd(load(path["pbuf"], at(path["below"]), inside), p1)  # L(q, d - 1) + P1
                b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
                y = builder.fadd(load(path["pbuf"], at(path["below"], 2), inside), p1)  # L(q, d + 1) + P1
                b = builder.select(builder.fcmp_ordered("<", y, b), y, b)
                el = builder.select(path["started"], builder.fadd(c, builder.fsub(b, path["pm"])), c)
                store(el, path["cbuf"], at(path["out"]), inside)  # an overlapping block writes them again, the same
                masked = el if inside is None else builder.select(inside, el, infs)
                m = builder.load(path["least"])
                builder.store(builder.select(builder.fcmp_ordered("<", masked, m), masked, m), path["least"])
                new.append(el)
            old = load(1, at(2), inside) if how == 2 or fresh is not None else None
            if how == 1:
                total = builder.fadd(new[0], new[1])
            else:
                total = builder.fmul(builder.fadd(builder.fadd(old, new[0]), new[1]),
                                     ir.Constant(vec, [0.25] * lanes))
            store(total if fresh is None else builder.select(fresh, total, old), 1, at(2), inside)

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
        least = [_least(builder, builder.load(path["least"]), lanes) for path in paths]
        return context.make_tuple(builder, signature.return_type, least)

    sig = types.UniTuple(types.float32, 2)(cost, acc, cells, n, p1, p2, mode,
                                           pbuf_a, cbuf_a, below_a, out_a, pm_a, pbuf_b, cbuf_b, below_b, out_b, pm_b)
    return sig, codegen


@njit(cache=True, error_model="numpy", inline="always")
def _sgm_pixel(cost, index, v, u, p1, p2, acc, mode, pbuf_a, base_a, pm_a, cbuf_a, back_a, pbuf_b, base_b, pm_b,
               cbuf_b, back_b):
    """One pixel's step on two paths, a and b (each: L(d) at ``base + d + 1`` of a buffer
    of n_disp + 2 cells, ``pm`` the least path cost of its previous pixel, inf at the
    path's start), in blocks of :data:`SGM_LANES` disparities.  Returns the least of this
    pixel's path costs on each path: their next steps' ``pm``, taken from the blocks as
    they are written instead of a scan of the band (a serial chain of compares that takes a
    fifth of the smoothing's time).

    The buffers hold inf outside the band last written into them: ``cbuf`` still holds the
    band of the pixel two steps back on its path (``back``: its (lo, hi), (0, 0) for
    none: all inf), and only its cells outside this pixel's band go back to inf (resetting
    the whole previous band costs more: neighbouring bands mostly overlap)."""
    off = index[v, u, 0]
    lo = index[v, u, 1]
    hi = index[v, u, 2]
    least = _sgm_band(cost, acc, off + lo, hi - lo, p1, p2, mode,
                      pbuf_a, cbuf_a, base_a + lo, base_a + lo + 1, pm_a,
                      pbuf_b, cbuf_b, base_b + lo, base_b + lo + 1, pm_b)
    _reset_outside(cbuf_a, base_a, back_a[0], back_a[1], lo, hi)
    _reset_outside(cbuf_b, base_b, back_b[0], back_b[1], lo, hi)
    return least


@njit(cache=True, error_model="numpy", inline="always")
def _reset_outside(cbuf, base, olo, ohi, lo, hi):
    """Cells of band ``[olo, ohi)`` outside ``[lo, hi)`` back to inf (L(d) at base + d + 1)."""
    for d in range(olo, min(ohi, lo)):
        cbuf[np.uint64(base + d + 1)] = np.inf
    for d in range(max(olo, hi), ohi):
        cbuf[np.uint64(base + d + 1)] = np.inf
