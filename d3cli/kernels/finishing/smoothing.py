"""The Gaussian range smoothing of the finishing: a piecewise-linear bilateral filter.

:func:`residual_and_range` (the residual to the plane and its range), :func:`range_levels`
(which levels the pixels interpolate from), :func:`smooth_groups` (per group of levels the
range weights, their box sums and each pixel's shares) and :func:`combine_shares` (the
smoothed map), with :func:`shift_plane_f32` and :func:`clamp_negative` around them
(docs/design.md, 'Finishing').

The box sums reproduce ``cv2.boxFilter(..., normalize=False, borderType=cv2.BORDER_CONSTANT)``
on float32 as OpenCV 5.0 computes them (float64 running sums along the rows, then down the
columns; direct 3- and 5-tap sums for radius 1 and 2), and the range weights are NumPy's
float32 ``exp`` (:func:`d3cli.kernels.finishing.exp.numpy_expf`): the reference's values,
bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..pool import row_tasks, run_tasks, threads
from ..road_model import host as _road_model
from .exp import numpy_expf
from .pixel_smoothing import build as build_bodies

_F32_ONE = np.float32(1.0)
_F32_ZERO = np.float32(0.0)
_F32_INF = np.float32(np.inf)


@njit(cache=True, inline="always")
def _mul_f64(a, b):
    """``a * b`` (the CPU compiler fuses no multiply into an add: a plain product)."""
    return a * b


# the per-pixel bodies, written once for the CPU and CUDA (pixel_smoothing.py), as globals
# numba can type; inlined into the tasks' loops (which vectorise over them)
_bodies = build_bodies(njit(cache=True, inline="always", error_model="numpy"), numpy_expf, _mul_f64)
_residual_at = _bodies.residual_at
_level_position = _bodies.level_position
_range_weight = _bodies.range_weight
_level_estimate = _bodies.level_estimate
_combine_at = _bodies.combine_at
#: ``x``, or 0 where ``x < 0`` (NaN and -0 stay): the finished map's disparities are >= 0
#: (:func:`clamp_negative`, and the smoothing passes that clamp as they write).
at_least_zero = _bodies.at_least_zero


@njit(cache=True, nogil=True)
def _residual_task(task, tasks, disp, base, valid, resid, use, row_lo, row_hi, row_use):
    h, w = disp.shape
    all_valid = valid.shape[0] != h  # no map: every finite pixel
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        lo = _F32_INF
        hi = -_F32_INF
        any_use = False
        for u in range(w):
            d = disp[y, u]
            r = _residual_at(d, base[y, u])
            resid[y, u] = r
            if np.isfinite(d):
                lo = min(lo, r)
                hi = max(hi, r)
                ok = all_valid or valid[y, u]
                use[y, u] = ok
                any_use |= ok
            else:
                use[y, u] = False
        row_lo[y] = lo
        row_hi[y] = hi
        row_use[y] = any_use


def residual_and_range(disp, base, valid):
    """Residual ``disp - base`` (0 where disp is not finite), the pixels that may be
    averaged into others and the residual's finite range.

    Parameters
    ----------
    disp, base : ndarray, float32, (H, W)
    valid : ndarray, bool, (H, W), or None
        None: every finite pixel (no map to build and read).

    Returns
    -------
    resid : ndarray, float32, (H, W)
    use : ndarray, bool, (H, W)
        Valid and finite.
    row_lo, row_hi : ndarray, float32, (H,)
        Per-row minimum and maximum of the finite residuals (+inf / -inf: none).
    row_use : ndarray, bool, (H,)
        Whether the row has a pixel in ``use``.
    """
    h, w = disp.shape
    resid = np.empty((h, w), np.float32)
    use = np.empty((h, w), np.bool_)
    row_lo = np.empty(h, np.float32)
    row_hi = np.empty(h, np.float32)
    row_use = np.empty(h, np.bool_)
    if valid is None:
        valid = np.empty((0, 0), np.bool_)
    run_tasks(_residual_task, row_tasks(h), disp, base, valid, resid, use, row_lo, row_hi, row_use)
    return resid, use, row_lo, row_hi, row_use


@njit(cache=True, nogil=True, error_model="numpy")
def _row_levels(r_row, lo, step, top, top_plus_1, k_row, t_row):
    """:func:`_level_position` of a row of residuals into ``k_row`` and ``t_row``."""
    for u in range(r_row.shape[0]):
        k, t = _level_position(r_row[u], lo, step, top, top_plus_1)
        k_row[u] = k
        t_row[u] = t


@njit(cache=True, nogil=True, error_model="numpy")
def _range_levels_task(task, tasks, resid, lo, step, n_levels, low, up, row_used, k_row):
    h, w = resid.shape
    top = np.float32(n_levels - 2)
    top_plus_1 = np.float32(n_levels - 1)
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    k_row = k_row[task]
    for y in range(y0, y1):
        r_row = resid[y]
        for u in range(w):
            k_row[u] = _level_position(r_row[u], lo, step, top, top_plus_1)[0]
        flags = row_used[y]
        flags[:] = False
        for u in range(w):
            k = k_row[u]
            if k >= 0:
                flags[k] = True
            else:  # NaN residual: no level writes its shares
                low[y, u] = _F32_ZERO
                up[y, u] = _F32_ZERO


def range_levels(resid, lo, step, n_levels, low, up):
    """Which range levels the pixels interpolate from, per row and in all.

    The pixel's lower level is ``k0 = clip(floor((resid - lo) / step), 0, n_levels - 2)``
    (float32 arithmetic, :func:`_level_position`), its upper one ``k0 + 1``.

    Parameters
    ----------
    resid : ndarray, float32, (H, W)
    lo, step : float32
        Level k sits at ``lo + k step``.
    n_levels : int (>= 2)
    low, up : ndarray, float32, (H, W)
        The shares maps :func:`smooth_groups` fills: set to 0 here where the residual is
        NaN (no level, so no share is written there).

    Returns
    -------
    used : ndarray, bool, (n_levels,)
        Level k is the lower (k0) or the upper (k0 + 1) level of some pixel.
    row_lower : ndarray, bool, (H, n_levels)
        Row y has a pixel whose lower level is k (what :func:`smooth_groups` needs).
    """
    h, w = resid.shape
    row_used = np.empty((h, n_levels), np.bool_)
    tasks = row_tasks(h)
    run_tasks(_range_levels_task, tasks, resid, np.float32(lo), np.float32(step), int(n_levels), low, up,
              row_used, np.empty((tasks, w), np.int32))
    lower = row_used.any(axis=0)
    used = lower.copy()
    used[1:] |= lower[:-1]
    return used, row_used


@njit(cache=True, inline="always", error_model="numpy")
def _level_weights(resid, use, y, level, neg_inv2s2, radius, pad_n, pad_d, tmp):
    """Row y of a level's range weights ``w = exp(neg_inv2s2 (r - level)^2)`` (+0 where not
    used; NumPy's float32 ``exp``) and of ``w r`` (float32 product) into the float64 pad
    rows, as ``range_exponents`` + ``np.exp`` + ``cv2.boxFilter``'s row pass read them.
    Two loops (float32 weights into ``tmp``, then the float64 rows): one loop that mixes
    the float32 exp with float64 stores did not vectorise (half the speed)."""
    r_row = resid[y]
    u_row = use[y]
    w = r_row.shape[0]
    for u in range(w):
        # +0 where not used, NaN stays NaN: the reference's use * exp(x)
        tmp[u] = _range_weight(r_row[u], u_row[u], level, neg_inv2s2)
    dst_n = pad_n[radius:radius + w]
    dst_d = pad_d[radius:radius + w]
    for u in range(w):
        e = tmp[u]
        dst_d[u] = e
        dst_n[u] = e * r_row[u]


@njit(cache=True, inline="always", error_model="numpy")
def _direct_sums(pad, dst, k):
    """3- and 5-tap box sums of a padded row, left to right (``cv2.boxFilter``'s small kernels)."""
    w = dst.shape[0]
    if k == 3:
        for i in range(w):
            dst[i] = pad[i] + pad[i + 1] + pad[i + 2]
    else:
        for i in range(w):
            dst[i] = pad[i] + pad[i + 1] + pad[i + 2] + pad[i + 3] + pad[i + 4]


@njit(cache=True, inline="always", error_model="numpy")
def _running_sums_2(pa, pb, da, db, k):
    """Running box sums (window k) of two padded rows: add the entering element minus the
    leaving one, as ``cv2.boxFilter``'s row pass; two independent chains."""
    w = da.shape[0]
    sa = 0.0
    sb = 0.0
    for j in range(k):
        sa += pa[j]
        sb += pb[j]
    da[0] = sa
    db[0] = sb
    for i in range(w - 1):
        sa += pa[i + k] - pa[i]
        sb += pb[i + k] - pb[i]
        da[i + 1] = sa
        db[i + 1] = sb


@njit(cache=True, inline="always", error_model="numpy")
def _running_sums_4(pa, pb, pc, pd, da, db, dc, dd, k):
    """:func:`_running_sums_2` of four rows at once: four independent chains hide the
    latency of the float64 adds (each chain is serial, element after element)."""
    w = da.shape[0]
    sa = 0.0
    sb = 0.0
    sc = 0.0
    sd = 0.0
    for j in range(k):
        sa += pa[j]
        sb += pb[j]
        sc += pc[j]
        sd += pd[j]
    da[0] = sa
    db[0] = sb
    dc[0] = sc
    dd[0] = sd
    for i in range(w - 1):
        sa += pa[i + k] - pa[i]
        sb += pb[i + k] - pb[i]
        sc += pc[i + k] - pc[i]
        sd += pd[i + k] - pd[i]
        da[i + 1] = sa
        db[i + 1] = sb
        dc[i + 1] = sc
        dd[i + 1] = sd


@njit(cache=True, inline="always", error_model="numpy")
def _group_row_sums(resid, use, y, values, g0, active, n_active, neg_inv2s2, radius, pad, ring, tmp):
    """Box sums along row y of ``w r`` and ``w`` of the task's active levels into the ring
    slot of row y: level ``g0 + i`` (``values[g0 + i]``) for each ``i = active[j]``,
    j < n_active, in ``pad[i]`` and ``ring[i]``.  The task's buffers are
    indexed, never sliced: numba types a slice as of unknown layout, and the loops over it
    stopped vectorising."""
    k = 2 * radius + 1
    slot = y % k
    for j in range(n_active):
        i = active[j]
        _level_weights(resid, use, y, values[g0 + i], neg_inv2s2, radius, pad[i, 0], pad[i, 1], tmp)
    if k == 3 or k == 5:
        for j in range(n_active):
            i = active[j]
            _direct_sums(pad[i, 0], ring[i, 0, slot], k)
            _direct_sums(pad[i, 1], ring[i, 1, slot], k)
        return
    j = 0
    while j + 1 < n_active:  # levels in pairs: four chains
        i = active[j]
        m = active[j + 1]
        _running_sums_4(pad[i, 0], pad[i, 1], pad[m, 0], pad[m, 1],
                        ring[i, 0, slot], ring[i, 1, slot], ring[m, 0, slot], ring[m, 1, slot], k)
        j += 2
    if j < n_active:
        i = active[j]
        _running_sums_2(pad[i, 0], pad[i, 1], ring[i, 0, slot], ring[i, 1, slot], k)


@njit(cache=True, inline="always", error_model="numpy")
def _prime_group(resid, use, level_values, g0, active, ng, neg_inv2s2, radius, pads, rings, all_sums, zero, tmp):
    """The column sums of the padded rows 0 .. k-2 (image rows -radius .. radius-1) of all the
    group's levels: their row sums into the rings, added to ``all_sums`` from the top."""
    h, w = resid.shape
    k = 2 * radius + 1
    for j in range(k - 1):  # padded rows 0 .. k-2 (image rows -radius .. radius-1)
        y = j - radius
        if 0 <= y < h:
            _group_row_sums(resid, use, y, level_values, g0, active, ng, neg_inv2s2, radius, pads, rings,
                            tmp)
        for i in range(ng):
            rn = rings[i, 0, y % k] if 0 <= y < h else zero
            rd = rings[i, 1, y % k] if 0 <= y < h else zero
            sum_n = all_sums[i, 0]
            sum_d = all_sums[i, 1]
            for u in range(w):
                sum_n[u] += rn[u]
                sum_d[u] += rd[u]


@njit(cache=True, inline="always", error_model="numpy")
def _slide_sums(sum_n, sum_d, pn, pd, mn, md):
    """A level's running column sums one row down (entering row added, leaving row taken
    off) on a row that does not interpolate from the level."""
    for u in range(sum_n.shape[0]):
        sum_n[u] = (sum_n[u] + pn[u]) - mn[u]
        sum_d[u] = (sum_d[u] + pd[u]) - md[u]


@njit(cache=True, inline="always", error_model="numpy")
def _slide_and_share(sum_n, sum_d, pn, pd, mn, md, r_row, level, k_row, t_row, tmp, low_row, up_row):
    """:func:`_slide_sums` on a row that interpolates from the level: its estimate
    ``num / den`` (the residual where ``den <= 1e-6``) from the sums before the leaving
    row is taken off, and its shares where it is the pixel's lower (upper) level."""
    w = sum_n.shape[0]
    for u in range(w):
        s0n = sum_n[u] + pn[u]
        s0d = sum_d[u] + pd[u]
        sum_n[u] = s0n - mn[u]
        sum_d[u] = s0d - md[u]
        tmp[u] = _level_estimate(s0n, s0d, r_row[u])
    # the shares where this level is the pixel's lower (upper) one: conditional
    # stores (a select that wrote the old value back elsewhere would race with the
    # task of the pixel's other level)
    for u in range(w):
        kk = k_row[u]
        if kk == level:
            low_row[u] = (_F32_ONE - t_row[u]) * tmp[u]
        elif kk == level - 1:
            up_row[u] = t_row[u] * tmp[u]


@njit(cache=True, nogil=True, error_model="numpy")
def _smooth_group_task(task, tasks, resid, use, lo, step, n_levels, level_ids, level_values, bounds, last_row,
                       row_used, neg_inv2s2, radius, low, up):
    h, w = resid.shape
    g0, g1 = bounds[task], bounds[task + 1]
    ng = g1 - g0
    if ng <= 0:
        return
    k = 2 * radius + 1
    # the group's scratch, allocated per task (a few levels at a time: all levels' rings at
    # once would take 256 x 2 (2 radius + 1) W float64 on a wide-range map): per level a
    # ring of 2 radius + 1 row sums (w r and w), a zero-padded weight row, the column sums
    rings = np.empty((ng, 2, k, w))
    pads = np.zeros((ng, 2, w + 2 * radius))
    all_sums = np.zeros((ng, 2, w))
    zero = np.zeros(w)
    tmp = np.empty(w, np.float32)
    k_row = np.empty(w, np.int32)  # the output row's lower levels and weights
    t_row = np.empty(w, np.float32)
    top = np.float32(n_levels - 2)
    top_plus_1 = np.float32(n_levels - 1)
    active = np.arange(ng)
    y_end = 0
    for i in range(ng):
        y_end = max(y_end, last_row[g0 + i] + 1)
    _prime_group(resid, use, level_values, g0, active, ng, neg_inv2s2, radius, pads, rings, all_sums, zero, tmp)
    # A level's running column sums carry their float64 rounding from the top row down (as
    # cv2.boxFilter's), so every level starts at row 0; it stops after the last row that
    # interpolates from it, and only rows that do divide and store shares.
    for y in range(y_end):
        n_active = 0
        for i in range(ng):
            if last_row[g0 + i] >= y:
                active[n_active] = i
                n_active += 1
        yp = y + radius  # entering row
        ym = y - radius  # leaving row
        if yp < h:
            _group_row_sums(resid, use, yp, level_values, g0, active, n_active, neg_inv2s2, radius, pads,
                            rings, tmp)
        r_row = resid[y]
        # the levels and weights of the row, once for all the task's levels (no maps written
        # by range_levels and read back per level)
        _row_levels(r_row, lo, step, top, top_plus_1, k_row, t_row)
        for j in range(n_active):
            i = active[j]
            g = g0 + i
            pn = rings[i, 0, yp % k] if yp < h else zero
            pd = rings[i, 1, yp % k] if yp < h else zero
            mn = rings[i, 0, ym % k] if ym >= 0 else zero
            md = rings[i, 1, ym % k] if ym >= 0 else zero
            if not row_used[y, g]:
                _slide_sums(all_sums[i, 0], all_sums[i, 1], pn, pd, mn, md)
            else:
                _slide_and_share(all_sums[i, 0], all_sums[i, 1], pn, pd, mn, md, r_row, np.int32(level_ids[g]),
                                 k_row, t_row, tmp, low[y], up[y])


def _balanced_groups(cost, tasks, max_group):
    """Consecutive groups of levels, at most ``tasks`` groups of at most ``max_group`` levels,
    whose largest total ``cost`` is the least possible; the bounds of the groups (int64)."""
    n = cost.shape[0]
    total = int(cost.sum())

    def cuts(cap):
        out = [0]
        acc = 0
        for g in range(n):
            c = int(cost[g])
            if g > out[-1] and (acc + c > cap or g - out[-1] == max_group):
                out.append(g)
                acc = 0
            acc += c
        out.append(n)
        return out

    lo, hi = int(cost.max()), total
    while lo < hi:  # the least capacity that needs no more than ``tasks`` groups
        mid = (lo + hi) // 2
        if len(cuts(mid)) - 1 <= tasks:
            hi = mid
        else:
            lo = mid + 1
    return np.array(cuts(lo), np.int64)


def smooth_groups(resid, use, lo, step, n_levels, level_ids, level_values, row_lower, neg_inv2s2, radius, low, up,
                  max_group=4):
    """The box-filtered range levels of the piecewise-linear bilateral filter and each
    pixel's shares of its two levels, all in one pass per group of levels.

    A task takes a group of consecutive used levels (at most ``max_group``; at least one
    group per thread) and streams the rows through it: per entering row the range weights
    of its levels (:func:`numpy_expf`) and their row box sums (the float64 row pass of
    ``cv2.boxFilter(..., normalize=False, borderType=cv2.BORDER_CONSTANT)``, two levels'
    running sums interleaved), per output row the float64 running column sums, the
    estimate ``num / den`` (``resid`` where ``den <= 1e-6``) and, where the level is the
    pixel's lower (upper) level, the share ``(1 - t) est`` (``t est``).  No weight or
    estimate maps: a pixel's shares go to ``low`` and ``up`` (each pixel has one lower and
    one upper level, so the tasks write disjoint cells).  The values are those of the
    reference (``np.exp`` of the float32 exponents, one pair of ``cv2.boxFilter`` calls per
    level, the blend) bit for bit.

    A level is filtered down to the last row that interpolates from it (its running sums
    still start at the top: their float64 rounding is the reference's), and only rows
    that interpolate from it divide and store shares; the groups split these rows evenly
    between the tasks (levels end at very different rows: on the road pair at rows 343,
    365, 673, 719, 719 of 720).  Each task finds the levels and weights of an output row
    itself (:func:`_level_position`), and ``low``, ``up`` come without a zeroing pass
    (every pixel with a level gets both its shares written): no level, weight or zeroed
    maps.

    Parameters
    ----------
    resid : ndarray, float32, (H, W)
    use : ndarray, bool, (H, W)
    lo, step : float32
        Level k sits at ``lo + k step``.
    n_levels : int
    level_ids : ndarray, int64, (L,)
        The used levels, increasing.
    level_values : ndarray, float32, (L,)
        Their residual values ``lo + k step``.
    row_lower : ndarray, bool, (H, n_levels)
        Whether row y has a pixel whose lower level is k (from :func:`range_levels`).
    neg_inv2s2 : float32
    radius : int (>= 1)
    low, up : ndarray, float32, (H, W)
        Receive the shares of each pixel's lower and upper level; the pixels without a
        level (NaN residual) must hold 0 already (what :func:`range_levels` writes).
    max_group : int

    Returns
    -------
    low, up : ndarray, float32, (H, W)
    """
    h, w = resid.shape
    n = level_ids.shape[0]
    if n == 0:
        return low, up
    level_ids = np.ascontiguousarray(level_ids, np.int64)
    # rows that interpolate from each used level: its lower or its upper level there
    row_used = row_lower[:, level_ids]
    below = level_ids > 0
    row_used[:, below] |= row_lower[:, level_ids[below] - 1]
    row_used = np.ascontiguousarray(row_used)
    last_row = (h - 1) - np.argmax(row_used[::-1], axis=0).astype(np.int64)  # each level is used somewhere
    # the work of a level: its row passes (to radius rows past its last row) and column passes
    cost = np.minimum(last_row + 1 + int(radius), h) + last_row + 1
    tasks = min(n, max(threads(), -(-n // int(max_group))))
    bounds = _balanced_groups(cost, tasks, int(max_group))
    run_tasks(_smooth_group_task, bounds.shape[0] - 1, resid, use, np.float32(lo), np.float32(step), int(n_levels),
              level_ids, np.ascontiguousarray(level_values, np.float32), bounds, last_row, row_used,
              np.float32(neg_inv2s2), int(radius), low, up)
    return low, up


@njit(cache=True, nogil=True, error_model="numpy")
def _combine_task(task, tasks, low, up, base, disp, non_negative):
    h, w = low.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            # written over low through low itself: with a separate output argument that is
            # low, the vectorised loop's runtime overlap check fails and the scalar loop runs
            low[y, u] = _combine_at(low[y, u], up[y, u], base[y, u], disp[y, u], non_negative)


def combine_shares(low, up, base, disp, non_negative=False):
    """The smoothed map: ``(0 + low) + up + base`` where ``disp`` is finite (the blend's
    float32 sum started at zero, lower share first), else ``disp``; float32 (H, W),
    written over ``low`` (no new map, no fresh pages) and returned.  ``non_negative``:
    then :func:`clamp_negative` of it, in the same pass."""
    run_tasks(_combine_task, row_tasks(disp.shape[0]), low, up, base, disp, bool(non_negative))
    return low


_pt_shift = _road_model.pt_shift  # the road model's shift (kernels/road_model.py), a global numba can type


@njit(cache=True, nogil=True)
def _plane_task(task, tasks, a0, b1, b2, margin, out):
    h, w = out.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            out[y, u] = np.float32(_pt_shift(a0, b1, b2, margin, np.float64(y), np.float64(u)))


def shift_plane_f32(a0, b1, b2, margin, shape):
    """The road model's shift ``s(u, v)`` of every pixel (:mod:`d3cli.kernels.road_model`):
    ``((a0 + b1 v) + b2 u) - margin`` in float64, rounded once to float32; (H, W)."""
    h, w = shape
    out = np.empty((h, w), np.float32)
    run_tasks(_plane_task, row_tasks(h), float(a0), float(b1), float(b2), float(margin), out)
    return out


@njit(cache=True, nogil=True)
def _clamp_task(task, tasks, a):
    h, w = a.shape
    y0, y1 = (task * h) // tasks, ((task + 1) * h) // tasks
    for y in range(y0, y1):
        for u in range(w):
            a[y, u] = at_least_zero(a[y, u])


def clamp_negative(a):
    """``a[a < 0] = 0`` in place (NaN and -0 stay), one pass; float32 (H, W)."""
    run_tasks(_clamp_task, row_tasks(a.shape[0]), a)
    return a


#: The compiled kernels of this module (nogil, cached on disk), run by :func:`d3cli.kernels.pool.run_tasks`.
KERNELS = (_residual_task, _range_levels_task, _smooth_group_task, _combine_task, _plane_task, _clamp_task)
