"""The scalar row machinery of the CPU recursive filter: the forward row of the
weights, one pixel's recursion and normalisation, the banded row layout."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import compile_cache as _compile_cache  # noqa: F401  (chooses the numba cache folder first)
from ..cpu_common import ops
from ..intrinsics import store_nt
from ..pixel import UINT


_rbf_weight = ops.rbf_weight


@njit(cache=True, error_model="numpy")
def _rbf_forward_row(fwd, img, v, j0, j1, lut, scale, inv_ss2, inv_sc2):
    """``fwd[j, u]``, j0 <= j < j1: the kernel from pixel (u, v) towards its forward
    neighbour (slot 5 + j: right, below-left, below, below-right), for the u whose
    neighbour is in the image (the others are never read).  From the table ``lut`` when
    ``scale`` > 0 (grey levels multiples of 1 / scale), else from the exp."""
    w = img.shape[1]
    ip = img[v]
    for j in range(j0, j1):
        k = 5 + j
        dy = k // 3 - 1
        dx = k % 3 - 1
        iq = img[v + dy]
        dst = fwd[j]
        lo = max(0, -dx)
        hi = min(w, w - dx)
        if scale > 0:
            table = lut[dy * dx * dx]
            # float32 is exact here too (multiples of 1 / scale up to 255: 14 bits), the
            # same index as the float64 difference, on twice the lanes
            sc = np.float32(scale)
            for u in range(lo, hi):
                diff = abs(ip[UINT(u)] - iq[UINT(u + dx)]) * sc
                dst[UINT(u)] = table[UINT(np.int32(diff))]
        else:
            for u in range(lo, hi):
                dst[UINT(u)] = _rbf_weight(dy, dx, np.float64(ip[UINT(u)]), np.float64(iq[UINT(u + dx)]),
                                           inv_ss2, inv_sc2)


@njit(cache=True, error_model="numpy")
def rbf_pixel(stage, up, cur, centre, has_up, has_down, u):
    """``stage[k, u]``, k < 9: pixel u's normalised weights, the exact expressions (for
    the border pixels and the rare rows that :func:`rbf_interior` leaves)."""
    w = stage.shape[1]
    left = u >= 1
    right = u + 1 < w
    r0 = up[3, u - 1] if has_up and left else 0.0
    r1 = up[2, u] if has_up else 0.0
    r2 = up[1, u + 1] if has_up and right else 0.0
    r3 = cur[0, u - 1] if left else 0.0
    r5 = cur[0, u] if right else 0.0
    r6 = cur[1, u] if has_down and left else 0.0
    r7 = cur[2, u] if has_down else 0.0
    r8 = cur[3, u] if has_down and right else 0.0
    t = 0.0
    t += r0
    t += r1
    t += r2
    t += r3
    t += centre
    t += r5
    t += r6
    t += r7
    t += r8
    stage[0, u] = np.float32(r0) / t
    stage[1, u] = np.float32(r1) / t
    stage[2, u] = np.float32(r2) / t
    stage[3, u] = np.float32(r3) / t
    stage[4, u] = np.float32(centre) / t
    stage[5, u] = np.float32(r5) / t
    stage[6, u] = np.float32(r6) / t
    stage[7, u] = np.float32(r7) / t
    stage[8, u] = np.float32(r8) / t


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_quotient(dst, u, r, rc):
    """``dst[u] = float32(float32(r) / t)`` from ``rc = 1 / t``; True where that is not
    certain (then ``dst[u]`` may differ by one float32 step).

    ``q = a rc`` is within 3 2^-53 q of the float64 quotient ``a / t`` (three roundings
    of 2^-53), so ``q (1 - 2^-50)`` and ``q (1 + 2^-50)`` (rounded) bracket it; float32
    rounding is monotonic, so when both round to the same float32, ``a / t`` rounds to
    it too.  The others (about 2^-26 of the weights: q within 2^-50 q of a float32
    rounding boundary) are reported.
    """
    q = np.float64(np.float32(r)) * rc
    lo = np.float32(q * (1.0 - 2.0 ** -50))
    hi = np.float32(q * (1.0 + 2.0 ** -50))
    dst[u] = hi
    return lo != hi


@njit(cache=True, error_model="numpy")
def rbf_interior(stage, up, cur, centre, w):
    """The weights of pixels 1..W-2 of a row with rows above and below, into ``stage``;
    the number of uncertain quotients (:func:`_rbf_quotient`): the row must then be
    redone exactly.  One division per pixel (the reciprocal of the sum) instead of nine:
    the divider is the bottleneck (two cycles per float64 lane)."""
    a0 = up[3]
    a1 = up[2]
    a2 = up[1]
    c0 = cur[0]
    b6 = cur[1]
    b7 = cur[2]
    b8 = cur[3]
    bad = 0
    for u in range(1, w - 1):
        uu = UINT(u)
        r0 = a0[uu - 1]
        r1 = a1[uu]
        r2 = a2[uu + 1]
        r3 = c0[uu - 1]
        r5 = c0[uu]
        r6 = b6[uu]
        r7 = b7[uu]
        r8 = b8[uu]
        t = r0  # 0.0 + r0: the same (r0 >= 0)
        t += r1
        t += r2
        t += r3
        t += centre
        t += r5
        t += r6
        t += r7
        t += r8
        rc = 1.0 / t
        bad += _rbf_quotient(stage[0], uu, r0, rc)
        bad += _rbf_quotient(stage[1], uu, r1, rc)
        bad += _rbf_quotient(stage[2], uu, r2, rc)
        bad += _rbf_quotient(stage[3], uu, r3, rc)
        bad += _rbf_quotient(stage[4], uu, centre, rc)
        bad += _rbf_quotient(stage[5], uu, r5, rc)
        bad += _rbf_quotient(stage[6], uu, r6, rc)
        bad += _rbf_quotient(stage[7], uu, r7, rc)
        bad += _rbf_quotient(stage[8], uu, r8, rc)
    return bad


@njit(cache=True, error_model="numpy")
def rbf_normalise_row(out, up, cur, centre, has_up, has_down, stage):
    """Row ``out`` (W, 9) of the normalised weights from the forward kernels of its own
    row (``cur``) and of the row above (``up``; ``has_up`` / ``has_down``: whether the
    rows above / below are in the image), through the slot-major ``stage`` (9, W)."""
    w = out.shape[0]
    if has_up and has_down and rbf_interior(stage, up, cur, centre, w) == 0:
        rbf_pixel(stage, up, cur, centre, has_up, has_down, 0)
        rbf_pixel(stage, up, cur, centre, has_up, has_down, w - 1)
    else:
        for u in range(w):
            rbf_pixel(stage, up, cur, centre, has_up, has_down, u)
    # Streaming stores: the weights (36 bytes a pixel, 33 MB at 720p) are read back by
    # the filter only after the rest of the level's weights, so caching them only
    # evicts the cost volume and costs a read of each line first.
    outf = out.reshape(-1)
    for u in range(w):
        for k in range(9):
            store_nt(outf, UINT(9 * u + k), stage[k, u])


@njit(parallel=True, cache=True, error_model="numpy")
def covered_bands(index):
    """uint8 (H, W) for the filter passes: 2 where the 3x3 neighbours (clamped at the
    border) all have the pixel's band, 1 where their bands contain it (every cell a pass
    reads exists), 0 elsewhere."""
    h, w, _ = index.shape
    out = np.empty((h, w), np.uint8)
    # Most pixels have the band of all eight neighbours.  Whether a pixel has the band of
    # both row neighbours is found once per pixel and reused by the rows above and below
    # (the same map).  The
    # band (lo, hi) as one int64 key, so that both tests are branch-free loops over
    # contiguous rows (vectorised); only the pixels that fail them (the border columns,
    # and about 2 % at level 0) take the test of every neighbour (the same map).
    key = np.empty((h, w), np.int64)
    same_row = np.empty((h, w), np.bool_)
    for y in prange(h):
        ky = key[y]
        sy = same_row[y]
        for u in range(w):
            ky[u] = (np.int64(index[y, u, 2]) << 32) | (np.int64(index[y, u, 1]) & 0xFFFFFFFF)
        if w > 0:
            sy[0] = False
            sy[w - 1] = False
        for u in range(1, w - 1):
            sy[u] = (ky[u - 1] == ky[u]) & (ky[u + 1] == ky[u])
    for v in prange(h):
        ym = max(v - 1, 0)
        yp = min(v + 1, h - 1)
        k0 = key[v]
        km = key[ym]
        kp = key[yp]
        s0 = same_row[v]
        sm = same_row[ym]
        sp = same_row[yp]
        ov = out[v]
        for u in range(w):
            ov[u] = np.uint8(2) * (s0[u] & sm[u] & sp[u] & (km[u] == k0[u]) & (kp[u] == k0[u]))
        for u in range(w):
            if ov[u] == 2:
                continue
            lo = index[v, u, 1]
            hi = index[v, u, 2]
            covered = 1
            same = 2
            for y in range(ym, yp + 1):
                for x in range(max(u - 1, 0), min(u + 1, w - 1) + 1):
                    if index[y, x, 1] > lo or index[y, x, 2] < hi:
                        covered = 0
                    if index[y, x, 1] != lo or index[y, x, 2] != hi:
                        same = 1
            ov[u] = covered * same
    return out


@njit(cache=True, error_model="numpy", inline="always")
def _rbf_cells(out, db, ring, offs, sb, count, weights, v, u):
    """``out[db + i]``, i < count: the nine sources ``ring[offs[k] + sb + i]`` weighted by
    ``weights[v, u, k]`` and added in slot order.  The arrays themselves and offsets, not
    slices (a slice per call costs its reference counting); unsigned subscripts, so the
    indexes need no negative-index wraparound and the loop vectorises."""
    w0 = weights[v, u, 0]
    w1 = weights[v, u, 1]
    w2 = weights[v, u, 2]
    w3 = weights[v, u, 3]
    w4 = weights[v, u, 4]
    w5 = weights[v, u, 5]
    w6 = weights[v, u, 6]
    w7 = weights[v, u, 7]
    w8 = weights[v, u, 8]
    o0, o1, o2, o3, o4, o5, o6, o7, o8 = offs
    for i in range(count):
        a = np.float32(0.0)
        a += w0 * ring[UINT(o0 + sb + i)]
        a += w1 * ring[UINT(o1 + sb + i)]
        a += w2 * ring[UINT(o2 + sb + i)]
        a += w3 * ring[UINT(o3 + sb + i)]
        a += w4 * ring[UINT(o4 + sb + i)]
        a += w5 * ring[UINT(o5 + sb + i)]
        a += w6 * ring[UINT(o6 + sb + i)]
        a += w7 * ring[UINT(o7 + sb + i)]
        a += w8 * ring[UINT(o8 + sb + i)]
        out[UINT(db + i)] = a
