"""CPU drivers of the cost aggregation (pipeline step 3): the RBF weights, the
recursive bilateral filter's passes over banded rows, the plain bilateral filter.
The row machinery lives in :mod:`.cpu_rows` (scalar) and :mod:`.cpu_vector` (vector
intrinsics).  The contract: :mod:`d3cli.kernels.backend`."""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from .cpu_rows import _rbf_forward_row, covered_bands, rbf_normalise_row
from .cpu_vector import RBF_MAX_LANES, _rbf_row, _run_ends
from ..cpu_common import on_grid, ops, pack_volume, row_layout, unpack_volume
from ..intrinsics import store_fence


_rbf_weight = ops.rbf_weight


# ----------------------------------------------------------------------------- aggregation (step 3)
#: Grey-level steps 4^-k, k < this, that rbf_weights recognises (the first four pyramid
#: levels of an 8-bit image: 2x2 means of 2x2 means of integers).
GREY_STEPS = 4


@njit(cache=True, error_model="numpy")
def grey_scale(img):
    """``s`` in {1, 4, 16, 64} when every grey level is in [0, 255] and a multiple of
    1 / s (the smallest such s), else 0.

    Level k of the pyramid of an 8-bit image holds exact multiples of 4^-(k-1) (2x2
    means, exact in float32), so a pixel and its neighbour differ by one of 255 s + 1
    values.
    """
    scale = 1
    for k in range(GREY_STEPS):
        if on_grid(img, scale, 0):
            return scale
        scale *= 4
    return 0


@njit(parallel=True, cache=True, error_model="numpy")
def rbf_weights(img, sigma_space, sigma_color):
    """Normalised 3x3 bilateral weights per pixel (paper eq. 3), computed once per level.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.rbf_weights`.
    """
    h, w = img.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    # K(p, q) = K(q, p): the kernel towards the four "forward" neighbours (slots 5..8:
    # right, below-left, below, below-right) is computed once and read back from the
    # neighbour for the mirrored slot (8 - k): half the exp calls, the same values.
    # Row by row within a block of rows, the forward kernels of a row and of the row
    # above in a two-row ring (nothing zero-filled: the kernels towards neighbours
    # outside the image are never read).  A row's sum, its quotients (through the
    # reciprocal, checked exact) and its float32 staging in one vectorised pass instead
    # of copies of the kernels, nine exact divisions per pixel and a staging pass per
    # slot, and the table index from float32 differences; the same bits.
    centre = _rbf_weight(0, 0, 0.0, 0.0, inv_ss2, inv_sc2)
    # Grey levels that are all multiples of 1/s in 0..255 (an 8-bit image: s = 1 at full
    # resolution, 4, 16, 64 at the next levels) have only 255 s + 1 differences
    # |i_p - i_q|: the kernel is read from a table made with the same expression (the
    # difference and the table's argument are the same float64), so the values are the
    # same, without an exp per neighbour.  The table is built when it needs fewer exp
    # calls than the image (level 2 of a 720p pair: 2042 instead of 921,600); other
    # images compute the kernel.
    scale = grey_scale(img)
    n_lut = 255 * scale + 1
    grey8 = scale > 0 and 2 * n_lut < 4 * h * w
    lut = np.empty((2, n_lut if grey8 else 1), np.float64)  # row 0: axis neighbours, row 1: diagonal ones
    if grey8:
        for i in range(n_lut):
            lut[0, i] = _rbf_weight(0, 1, np.float64(i) / scale, 0.0, inv_ss2, inv_sc2)
            lut[1, i] = _rbf_weight(1, 1, np.float64(i) / scale, 0.0, inv_ss2, inv_sc2)
    weights = np.empty((h, w, 9), np.float32)
    block = 32
    n_blocks = (h + block - 1) // block
    for b in prange(n_blocks):
        vb0 = b * block
        vb1 = min(h, vb0 + block)
        # forward kernels of two rows (slot-major: a row of one slot is contiguous), the
        # row above the block first (its slots towards the block only)
        ring = np.empty((2, 4, w), np.float64)
        stage = np.empty((9, w), np.float32)
        if vb0 > 0:
            _rbf_forward_row(ring[(vb0 - 1) & 1], img, vb0 - 1, 1, 4, lut, scale if grey8 else 0, inv_ss2, inv_sc2)
        for v in range(vb0, vb1):
            cur = ring[v & 1]
            _rbf_forward_row(cur, img, v, 0, 4 if v + 1 < h else 1, lut, scale if grey8 else 0, inv_ss2, inv_sc2)
            rbf_normalise_row(weights[v], ring[(v - 1) & 1], cur, centre, v > 0, v + 1 < h, stage)
        store_fence()  # the block's streaming stores done before the task ends
    return weights


@njit(parallel=True, cache=True, error_model="numpy")
def rbf_passes(cost, index, covered, weights, row_start, n_tasks, max_row, t_max):
    """``t_max`` 3x3 passes of eq. 2, in place, temporally blocked.

    The rows are cut into ``n_tasks`` strips, one task each.  A task runs all passes
    over its strip as a wavefront: at step t it reads input row t + 1 and computes row
    t of pass 1, row t - 1 of pass 2, ..., row t - t_max + 1 of the last pass, which goes
    straight into the volume.  Each pass keeps its last three rows in a ring (the rows
    the next pass reads), so a row of the volume and of the weights is read from memory
    once for all passes instead of once per pass, and the rings stay in cache.  Pass p
    also computes the ``t_max - p`` rows beyond each end of the strip that the later
    passes need (``t_max (t_max - 1)`` extra rows per strip: few strips keep that small);
    the input rows there belong to the neighbouring tasks, which overwrite them, so
    their originals are copied before any task starts.  Every row of every pass is
    computed by :func:`_rbf_row` from the same three rows as pass-by-pass filtering
    would, so the result is the same, bit for bit (``tests/kernels``: against the NumPy
    reference and one pass at a time).
    """
    h = index.shape[0]
    t = max(1, t_max)
    strip = (h + n_tasks - 1) // n_tasks
    n_strips = (h + strip - 1) // strip
    edges = np.empty((n_strips, 2 * t, max_row), np.float32)  # t rows above, t below
    run_end = np.empty(covered.shape, np.int32)
    for s in prange(n_strips):
        s0 = s * strip
        s1 = min(h, s0 + strip)
        for v in range(s0, s1):
            _run_ends(run_end[v], covered[v], index[v])
        for k in range(t):
            y = s0 - t + k
            if y >= 0:
                edges[s, k, :row_start[y + 1] - row_start[y]] = cost[row_start[y]:row_start[y + 1]]
            y = s1 + k
            if y < h:
                edges[s, t + k, :row_start[y + 1] - row_start[y]] = cost[row_start[y]:row_start[y + 1]]
    for s in prange(n_strips):
        s0 = s * strip
        s1 = min(h, s0 + strip)
        # level 0: input rows; level p: rows of pass p; row y of a level at slot y % 3;
        # zeros after the last slot for the blocks of _rbf_run that read past it
        ring = np.zeros(t * 3 * max_row + RBF_MAX_LANES, np.float32)
        y_first = max(0, s0 - t)
        y_last = min(h, s1 + t)
        for step in range(y_first - 1, s1 + t - 1):
            y = step + 1
            if y_first <= y < y_last:
                n = row_start[y + 1] - row_start[y]
                base = y % 3 * max_row
                if y < s0:
                    ring[base:base + n] = edges[s, y - (s0 - t), :n]
                elif y >= s1:
                    ring[base:base + n] = edges[s, t + y - s1, :n]
                else:  # not overwritten yet: the last pass writes row y at a later step
                    ring[base:base + n] = cost[row_start[y]:row_start[y + 1]]
            for p in range(1, t + 1):
                y = step - (p - 1)
                if y < max(0, s0 - (t - p)) or y >= min(h, s1 + (t - p)):
                    continue
                src = (p - 1) * 3 * max_row
                ra = src + max(y - 1, 0) % 3 * max_row
                rh = src + y % 3 * max_row
                rb = src + min(y + 1, h - 1) % 3 * max_row
                if p == t:
                    _rbf_row(cost, 0, y, ring, ra, rh, rb, row_start, index, covered, run_end, weights)
                else:
                    dst = p * 3 * max_row + y % 3 * max_row
                    _rbf_row(ring, dst - row_start[y], y, ring, ra, rh, rb, row_start, index, covered, run_end, weights)


#: Strips (tasks) per thread of the blocked RBF: two balance the threads, more repeat
#: the halo rows of the passes (2 per thread: 0.054 s, 8: 0.058 s on the road-full volume).
RBF_TASKS_PER_THREAD = 2


def rbf_filter(cost, weights, t_max, overwrite_input=False):
    """Recursive bilateral filtering: ``t_max`` passes of the 3x3 kernel (paper eq. 2).

    ``overwrite_input`` filters ``cost`` itself: one volume at the peak instead of two.

    The passes run in place, row by row and all passes at once (:func:`rbf_passes`),
    so the filter needs one volume and a few row buffers.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.rbf_filter`.
    """
    flat, index, n_disp, dense_shape = unpack_volume(cost)
    work = flat if overwrite_input else flat.copy()
    if t_max == 0 or work.size == 0:
        return pack_volume(work, index, n_disp, dense_shape)
    row_start, max_row = row_layout(index)
    covered = covered_bands(index)
    n_tasks = RBF_TASKS_PER_THREAD * numba.get_num_threads()
    rbf_passes(work, index, covered, weights, row_start, n_tasks, max_row, int(t_max))
    return pack_volume(work, index, n_disp, dense_shape)


def bilateral_filter(cost, img, radius, sigma_space, sigma_color):
    """One pass of a plain (2 radius + 1)^2 bilateral filter over every disparity slice.

    The contract (arguments, shapes, results): :meth:`d3cli.kernels.backend.Backend.bilateral_filter`.
    """
    flat, index, n_disp, dense_shape = unpack_volume(cost)
    max_band = max(1, int((index[:, :, 2] - index[:, :, 1]).max()))
    out = _bilateral(flat, index, img, int(radius), float(sigma_space), float(sigma_color), max_band)
    return pack_volume(out, index, n_disp, dense_shape)


@njit(parallel=True, cache=True, error_model="numpy")
def _bilateral(cost, index, img, radius, sigma_space, sigma_color, max_band):
    h, w, _ = index.shape
    inv_ss2 = 1.0 / (sigma_space * sigma_space)
    inv_sc2 = 1.0 / (sigma_color * sigma_color)
    out = np.empty_like(cost)
    for v in prange(h):
        acc = np.empty(max_band, np.float64)
        for u in range(w):
            off = index[v, u, 0]
            lo = index[v, u, 1]
            hi = index[v, u, 2]
            for i in range(hi - lo):
                acc[i] = 0.0
            total = 0.0
            for dy in range(-radius, radius + 1):
                y = v + dy
                if y < 0 or y >= h:
                    continue
                for dx in range(-radius, radius + 1):
                    x = u + dx
                    if x < 0 or x >= w:
                        continue
                    wk = _rbf_weight(dy, dx, np.float64(img[v, u]), np.float64(img[y, x]), inv_ss2, inv_sc2)
                    total += wk
                    q_off = index[y, x, 0]
                    q_lo = index[y, x, 1]
                    q_hi = index[y, x, 2]
                    for d in range(lo, hi):
                        if q_lo <= d < q_hi:
                            acc[d - lo] += wk * cost[q_off + d]
                        else:
                            acc[d - lo] += wk * cost[off + d]
            for d in range(lo, hi):
                out[off + d] = acc[d - lo] / total
    return out
