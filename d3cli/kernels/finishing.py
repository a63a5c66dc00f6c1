"""Numba kernels of step 8, the finishing of the disparity map (DESIGN step 8).

CPU only: the finishing runs on the host for every backend (the CUDA backend downloads
its integer and sub-pixel maps first, see ``D3Stereo._finish``), so these kernels serve
the CPU and the CUDA pipeline alike.  ``d3cli.method.refinement`` calls them; its
docstrings say what each step means.

Every kernel gives exactly the values of the NumPy/OpenCV formulation it replaced (kept
as the reference in ``tests/kernels/test_finishing.py``): the same float32/float64
operations in the same order, bit for bit.  Parallel loops (``prange``) run over rows or
column blocks that write disjoint cells, so the results do not depend on the thread
count.  The box sums of the smoothing reproduce ``cv2.boxFilter(..., normalize=False,
borderType=cv2.BORDER_CONSTANT)`` on float32 (float64 running sums along the rows, then
down the columns; direct 3- and 5-tap sums for radius 1 and 2), and the range weights
are computed by ``np.exp`` between the kernels, because NumPy's vectorised float32
``exp`` and the C library's ``expf`` (what numba calls) differ in the last bit for about a
third of the arguments.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

# cpu.py chooses a writable numba cache folder (NUMBA_CACHE_DIR) for a read-only install
# when it is imported; the decorators below read that setting, so it must run first.
from . import cpu as _cpu  # noqa: F401,E402  (import for its side effect)

_F32_ONE = np.float32(1.0)
_F32_TWO = np.float32(2.0)
_F32_ZERO = np.float32(0.0)
_F32_INF = np.float32(np.inf)
# NumPy's float -> int64 cast of a value outside the int64 range (and of NaN) gives
# INT64_MIN on x86, which the reference's clip then maps to column 0
_INT64_LIMIT = 9.223372036854775807e18


# ----------------------------------------------------------------------------- occlusion tests
@njit(cache=True, inline="always")
def _right_column(u, d, w):
    """Column ``round(u - d)`` clipped to [0, w-1], as NumPy computes it (float64, half to even)."""
    x = np.float64(u) - d
    if not abs(x) < _INT64_LIMIT:
        return 0
    xr = np.int64(np.rint(x))
    if xr < 0:
        return 0
    if xr > w - 1:
        return w - 1
    return xr


@njit(parallel=True, cache=True)
def uniqueness_occluded(disparity, valid, tolerance):
    """Left pixels whose right-image match is claimed by a larger disparity.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W), C-contiguous
    valid : ndarray, bool, (H, W), C-contiguous
    tolerance : float
        Pixels with ``d < max_d(match) - tolerance`` are occluded.

    Returns
    -------
    ndarray, bool, (H, W)
        Per row, the largest valid disparity that maps to each right column
        ``round(u - d)`` (a scatter-max into one row buffer), then the test; NaN wins the
        maximum as in ``np.maximum``.
    """
    h, w = disparity.shape
    out = np.zeros((h, w), np.bool_)
    chunks = max(1, min(h, 16))
    best = np.empty((chunks, max(w, 1)), np.float64)  # one row buffer per chunk of rows
    for c in prange(chunks):
        row_best = best[c]
        for y in range((c * h) // chunks, ((c + 1) * h) // chunks):
            row_best[:] = -np.inf
            for u in range(w):
                if valid[y, u]:
                    d = np.float64(disparity[y, u])
                    xr = _right_column(u, d, w)
                    if d > row_best[xr] or d != d:
                        row_best[xr] = d
            for u in range(w):
                if valid[y, u]:
                    d = np.float64(disparity[y, u])
                    out[y, u] = d < row_best[_right_column(u, d, w)] - tolerance
    return out


@njit(parallel=True, cache=True)
def out_of_view_mask(disparity, valid, start):
    """Left-border pixels below the first valid disparity ``b`` at or right of ``start``.

    Parameters
    ----------
    disparity : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
    start : int
        First column searched for ``b`` (0 <= start < W); rows without one get b = -inf.

    Returns
    -------
    ndarray, bool, (H, W)
        ``valid & (u < b) & (d < b - 1)`` (``b - 1`` in float32, as NumPy computes it).
    """
    h, w = disparity.shape
    out = np.zeros((h, w), np.bool_)
    for y in prange(h):
        b = -_F32_INF
        for u in range(start, w):
            if valid[y, u]:
                b = disparity[y, u]
                break
        b_minus_1 = b - _F32_ONE
        for u in range(w):
            out[y, u] = valid[y, u] and u < b and disparity[y, u] < b_minus_1
    return out


# ----------------------------------------------------------------------------- hole filling
@njit(cache=True, inline="always")
def _np_minimum(a, b):
    """``np.minimum`` of two non-NaN values (the second when they compare equal)."""
    return a if a < b else b


@njit(parallel=True, cache=True)
def fill_rows_smaller_side(disp, valid):
    """Row-wise fill: each hole takes the smaller of the nearest valid values left and right.

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)
        Pixels to keep and to fill from (finite values only).

    Returns
    -------
    filled : ndarray, float32, (H, W)
        ``disp`` where valid, else the smaller neighbour (inf where the row has none).
    row_has : ndarray, bool, (H,)
        Whether the row has a valid pixel.
    """
    h, w = disp.shape
    filled = np.empty((h, w), np.float32)
    row_has = np.zeros(h, np.bool_)
    for y in prange(h):
        right = _F32_INF
        for u in range(w - 1, -1, -1):  # pass 1: nearest valid value at or right of u
            if valid[y, u]:
                right = disp[y, u]
            filled[y, u] = right
        left = _F32_INF
        has = False
        for u in range(w):  # pass 2: nearest to the left, the smaller of the two
            if valid[y, u]:
                left = disp[y, u]
                has = True
            else:
                filled[y, u] = _np_minimum(left, filled[y, u])
        row_has[y] = has
    return filled, row_has


@njit(parallel=True, cache=True)
def nearest_along_rows(disp, valid):
    """Values of the nearest valid pixel to the left and to the right in each row.

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W)

    Returns
    -------
    left, right : ndarray, float32, (H, W)
        The nearest valid value at or left (right) of each pixel; inf where there is none.
    """
    h, w = disp.shape
    left = np.empty((h, w), np.float32)
    right = np.empty((h, w), np.float32)
    for y in prange(h):
        value = _F32_INF
        for u in range(w):
            if valid[y, u]:
                value = disp[y, u]
            left[y, u] = value
        value = _F32_INF
        for u in range(w - 1, -1, -1):
            if valid[y, u]:
                value = disp[y, u]
            right[y, u] = value
    return left, right


@njit(parallel=True, cache=True)
def fill_inside(disp, valid, occluded, left, right, up, down):
    """Fill with the median of the finite nearest values in four directions where a hole
    is not occluded and has one, else with the smaller row neighbour.

    Parameters
    ----------
    disp : ndarray, float32, (H, W)
    valid, occluded : ndarray, bool, (H, W)
    left, right, up, down : ndarray, float32, (H, W)
        Nearest valid values in the four directions (inf: none).

    Returns
    -------
    ndarray, float32, (H, W)
        As ``np.nanmedian`` over the finite ones (mean of the middle two of an even count,
        in float32).
    """
    h, w = disp.shape
    out = np.empty((h, w), np.float32)
    vals = np.empty((h, 4), np.float32)  # one sort buffer per row
    for y in prange(h):
        buf = vals[y]
        for u in range(w):
            if valid[y, u]:
                out[y, u] = disp[y, u]
                continue
            side = _np_minimum(left[y, u], right[y, u])
            if occluded[y, u]:
                out[y, u] = side
                continue
            n = 0
            for v in (left[y, u], right[y, u], up[y, u], down[y, u]):
                if np.isfinite(v):
                    # insertion sort of at most four values
                    i = n
                    while i > 0 and buf[i - 1] > v:
                        buf[i] = buf[i - 1]
                        i -= 1
                    buf[i] = v
                    n += 1
            if n == 0:
                out[y, u] = side
            elif n % 2 == 1:
                out[y, u] = buf[n // 2]
            else:
                out[y, u] = (buf[n // 2 - 1] + buf[n // 2]) / _F32_TWO
    return out


@njit(cache=True)
def copy_nearest_rows(filled, row_has):
    """Rows without a valid pixel copy the nearest row that has one (the upper on a tie).

    Parameters
    ----------
    filled : ndarray, float32, (H, W), modified in place
    row_has : ndarray, bool, (H,)
        At least one True.
    """
    h = filled.shape[0]
    above = np.full(h, -1, np.int64)
    last = -1
    for y in range(h):
        if row_has[y]:
            last = y
        above[y] = last
    below = -1
    for y in range(h - 1, -1, -1):
        if row_has[y]:
            below = y
            continue
        up = above[y]
        if below < 0 or (up >= 0 and y - up <= below - y):
            filled[y, :] = filled[up, :]
        else:
            filled[y, :] = filled[below, :]


@njit(parallel=True, cache=True)
def keep_valid(filled, valid, other):
    """``filled`` where valid, else ``other``, in place (float32 (H, W))."""
    h, w = filled.shape
    for y in prange(h):
        for u in range(w):
            if not valid[y, u]:
                filled[y, u] = other[y, u]


# ----------------------------------------------------------------------------- smoothing
@njit(parallel=True, cache=True)
def residual_and_range(disp, base):
    """Residual ``disp - base`` (0 where disp is not finite) and its finite range.

    Returns
    -------
    resid : ndarray, float32, (H, W)
    finite : ndarray, bool, (H, W)
    row_lo, row_hi : ndarray, float32, (H,)
        Per-row minimum and maximum of the finite residuals (+inf / -inf: none).
    """
    h, w = disp.shape
    resid = np.empty((h, w), np.float32)
    finite = np.empty((h, w), np.bool_)
    row_lo = np.full(h, _F32_INF, np.float32)
    row_hi = np.full(h, -_F32_INF, np.float32)
    for y in prange(h):
        lo = _F32_INF
        hi = -_F32_INF
        for u in range(w):
            d = disp[y, u]
            if np.isfinite(d):
                r = d - base[y, u]
                resid[y, u] = r
                finite[y, u] = True
                lo = min(lo, r)
                hi = max(hi, r)
            else:
                resid[y, u] = _F32_ZERO
                finite[y, u] = False
        row_lo[y] = lo
        row_hi[y] = hi
    return resid, finite, row_lo, row_hi


@njit(parallel=True, cache=True)
def range_levels(resid, lo, step, n_levels):
    """Lower range level ``k0`` of every pixel, its interpolation weight ``t`` and which
    levels some pixel interpolates from.

    Parameters
    ----------
    resid : ndarray, float32, (H, W)
    lo, step : float32
        Level k sits at ``lo + k step``.
    n_levels : int (>= 2)

    Returns
    -------
    k0 : ndarray, int32, (H, W)
        ``clip(floor((resid - lo) / step), 0, n_levels - 2)`` (float32 arithmetic).
    t : ndarray, float32, (H, W)
        ``pos - k0`` (float64 difference rounded to float32, as NumPy promotes it).
    used : ndarray, bool, (n_levels,)
        Level k is the lower or the upper level of some pixel.
    """
    h, w = resid.shape
    k0 = np.empty((h, w), np.int32)
    t = np.empty((h, w), np.float32)
    top = np.float32(n_levels - 2)
    row_used = np.zeros((h, n_levels), np.bool_)
    for y in prange(h):
        for u in range(w):
            pos = (resid[y, u] - lo) / step
            f = np.floor(pos)
            if f < _F32_ZERO:  # np.clip: NaN stays NaN, and its int32 cast follows below
                f = _F32_ZERO
            elif f > top:
                f = top
            k = np.int32(f) if f == f else np.int32(-2147483648)
            k0[y, u] = k
            t[y, u] = np.float32(np.float64(pos) - np.float64(k))
            if 0 <= k < n_levels:
                row_used[y, k] = True
            if 0 <= k + 1 < n_levels:
                row_used[y, k + 1] = True
    used = np.zeros(n_levels, np.bool_)
    for y in range(h):
        for k in range(n_levels):
            used[k] |= row_used[y, k]
    return k0, t, used


@njit(parallel=True, cache=True)
def range_exponent(resid, level, neg_inv2s2, out):
    """``out = neg_inv2s2 * (resid - level) ** 2`` in float32 (the argument of the range
    weight; ``np.exp`` of it is taken by the caller)."""
    h, w = resid.shape
    for y in prange(h):
        for u in range(w):
            a = resid[y, u] - level
            out[y, u] = neg_inv2s2 * (a * a)


@njit(cache=True, inline="always")
def _padded(row, j, r, w):
    """Element j of the row padded by r zeros on both sides, as float64."""
    i = j - r
    if 0 <= i < w:
        return np.float64(row[i])
    return 0.0


@njit(parallel=True, cache=True)
def weighted_row_sums(weight, use, resid, radius, num_rows, den_rows, wr_buf):
    """Row box sums (window ``2 radius + 1``, zero padding) of ``w r`` and ``w``,
    ``w = weight`` where ``use`` else 0, summed as ``cv2.boxFilter``'s row pass does.

    Parameters
    ----------
    weight : ndarray, float32, (H, W)
        Range weights exp(-(r - level)^2 / (2 sigma^2)).
    use : ndarray, bool, (H, W)
    resid : ndarray, float32, (H, W)
    radius : int (>= 1)
    num_rows, den_rows : ndarray, float64, (H, W), written
    wr_buf : ndarray, float32, (H, W)
        Scratch for ``w r`` (float32 product, as in the reference).
    """
    h, w = resid.shape
    k = 2 * radius + 1
    for y in prange(h):
        wrow = weight[y]
        for u in range(w):
            if not use[y, u]:
                wrow[u] = _F32_ZERO * wrow[u]  # the reference multiplies by a 0/1 mask
            wr_buf[y, u] = wrow[u] * resid[y, u]
        nrow = wr_buf[y]
        if k == 3:  # OpenCV sums 3 and 5 taps directly, left to right
            for i in range(w):
                num_rows[y, i] = _padded(nrow, i, 1, w) + _padded(nrow, i + 1, 1, w) + _padded(nrow, i + 2, 1, w)
                den_rows[y, i] = _padded(wrow, i, 1, w) + _padded(wrow, i + 1, 1, w) + _padded(wrow, i + 2, 1, w)
        elif k == 5:
            for i in range(w):
                num_rows[y, i] = (_padded(nrow, i, 2, w) + _padded(nrow, i + 1, 2, w) + _padded(nrow, i + 2, 2, w)
                                  + _padded(nrow, i + 3, 2, w) + _padded(nrow, i + 4, 2, w))
                den_rows[y, i] = (_padded(wrow, i, 2, w) + _padded(wrow, i + 1, 2, w) + _padded(wrow, i + 2, 2, w)
                                  + _padded(wrow, i + 3, 2, w) + _padded(wrow, i + 4, 2, w))
        else:  # running sums: add the entering element minus the leaving one
            sn = 0.0
            sd = 0.0
            for j in range(k):
                sn += _padded(nrow, j, radius, w)
                sd += _padded(wrow, j, radius, w)
            num_rows[y, 0] = sn
            den_rows[y, 0] = sd
            for i in range(w - 1):
                sn += _padded(nrow, i + k, radius, w) - _padded(nrow, i, radius, w)
                sd += _padded(wrow, i + k, radius, w) - _padded(wrow, i, radius, w)
                num_rows[y, i + 1] = sn
                den_rows[y, i + 1] = sd


@njit(parallel=True, cache=True)
def blend_level(num_rows, den_rows, resid, k0, t, level_index, radius, acc, col_sums):
    """Column box sums of the row sums (``cv2.boxFilter``'s column pass, float64 running
    sums rounded to float32), the level's estimate ``num / den`` (``resid`` where
    ``den <= 1e-6``) and its share in ``acc``: ``(1 - t) est`` where the level is the
    pixel's lower one, ``t est`` where it is the upper one.

    Parameters
    ----------
    num_rows, den_rows : ndarray, float64, (H, W)
    resid : ndarray, float32, (H, W)
    k0 : ndarray, int32, (H, W)
    t : ndarray, float32, (H, W)
    level_index : int
    radius : int (>= 1)
    acc : ndarray, float32, (H, W), updated
    col_sums : ndarray, float64, (2, W)
        Scratch: running column sums; parallel column blocks own disjoint columns.
    """
    h, w = resid.shape
    k = 2 * radius + 1
    eps = np.float32(1e-6)
    block = 64
    for b in prange((w + block - 1) // block):
        u0 = b * block
        u1 = min(w, u0 + block)
        sum_n = col_sums[0]
        sum_d = col_sums[1]
        for u in range(u0, u1):
            sum_n[u] = 0.0
            sum_d[u] = 0.0
        for j in range(k - 1):  # padded rows 0 .. k-2 (image rows -radius .. radius-1)
            y = j - radius
            for u in range(u0, u1):
                if 0 <= y < h:
                    sum_n[u] += num_rows[y, u]
                    sum_d[u] += den_rows[y, u]
                else:
                    sum_n[u] += 0.0
                    sum_d[u] += 0.0
        for y in range(h):
            yp = y + radius  # entering row
            ym = y - radius  # leaving row
            for u in range(u0, u1):
                pn = num_rows[yp, u] if yp < h else 0.0
                pd = den_rows[yp, u] if yp < h else 0.0
                s0n = sum_n[u] + pn
                s0d = sum_d[u] + pd
                mn = num_rows[ym, u] if ym >= 0 else 0.0
                md = den_rows[ym, u] if ym >= 0 else 0.0
                sum_n[u] = s0n - mn
                sum_d[u] = s0d - md
                kk = k0[y, u]
                if kk == level_index or kk + 1 == level_index:
                    num = np.float32(s0n)
                    den = np.float32(s0d)
                    if den > eps:
                        est = num / den  # the reference's np.maximum(den, 1e-6) is den here
                    else:
                        est = resid[y, u]
                    if kk == level_index:
                        acc[y, u] += (_F32_ONE - t[y, u]) * est
                    else:
                        acc[y, u] += t[y, u] * est


@njit(parallel=True, cache=True)
def add_base(acc, base, finite, disp):
    """``acc + base`` where finite, else ``disp`` (float32 (H, W), new array)."""
    h, w = acc.shape
    out = np.empty((h, w), np.float32)
    for y in prange(h):
        for u in range(w):
            out[y, u] = acc[y, u] + base[y, u] if finite[y, u] else disp[y, u]
    return out
