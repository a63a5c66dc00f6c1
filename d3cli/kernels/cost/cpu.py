"""CPU drivers of the matching cost (pipeline step 2): integral images, the NCC cost
volume (full range or banded), the cosine (deep-feature) cost and the out-of-view
invalidation.  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import on_grid, ops, pack_volume, row_layout, unpack_volume
from ..pixel import UINT
from ..volume import dense_index
from .pixel import F32_ONE


_cosine_cost = ops.cosine_cost


_box_sum = ops.box_sum


_ncc_finish = ops.ncc_finish


#: Rows per parallel task of the NCC driver (one running window sum per task).
NCC_BLOCK_ROWS = 32


#: Tasks per thread of the NCC driver when its sums are exact (:func:`_ncc_banded`).
NCC_EXACT_TASKS = 4


#: Fractional bits of the grey levels that :func:`_integral_pair_into` tests for.
GRID_BITS = (6, 20)


#: Bands of at most this many unclipped cells take the NCC row's one-loop slide (below a
#: vector's few steps, one loop over the cells beats two).
NCC_NARROW = 8


@njit(cache=True, error_model="numpy")
def integral_image(img, power):
    """(H+1, W+1) float64 integral image of ``img ** power`` (power 1 or 2)."""
    h, w = img.shape
    ii = np.empty((h + 1, w + 1), np.float64)
    _integral_into(img, power, ii)
    return ii


@njit(cache=True, error_model="numpy")
def _integral_into(img, power, ii):
    """Write :func:`integral_image` of ``img ** power`` into ``ii`` (H+1, W+1)."""
    h, w = img.shape
    for x in range(w + 1):
        ii[0, x] = 0.0
    for y in range(h):
        ii[y + 1, 0] = 0.0
        row = 0.0
        for x in range(w):
            val = np.float64(img[y, x])
            row += val if power == 1 else val * val
            ii[y + 1, x + 1] = ii[y, x + 1] + row


@njit(cache=True, error_model="numpy")
def _integral_pair_into(img, ii, ii2):
    """:func:`_integral_into` of ``img`` (into ``ii``) and of ``img ** 2`` (into ``ii2``)
    in one scan: two independent chains of adds, so each waits less on the other's
    latency (the same operations per image)."""
    h, w = img.shape
    for x in range(w + 1):
        ii[0, x] = 0.0
        ii2[0, x] = 0.0
    for y in range(h):
        ii[y + 1, 0] = 0.0
        ii2[y + 1, 0] = 0.0
        row = 0.0
        row2 = 0.0
        for x in range(w):
            val = np.float64(img[y, x])
            row += val
            row2 += val * val
            ii[y + 1, x + 1] = ii[y, x + 1] + row
            ii2[y + 1, x + 1] = ii2[y, x + 1] + row2


@njit(cache=True, error_model="numpy")
def grid_bits(img):
    """The least k in :data:`GRID_BITS` such that every value of ``img`` is a multiple of
    2^-k of magnitude <= 255 (6: the first four pyramid levels of an 8-bit image; 20: a
    warped one), else 64 (:func:`on_grid`)."""
    for k in GRID_BITS:
        if on_grid(img, 2.0 ** k, -255):
            return k
    return 64


@njit(parallel=True, cache=True, error_model="numpy")
def _integral_images(left, right):
    """The four integral images of the NCC (L, L^2, R, R^2), two at a time: each is a
    serial scan.  Each is written in place into its slice of one array (no zeroed
    temporary per image and no copy of it), an image's two in one scan."""
    h, w = left.shape
    out = np.empty((4, h + 1, w + 1), np.float64)
    bits = np.empty(2, np.int64)
    for k in prange(2):
        img = left if k == 0 else right
        _integral_pair_into(img, out[2 * k], out[2 * k + 1])
        bits[k] = grid_bits(img)
    return out[0], out[1], out[2], out[3], bits[0] + bits[1]


# ----------------------------------------------------------------------------- matching cost (step 2)
def ncc_cost_volume(left, right, max_disparity, window, min_variance, index=None):
    """NCC cost volume ``(1 - NCC) / 2`` with box sums (docs/design.md, step 2).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.ncc_cost_volume`.
    """
    h, w = left.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    if dense:
        index = dense_index(h, w, n_disp)
    n_cells = int(index[-1, -1, 0]) + int(index[-1, -1, 2])
    flat = _ncc_banded(left, right, index, n_disp, n_cells, int(window), float(min_variance), numba.get_num_threads())
    return pack_volume(flat, index, n_disp, (h, w, n_disp) if dense else None)


@njit(parallel=True, cache=True, error_model="numpy")
def _ncc_banded(left, right, index, n_disp, n_cells, window, min_variance, n_threads):
    h, w = left.shape
    r = window // 2
    ii_l, ii_ll, ii_r, ii_rr, bits = _integral_images(left, right)
    max_row = row_layout(index)[1]  # the most cells of a row
    cost = np.empty(n_cells, np.float32)
    # The rows are cut into blocks, one prange task each; inside a block acc is a running
    # sum along the rows (add the row entering the window, subtract the one leaving it),
    # and along a row the window sum over columns slides too, so the work per cell does
    # not grow with the window .  acc holds, per column, only the
    # disparities some pixel within the window radius needs (the hull of their bands).
    # float64 keeps the add/subtract drift far below the 1e-5 cost tolerance (values
    # <= 255^2 * window^2; float32 sums drift by more than that: measured, see tests).
    block = NCC_BLOCK_ROWS
    if bits <= 36 and (2 * r + 2) ** 2 <= 2 ** (36 - bits):
        # Grey levels up to 255 that are multiples of 2^-kl (left) and 2^-kr (right) have
        # products that are multiples of 2^-(kl + kr) below 2^16; every sum here (acc,
        # the window sums, their slides) holds fewer than (2r + 2)^2 of them, so below
        # 2^53 units of 2^-(kl + kr) all are exact in float64: they do not depend on
        # where the blocks start, and fewer, taller blocks fill fewer window rows anew
        # (KITTI's grey levels from colour fail the test in the first row).
        block = max(block, h // (NCC_EXACT_TASKS * n_threads))  # (numba's get_num_threads here: no caching)
    n_blocks = (h + block - 1) // block
    for b in prange(n_blocks):
        vb0 = b * block
        vb1 = min(h, vb0 + block)
        acc_lo, acc_hi = _block_hull(index, vb0, vb1, n_disp, r)
        # acc[u, d]: column sum over the window rows of L(y, u) R(y, u - d)
        acc = np.zeros((w, n_disp), np.float64)
        win = np.zeros(n_disp, np.float64)
        ml = np.zeros(w, np.float64)  # window means and variances per column (left, right)
        vl = np.zeros(w, np.float64)
        mr = np.zeros(w, np.float64)
        vr = np.zeros(w, np.float64)
        rev = np.empty((2, w), np.float64)  # mr, vr reversed (_reversed_stats)
        # per cell of a row: NCC numerator, denominator^2, rounded to float32 as they are
        # stored (ncc_finish rounds them first: the same bits, half the bytes of float64)
        num = np.zeros(max_row, np.float32)
        den = np.zeros(max_row, np.float32)
        r_in = np.empty(w, np.float64)  # a right row reversed, float64 (_add_row_products)
        r_out = np.empty(w, np.float64)
        for y in range(max(0, vb0 - r), min(h - 1, vb0 + r) + 1):
            _add_row_products(acc, acc_lo, acc_hi, left, right, y, -1, r_in, r_out)
        for v in range(vb0, vb1):
            if v > vb0:
                y_in = v + r if v + r <= h - 1 else -1
                y_out = v - r - 1 if v - r - 1 >= 0 else -1
                if y_in >= 0 or y_out >= 0:
                    _add_row_products(acc, acc_lo, acc_hi, left, right, y_in, y_out, r_in, r_out)
            _ncc_row(cost, index, v, acc, win, ml, vl, mr, vr, rev, num, den, ii_l, ii_ll, ii_r, ii_rr, h, w, r,
                     min_variance)
    return cost


@njit(cache=True, error_model="numpy")
def _block_hull(index, vb0, vb1, n_disp, r):
    """``(acc_lo, acc_hi)``, int64 (W,): per column u the hull of the bands of rows
    vb0 .. vb1 - 1 over the columns within r of u (every disparity some window over u
    needs), cut at u + 1 (d > u: the right pixel is outside the image).

    Branch-free over the bands, then one pass per column offset over contiguous columns
    (vectorised) instead of a 2r + 1 loop per column; min and max are exact, so the
    hull is the same.
    """
    w = index.shape[1]
    col_lo = np.full(w, n_disp, np.int64)
    col_hi = np.zeros(w, np.int64)
    for v in range(vb0, vb1):  # row by row, index in memory order
        for u in range(w):
            lo = np.int64(index[v, u, 1])
            hi = np.int64(index[v, u, 2])
            empty = hi <= lo
            col_lo[u] = min(col_lo[u], n_disp if empty else lo)
            col_hi[u] = max(col_hi[u], 0 if empty else hi)
    acc_lo = np.full(w, n_disp, np.int64)
    acc_hi = np.zeros(w, np.int64)
    for k in range(-r, r + 1):  # column u + k, for the u that have it
        for u in range(max(0, -k), min(w, w - k)):
            acc_lo[UINT(u)] = min(acc_lo[UINT(u)], col_lo[UINT(u + k)])
            acc_hi[UINT(u)] = max(acc_hi[UINT(u)], col_hi[UINT(u + k)])
    for u in range(w):
        acc_hi[u] = min(acc_hi[u], u + 1)
    return acc_lo, acc_hi


@njit(cache=True, error_model="numpy")
def _reversed_row(img, y, out):
    """``out[k] = img[y, w - 1 - k]`` as float64."""
    w = out.shape[0]
    src = img[y]
    for k in range(w):
        out[k] = np.float64(src[w - 1 - k])


@njit(cache=True, error_model="numpy")
def _add_row_products(acc, acc_lo, acc_hi, left, right, y_in, y_out, r_in, r_out):
    """acc[u, d] += L(y_in, u) R(y_in, u - d), then acc[u, d] -= L(y_out, u) R(y_out, u - d),
    for every u and acc_lo[u] <= d < acc_hi[u]; a row < 0 is left out.

    One pass over acc for the row entering the window and the row leaving it, each cell
    rounded after each of the two terms as two passes would (``(a + x) + (-y)``, no
    fused multiply-add), so the sums are the same bits.  The right rows are read
    reversed (``R(y, u - d)`` with d rising), so they are first copied reversed into
    ``r_in``, ``r_out`` and both operands run forward (vectorises).
    """
    w = acc.shape[0]
    if y_in >= 0:
        _reversed_row(right, y_in, r_in)
    if y_out >= 0:
        _reversed_row(right, y_out, r_out)
    acc_w = acc.shape[1]
    accf = acc.reshape(-1)  # flat, unsigned subscripts: as in _ncc_row
    for u in range(w):
        lo = acc_lo[u]
        n = acc_hi[u] - lo
        if n <= 0:
            continue
        o = u * acc_w + lo  # acc[u, lo] in accf
        k = w - 1 - u + lo  # R(y, u - lo - i) = r_in[k + i]
        if y_out < 0:
            a = np.float64(left[y_in, u])
            for i in range(n):
                accf[UINT(o + i)] += a * r_in[UINT(k + i)]
        elif y_in < 0:
            b = -np.float64(left[y_out, u])
            for i in range(n):
                accf[UINT(o + i)] += b * r_out[UINT(k + i)]
        else:
            a = np.float64(left[y_in, u])
            b = -np.float64(left[y_out, u])
            for i in range(n):
                accf[UINT(o + i)] = (accf[UINT(o + i)] + a * r_in[UINT(k + i)]) + b * r_out[UINT(k + i)]


@njit(cache=True, error_model="numpy")
def _window_stats(ii, ii2, v0, v1, r, inv, mean, var):
    """Mean and variance of the unclipped windows (columns c - r .. c + r, rows v0 .. v1)
    of one image, for every column c with such a window: ``mean[c], var[c]``.

    The box sums are :func:`_box_sum`'s expression ``ii[r1+1, c1+1] - ii[r0, c1+1] -
    ii[r1+1, c0] + ii[r0, c0]`` and the moments :func:`pixel.ncc_cost`'s (``s inv``,
    ``ss inv - m m``), so the values are bit for bit those the formula computed per
    cell; written over slices (non-negative subscripts) the loop vectorises (scalar
    per-column box sums take a third of the NCC time).
    """
    m = ii.shape[1] - 1 - 2 * r  # columns with an unclipped window
    if m <= 0:
        return
    a1 = ii[v1 + 1, 2 * r + 1:2 * r + 1 + m]
    b1 = ii[v0, 2 * r + 1:2 * r + 1 + m]
    c1 = ii[v1 + 1, 0:m]
    d1 = ii[v0, 0:m]
    a2 = ii2[v1 + 1, 2 * r + 1:2 * r + 1 + m]
    b2 = ii2[v0, 2 * r + 1:2 * r + 1 + m]
    c2 = ii2[v1 + 1, 0:m]
    d2 = ii2[v0, 0:m]
    mean_c = mean[r:r + m]
    var_c = var[r:r + m]
    for i in range(m):
        s = a1[i] - b1[i] - c1[i] + d1[i]
        ss = a2[i] - b2[i] - c2[i] + d2[i]
        mu = s * inv
        mean_c[i] = mu
        var_c[i] = ss * inv - mu * mu


@njit(cache=True, error_model="numpy")
def _unclipped_end(u, lo, hi, r, w):
    """``d_fast``: the band's disparities ``lo <= d < d_fast`` of pixel u have neither
    window clipped (left window inside the image, right window at u - d too)."""
    d_fast = min(hi, u - r + 1) if u + r <= w - 1 else lo
    return max(d_fast, lo)


@njit(cache=True, error_model="numpy")
def _ncc_row(cost, index, v, acc, win, ml, vl, mr, vr, rev, num, den, ii_l, ii_ll, ii_r, ii_rr, h, w, r, min_variance):
    """Costs of the bands of row v from the window-row column sums ``acc``.

    ``win[d]`` is the window sum of ``acc`` over the columns u - r .. u + r; it slides
    from column to column while the band stays the same and the window is not clipped,
    and is summed afresh otherwise.  The window means and variances of unclipped windows
    are computed once per column (:func:`_window_stats`), not once per cell, the right
    image's also reversed (:func:`_reversed_stats`).  The cells of unclipped windows are
    done in two passes: the first leaves each cell's numerator ``slr / n - m_l m_r`` and
    ``v_l v_r`` (NaN or -1: flat) in ``num``, ``den``; the second
    (:func:`_costs_from_terms`) runs over the row's contiguous cells (a band of 5-7 cells is
    shorter than a vector; a row is not).  Operation for operation this is
    :func:`pixel.ncc_cost`: the same bits.  Clipped windows (the image borders) get their
    ``num``, ``den`` from their own box sums (:func:`_clipped_terms`)."""
    v0 = max(0, v - r)
    v1 = min(h - 1, v + r)
    inv = 1.0 / ((v1 - v0 + 1) * (2 * r + 1))
    _window_stats(ii_l, ii_ll, v0, v1, r, inv, ml, vl)
    _window_stats(ii_r, ii_rr, v0, v1, r, inv, mr, vr)
    mrr, vrr = _reversed_stats(mr, vr, rev, min_variance)
    start = index[v, 0, 0] + index[v, 0, 1]  # the row's cells: cost[start:start + n_row]
    n_row = 0
    clipped = False
    run_lo = 0
    run_hi = -1  # no running window sum yet
    acc_w = acc.shape[1]
    accf = acc.reshape(-1)
    for u in range(w):
        off = index[v, u, 0]
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        n_row += max(hi - lo, 0)
        d_fast = _unclipped_end(u, lo, hi, r, w)
        if d_fast < hi:
            clipped = True
        if d_fast > lo:
            # flat subscripts cast to unsigned (known >= 0): no negative-index wraparound,
            # so the loops vectorise, and no slice objects per pixel, whose set-up cost
            # more than the 5-40 cells of a band
            n = d_fast - lo
            ea = (u + r) * acc_w + lo  # acc[u + r, lo] in accf
            la = (u - r - 1) * acc_w + lo
            o = off + lo - start
            k = w - 1 - u + lo  # the right window of d = lo + i sits at column u - d: rev[:, k + i]
            ml_u = ml[u]
            vl_u = vl[u] if vl[u] > min_variance else np.nan  # a flat window: NaN, as the right's
            if run_lo == lo and run_hi == d_fast and u > r and n <= NCC_NARROW:
                # a narrow band: slide and the cell's terms in one loop, the same operations
                # (two loops over 5-8 cells barely vectorise, and one costs less; on wide
                # bands one loop is slower)
                for i in range(n):  # slide by one column
                    t = win[UINT(lo + i)] + (accf[UINT(ea + i)] - accf[UINT(la + i)])
                    win[UINT(lo + i)] = t
                    num[UINT(o + i)] = t * inv - ml_u * mrr[UINT(k + i)]
                    den[UINT(o + i)] = vl_u * vrr[UINT(k + i)]
                continue
            if run_lo == lo and run_hi == d_fast and u > r:
                for i in range(n):  # slide by one column
                    win[UINT(lo + i)] += accf[UINT(ea + i)] - accf[UINT(la + i)]
            else:
                for i in range(n):
                    win[UINT(lo + i)] = 0.0
                for c in range(u - r, u + r + 1):
                    ca = c * acc_w + lo
                    for i in range(n):
                        win[UINT(lo + i)] += accf[UINT(ca + i)]
            run_lo = lo
            run_hi = d_fast
            for i in range(n):
                num[UINT(o + i)] = win[UINT(lo + i)] * inv - ml_u * mrr[UINT(k + i)]
                den[UINT(o + i)] = vl_u * vrr[UINT(k + i)]  # no select per cell
        else:
            run_hi = -1
    if clipped:
        _clipped_terms(index, v, acc, num, den, start, ii_l, ii_ll, ii_r, ii_rr, v0, v1, w, r, min_variance)
    _costs_from_terms(cost[start:start + n_row], num, den)


@njit(cache=True, error_model="numpy")
def _reversed_stats(mr, vr, rev, min_variance):
    """``(rev[0], rev[1])``: ``mr`` and ``vr`` reversed (``rev[:, w - 1 - x]`` holds column
    x), a flat window's variance (<= ``min_variance``) replaced by NaN.

    A pixel's cells read the right windows at columns u - d with d rising: reversed,
    they run forward, without a shuffle per vector; and the flat test needs no select
    per cell: a product with NaN is NaN, which :func:`_costs_from_terms` rejects (``den
    >= 0`` fails) as it rejects the -1 of a flat window, so the costs are the same bits.
    """
    w = mr.shape[0]
    mrr = rev[0]
    vrr = rev[1]
    for k in range(w):
        x = w - 1 - k
        mrr[k] = mr[x]
        vrr[k] = vr[x] if vr[x] > min_variance else np.nan
    return mrr, vrr


@njit(cache=True, error_model="numpy", inline="always")
def _costs_from_terms(out, num, den):
    """The second pass of :func:`_ncc_row`: ``(1 - NCC) / 2`` of the row's cells from their
    numerators and variance products, one loop over the contiguous cells."""
    for j in range(out.shape[0]):
        den_j = den[j]
        out[j] = _ncc_finish(num[j], den_j) if den_j >= 0.0 else F32_ONE  # a flat window: NCC undefined


@njit(cache=True, error_model="numpy")
def _clipped_terms(index, v, acc, num, den, start, ii_l, ii_ll, ii_r, ii_rr, v0, v1, w, r, min_variance):
    """``num``, ``den`` of row v's cells of clipped windows (the image borders), for
    :func:`_ncc_row`'s pass over the row: den -1 where u - d < 0 or a window is flat.

    Operation for operation :func:`pixel.ncc_window_cost` up to the square root and the
    division, which the row's pass does for them too (done per cell, serially, after that
    pass, these cells take longer).  Each window sum of L*R is summed up from 0 over its
    columns: summing column by column over a pixel's cells (one vector loop per column) is
    slower on these 5-20 cell bands.
    """
    n_disp = acc.shape[1]
    # Where the window starts at column d (c0 = d: clipped by the right image's edge),
    # the sum over columns d .. c1 is the one over d .. c1' < c1 of a pixel before it
    # (c1 grows with u) continued: the same additions in the same order, so it is kept
    # per disparity and continued instead of summed afresh.
    run_c1 = np.full(n_disp, -1, np.int64)  # the last column summed into run_slr[d], -1: none
    run_slr = np.empty(n_disp, np.float64)
    for u in range(w):
        off = index[v, u, 0] - start
        lo = index[v, u, 1]
        hi = index[v, u, 2]
        c1 = min(u + r, w - 1)
        for d in range(_unclipped_end(u, lo, hi, r, w), hi):
            if u - d < 0:
                den[off + d] = -1.0
                continue
            c0 = max(u - r, d)
            if c0 == d:
                c = run_c1[d] + 1
                slr = run_slr[d]
                if c == 0:
                    c = d
                    slr = 0.0
                for c in range(c, c1 + 1):
                    slr += acc[c, d]
                run_c1[d] = c1
                run_slr[d] = slr
            else:
                slr = 0.0
                for c in range(c0, c1 + 1):
                    slr += acc[c, d]
            inv = 1.0 / ((v1 - v0 + 1) * (c1 - c0 + 1))
            ml = _box_sum(ii_l, v0, c0, v1, c1) * inv
            mr = _box_sum(ii_r, v0, c0 - d, v1, c1 - d) * inv
            vl = _box_sum(ii_ll, v0, c0, v1, c1) * inv - ml * ml
            vr = _box_sum(ii_rr, v0, c0 - d, v1, c1 - d) * inv - mr * mr
            num[off + d] = slr * inv - ml * mr
            den[off + d] = vl * vr if (vl > min_variance and vr > min_variance) else -1.0


def cosine_cost_volume(fl, fr, nl, nr, max_disparity, index=None):
    """Deep-feature cost volume ``(1 - cos) / 2`` of one level (docs/design.md, step 2, features).

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.cosine_cost_volume`.
    """
    h, w = nl.shape
    n_disp = int(max_disparity) + 1
    dense = index is None
    if dense:
        index = dense_index(h, w, n_disp)
    n_cells = int(index[-1, -1, 0]) + int(index[-1, -1, 2])
    flat = _cosine_banded(fl, fr, nl, nr, index, n_cells)
    return pack_volume(flat, index, n_disp, (h, w, n_disp) if dense else None)


@njit(parallel=True, cache=True, error_model="numpy")
def _cosine_banded(fl, fr, nl, nr, index, n_cells):
    h, w = nl.shape
    cost = np.empty(n_cells, np.float32)
    for v in prange(h):
        for u in range(w):
            off = index[v, u, 0]
            for d in range(index[v, u, 1], index[v, u, 2]):
                cost[off + d] = _cosine_cost(fl, fr, nl, nr, v, u, d)
    return cost


def invalidate_out_of_view(cost):
    """Set every cell whose right pixel u - d is outside the image back to 1, in place.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.invalidate_out_of_view`.
    """
    flat, index, n_disp, _ = unpack_volume(cost)
    _invalidate(flat, index, int(n_disp))
    return cost


@njit(parallel=True, cache=True, error_model="numpy")
def _invalidate(cost, index, n_disp):
    h, w, _ = index.shape
    for v in prange(h):
        for u in range(min(w, n_disp)):  # d > u only where u < n_disp - 1
            off = index[v, u, 0]
            for d in range(max(index[v, u, 1], u + 1), index[v, u, 2]):
                cost[UINT(off + d)] = 1.0  # unsigned: no wraparound test, the loop vectorises
