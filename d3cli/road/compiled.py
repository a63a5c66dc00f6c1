"""Compiled loops of the road report (numba, cached beside this file like the kernels').

Each function computes what a NumPy, OpenCV or scikit-image expression of
:mod:`d3cli.road.plane`, :mod:`d3cli.road.defects`, :mod:`d3cli.road.splitting`,
:mod:`d3cli.road.morphology`, :mod:`d3cli.road.confidence`, :mod:`d3cli.road.rematch` or
:mod:`d3cli.road.outputs` computes, the same numbers, in one pass over the pixels or points
instead of a chain of whole-array temporaries: on a 1280x720 map the NumPy versions took most of the road
report's time (tests/road/test_compiled.py holds each against its reference).  The loops
release the interpreter lock, so the report's second thread (:mod:`d3cli.road.threads`)
runs beside them.  May import numpy, numba and the standard library only.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, fastmath=True)
def weighted_scatter(xs, ys, zs, inverse_tolerance, normal, offset, limit):  # pragma: no cover - compiled
    """Tukey-biweight IRLS round of the plane fit: weights ``(1 - (r / limit)^2)^2`` of the
    residuals ``r = (n . P + c) / t`` (0 beyond ``limit``), with each point's tolerance
    ``t`` given as ``inverse_tolerance`` (1 / t), their weighted centre and the weighted
    scatter matrix ``sum w (P - centre)(P - centre)^T``.

    The points are columns (``xs``, ``ys``, ``zs``, (N,) float64 each, contiguous) and the
    weight of a point beyond the limit is the clipped polynomial's 0 rather than a branch:
    the loop runs on the vector units, its sums in any order (``fastmath``: the moments
    agree with the ordered sums to about 1e-12).  One pass: the moments are summed about the
    point on the plane nearest the origin (``-c n``, a point of the road), which keeps them
    as exact as a second pass about the centre would.
    Returns (sum of weights, centre (3,), scatter (3, 3)); the centre and scatter are zeros
    when no weight is positive.
    """
    n = xs.shape[0]
    nx, ny, nz = normal[0], normal[1], normal[2]
    ox, oy, oz = -offset * nx, -offset * ny, -offset * nz
    inv_limit = 1.0 / limit
    total = 0.0
    sx = sy = sz = 0.0
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for i in range(n):
        x, y, z = xs[i], ys[i], zs[i]
        r = (x * nx + y * ny + z * nz + offset) * inverse_tolerance[i] * inv_limit
        q = max(1.0 - r * r, 0.0)
        wi = q * q
        dx, dy, dz = x - ox, y - oy, z - oz
        total += wi
        sx += wi * dx
        sy += wi * dy
        sz += wi * dz
        sxx += wi * dx * dx
        sxy += wi * dx * dy
        sxz += wi * dx * dz
        syy += wi * dy * dy
        syz += wi * dy * dz
        szz += wi * dz * dz
    centre = np.zeros(3)
    scatter = np.zeros((3, 3))
    if total <= 0.0:
        return total, centre, scatter
    mx, my, mz = sx / total, sy / total, sz / total
    centre[0], centre[1], centre[2] = mx + ox, my + oy, mz + oz
    scatter[0, 0] = sxx - total * mx * mx
    scatter[0, 1] = scatter[1, 0] = sxy - total * mx * my
    scatter[0, 2] = scatter[2, 0] = sxz - total * mx * mz
    scatter[1, 1] = syy - total * my * my
    scatter[1, 2] = scatter[2, 1] = syz - total * my * mz
    scatter[2, 2] = szz - total * mz * mz
    return total, centre, scatter


@njit(cache=True, nogil=True)
def plane_columns(points, step, min_tolerance, depth_factor):  # pragma: no cover - compiled
    """Every ``step``-th of the (N, 3) ``points`` as the plane fit's rounds read them, in one
    pass: their coordinates as contiguous float64 columns, each point's tolerance
    ``max(min_tolerance, depth_factor Z^2)`` and its inverse.
    Returns (xs, ys, zs, tolerance, inverse), (ceil(N / step),) float64 each."""
    n = (points.shape[0] + step - 1) // step
    xs = np.empty(n)
    ys = np.empty(n)
    zs = np.empty(n)
    tolerance = np.empty(n)
    inverse = np.empty(n)
    for k in range(n):
        i = k * step
        z = float(points[i, 2])
        xs[k], ys[k], zs[k] = float(points[i, 0]), float(points[i, 1]), z
        t = max(min_tolerance, z * z * depth_factor)
        tolerance[k] = t
        inverse[k] = 1.0 / t
    return xs, ys, zs, tolerance, inverse


@njit(cache=True, nogil=True)
def inlier_count(xs, ys, zs, tolerance, normal, offset):  # pragma: no cover - compiled
    """Number of points (columns ``xs``, ``ys``, ``zs``, (N,) float64 each) with
    ``|n . P + c| < tolerance``."""
    count = 0
    nx, ny, nz = normal[0], normal[1], normal[2]
    for i in range(xs.shape[0]):
        count += abs(xs[i] * nx + ys[i] * ny + zs[i] * nz + offset) < tolerance[i]
    return count


@njit(cache=True, nogil=True)
def ransac_scores(points, triples, tolerance):  # pragma: no cover - compiled
    """Inliers of the plane through each row of ``triples`` (K, 3) (indices into ``points``):
    ``|n . P + c| < tolerance`` counted over ``points`` (N, 3) float64; -1 for a degenerate
    triple (normal shorter than 1e-12).  Returns (scores (K,), normals (K, 3), offsets (K,)).

    The points are counted from contiguous columns (copied once a call): the count of every
    hypothesis then runs on the vector units."""
    k = triples.shape[0]
    scores = np.full(k, -1.0)
    normals = np.zeros((k, 3))
    offsets = np.zeros(k)
    xs = np.ascontiguousarray(points[:, 0])
    ys = np.ascontiguousarray(points[:, 1])
    zs = np.ascontiguousarray(points[:, 2])
    for j in range(k):
        a = points[triples[j, 0]]
        b = points[triples[j, 1]]
        c = points[triples[j, 2]]
        ux, uy, uz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        vx, vy, vz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        nx = uy * vz - uz * vy
        ny = uz * vx - ux * vz
        nz = ux * vy - uy * vx
        norm = np.sqrt(nx * nx + ny * ny + nz * nz)
        if norm < 1e-12:
            continue
        nx, ny, nz = nx / norm, ny / norm, nz / norm
        off = -(nx * a[0] + ny * a[1] + nz * a[2])
        count = 0
        for i in range(xs.shape[0]):
            count += abs(xs[i] * nx + ys[i] * ny + zs[i] * nz + off) < tolerance[i]
        scores[j] = count
        normals[j, 0], normals[j, 1], normals[j, 2] = nx, ny, nz
        offsets[j] = off
    return scores, normals, offsets


@njit(cache=True, nogil=True)
def height_grid(disparity, valid, f, baseline, cx, cy, doffs, normal, offset, v0=0, u0=0):  # pragma: no cover - compiled
    """Signed height above the plane ``n . P + c = 0`` of every pixel, float32 (H, W), inf
    where ``valid`` is false, the disparity is not finite or ``d + doffs <= 0``.  The arrays
    may be a window of the image whose first pixel is (``v0``, ``u0``).

    The same numbers as back-projecting with :func:`d3cli.road.pointcloud.disparity_to_points`
    (float64 arithmetic, points rounded to float32) and taking ``n . P + c`` in float64.
    """
    h, w = disparity.shape
    out = np.full((h, w), np.inf, np.float32)
    fb = f * baseline
    for v in range(h):
        for u in range(w):
            if not valid[v, u]:
                continue
            d = float(disparity[v, u]) + doffs
            if not (d > 0.0) or not np.isfinite(d):
                continue
            z = fb / d
            x = np.float32((u + u0 - cx) * z / f)
            y = np.float32((v + v0 - cy) * z / f)
            zz = np.float32(z)
            out[v, u] = float(x) * normal[0] + float(y) * normal[1] + float(zz) * normal[2] + offset
    return out


@njit(cache=True, nogil=True)
def _reconstruct_by_dilation(seed, mask):  # pragma: no cover - compiled
    """Grey reconstruction by dilation of ``seed`` under ``mask`` (8-connected; seed <= mask),
    by the hybrid algorithm (a forward and a backward raster scan, then a FIFO of the pixels
    that can still propagate, L. Vincent, IEEE TIP 1993).  Only minima and maxima of the
    inputs: the result is exactly scikit-image's ``reconstruction(seed, mask)``."""
    h, w = seed.shape
    rec = seed.copy()
    for v in range(h):
        for u in range(w):
            best = rec[v, u]
            for dv, du in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):
                y, x = v + dv, u + du
                if 0 <= y < h and 0 <= x < w and rec[y, x] > best:
                    best = rec[y, x]
            rec[v, u] = min(best, mask[v, u])
    queue = np.empty(h * w * 8 + 1, np.int64)
    head = tail = 0
    for v in range(h - 1, -1, -1):
        for u in range(w - 1, -1, -1):
            best = rec[v, u]
            for dv, du in ((1, 1), (1, 0), (1, -1), (0, 1)):
                y, x = v + dv, u + du
                if 0 <= y < h and 0 <= x < w and rec[y, x] > best:
                    best = rec[y, x]
            value = min(best, mask[v, u])
            rec[v, u] = value
            for dv, du in ((1, 1), (1, 0), (1, -1), (0, 1)):
                y, x = v + dv, u + du
                if 0 <= y < h and 0 <= x < w and rec[y, x] < value and rec[y, x] < mask[y, x]:
                    queue[tail] = v * w + u
                    tail += 1
                    break
    while head < tail:
        p = queue[head]
        head += 1
        v, u = p // w, p % w
        value = rec[v, u]
        for dv in (-1, 0, 1):
            for du in (-1, 0, 1):
                y, x = v + dv, u + du
                if (dv == 0 and du == 0) or not (0 <= y < h and 0 <= x < w):
                    continue
                if rec[y, x] < value and rec[y, x] != mask[y, x]:
                    rec[y, x] = min(value, mask[y, x])
                    if tail == queue.size:  # never in practice: each pixel rises at most once per value
                        queue = np.concatenate((queue[head:], np.empty(queue.size, np.int64)))
                        tail -= head
                        head = 0
                    queue[tail] = y * w + x
                    tail += 1
    return rec


@njit(cache=True, nogil=True)
def terrace_level(part, depth, footprint, t, step, core, lost, stack, box):  # pragma: no cover - compiled
    """One level ``t`` of the terrace search of :func:`d3cli.road.splitting._terrace_candidates`,
    in one flood fill and two passes over a box instead of a labelling and eight array
    expressions.

    Fills ``core`` (bool) with ``part & (depth > t + step / 2)`` where it is 8-connected to
    the pit ``part & (depth > t + step)`` (the labels of that mask holding a pit pixel) and
    ``lost`` (uint8) with ``part & (depth > t) & ~core``; ``stack``: int32 work space of
    shape ``(2, part.size)``.  Only the rows ``box[0]:box[1]`` and columns ``box[2]:box[3]`` are
    read and written: they must hold every pixel of ``part & (depth > t)``, and ``core``
    and ``lost`` must be 0 outside them.  ``box`` is then set to the bounding box of
    ``part & (depth > t)`` (empty: ``box[0] == box[1]``), which holds the pixels of every
    deeper level.  Returns ``(pit_area, n_core, n_core_below, lost_area)``: the areas
    (float64 sums of ``footprint``) of the pit and of ``lost``, the pixels of ``core`` and
    those of them with ``depth < t + step``."""
    v0, v1, u0, u1 = box[0], box[1], box[2], box[3]
    high = t + step
    mid = t + 0.5 * step
    pit_area = 0.0
    n = 0
    for v in range(v0, v1):
        for u in range(u0, u1):
            core[v, u] = False
            if part[v, u] and depth[v, u] > high:
                pit_area += footprint[v, u]
                core[v, u] = True
                stack[0, n] = v
                stack[1, n] = u
                n += 1
    while n > 0:  # rows and columns on the stack: no division per pixel
        n -= 1
        v, u = stack[0, n], stack[1, n]
        for y in range(max(v - 1, v0), min(v + 2, v1)):
            for x in range(max(u - 1, u0), min(u + 2, u1)):
                if not core[y, x] and part[y, x] and depth[y, x] > mid:
                    core[y, x] = True
                    stack[0, n] = y
                    stack[1, n] = x
                    n += 1
    n_core = 0
    below = 0
    lost_area = 0.0
    b0, b1, b2, b3 = v1, v0, u1, u0
    for v in range(v0, v1):
        for u in range(u0, u1):
            lost[v, u] = 0
            inside = False
            if core[v, u]:
                inside = True
                n_core += 1
                if depth[v, u] < high:
                    below += 1
            elif part[v, u] and depth[v, u] > t:
                inside = True
                lost[v, u] = 1
                lost_area += footprint[v, u]
            if inside:
                b0, b1, b2, b3 = min(b0, v), max(b1, v + 1), min(b2, u), max(b3, u + 1)
    if b0 >= b1:
        b0, b1, b2, b3 = v0, v0, u0, u0
    box[0], box[1], box[2], box[3] = b0, b1, b2, b3
    return pit_area, n_core, below, lost_area


@njit(cache=True, nogil=True)
def label_boxes(labels, n, weights):  # pragma: no cover - compiled
    """Bounding box ``(x, y, width, height)`` of each label ``1 .. n - 1`` of ``labels``, as
    the first four columns of OpenCV's ``connectedComponentsWithStats`` (whose other
    statistics, the areas and the centroids, cost more than the labelling), and the sum of
    ``weights`` (same shape as ``labels``) over each label's pixels (float64, raster order).
    The background (label 0, most of a map) is skipped: its row is zeros.
    Returns (boxes (n, 4) int64, sums (n,) float64)."""
    h, w = labels.shape
    lo_x = np.full(n, w, np.int64)
    lo_y = np.full(n, h, np.int64)
    hi_x = np.full(n, -1, np.int64)
    hi_y = np.full(n, -1, np.int64)
    sums = np.zeros(n)
    for v in range(h):
        for u in range(w):
            k = labels[v, u]
            if k == 0:
                continue
            sums[k] += weights[v, u]
            if u < lo_x[k]:
                lo_x[k] = u
            if u > hi_x[k]:
                hi_x[k] = u
            if v < lo_y[k]:
                lo_y[k] = v
            hi_y[k] = v
    boxes = np.zeros((n, 4), np.int64)
    for k in range(1, n):
        if hi_x[k] >= 0:
            boxes[k, 0], boxes[k, 1] = lo_x[k], lo_y[k]
            boxes[k, 2], boxes[k, 3] = hi_x[k] - lo_x[k] + 1, hi_y[k] - lo_y[k] + 1
    return boxes, sums


def h_maxima(image: np.ndarray, h: float) -> np.ndarray:
    """``skimage.morphology.h_maxima(image, h)`` of a float image (8-connected), the same
    uint8 result: the regional maxima of height at least ``h``, found by a compiled grey
    reconstruction instead of scikit-image's sort of every pixel."""
    image = np.asarray(image)
    if h > np.ptp(image):
        return np.zeros(image.shape, np.uint8)
    if h == 0:
        raise ValueError("h = 0 is ambiguous")
    # scikit-image's steps and types: the seed h (and a rounding allowance) below the image,
    # both in the mask's float type
    resolution = 2 * np.finfo(image.dtype).resolution * np.abs(image)
    shifted = image - h - resolution
    ftype = np.float32 if image.dtype in (np.float16, np.float32) else np.float64
    rec = _reconstruct_by_dilation(np.ascontiguousarray(shifted, ftype), np.ascontiguousarray(image, ftype))
    return ((image - rec) >= h).astype(np.uint8)


_HALF_WIDTHS: dict = {}  # (shape, kernel bytes) -> symmetric_half_widths: a few kernels, used per region


def symmetric_half_widths(kernel: np.ndarray) -> np.ndarray | None:
    """Half-width of each row of a structuring element whose rows are runs centred on its
    centre column (an ellipse, a rectangle, a cross), -1 for an empty row; None for any
    other kernel (even sides, a row that is not one centred run).  Remembered per kernel:
    the report dilates every region by the same few discs."""
    k = np.asarray(kernel) != 0
    key = (k.shape, np.packbits(k).tobytes())
    if key not in _HALF_WIDTHS:
        if len(_HALF_WIDTHS) > 256:
            _HALF_WIDTHS.clear()
        _HALF_WIDTHS[key] = _half_widths(k)
    return _HALF_WIDTHS[key]


def _half_widths(k: np.ndarray) -> np.ndarray | None:
    """:func:`symmetric_half_widths` of a bool kernel, computed."""
    if k.shape[0] % 2 == 0 or k.shape[1] % 2 == 0:
        return None
    centre = k.shape[1] // 2
    half = np.full(k.shape[0], -1, np.int64)
    for i, row in enumerate(k):
        cols = np.flatnonzero(row)
        if cols.size == 0:
            continue
        if cols[-1] - cols[0] + 1 != cols.size or cols[0] + cols[-1] != 2 * centre:
            return None
        half[i] = centre - cols[0]
    return half


@njit(cache=True, nogil=True)
def _row_distance(mask, value):  # pragma: no cover - compiled
    """Per row, the distance (columns) of each pixel to the nearest pixel equal to ``value``
    in its row; a large number where the row holds none.  Also whether each row holds one."""
    h, w = mask.shape
    big = 1 << 30
    dist = np.empty((h, w), np.int32)
    any_row = np.zeros(h, np.bool_)
    for y in range(h):
        last = -big
        for x in range(w):
            if mask[y, x] == value:
                last = x
                any_row[y] = True
            dist[y, x] = min(x - last, big)
        last = 2 * big
        for x in range(w - 1, -1, -1):
            if mask[y, x] == value:
                last = x
            d = last - x
            if d < dist[y, x]:
                dist[y, x] = d
    return dist, any_row


@njit(cache=True, nogil=True)
def dilate_rows(mask, half):  # pragma: no cover - compiled
    """``cv2.dilate(mask, kernel)`` of a bool mask (default border: nothing outside the
    image counts) for a kernel of centred row runs of half-widths ``half``
    (:func:`symmetric_half_widths`): a pixel is set when, for some kernel row, the mask's
    row it reaches has a set pixel within that half-width (a distance per row answers it).
    Only the mask's rows with a set pixel are visited."""
    h, w = mask.shape
    kh = half.shape[0]
    ay = kh // 2
    dist, filled = _row_distance(mask, True)
    out = np.zeros((h, w), np.bool_)
    for y in range(h):
        for i in range(kh):
            yy = y + i - ay
            if yy < 0 or yy >= h or not filled[yy] or half[i] < 0:
                continue
            reach = half[i]
            for x in range(w):
                out[y, x] |= dist[yy, x] <= reach
    return out


@njit(cache=True, nogil=True)
def erode_rows(mask, half):  # pragma: no cover - compiled
    """``cv2.erode(mask, kernel)`` of a bool mask (default border: what lies outside the
    image erodes nothing) for a kernel of centred row runs (:func:`dilate_rows`)."""
    h, w = mask.shape
    kh = half.shape[0]
    ay = kh // 2
    dist, holed = _row_distance(mask, False)
    out = mask.copy()
    for y in range(h):
        for i in range(kh):
            yy = y + i - ay
            if yy < 0 or yy >= h or not holed[yy] or half[i] < 0:
                continue
            reach = half[i]
            for x in range(w):
                out[y, x] &= dist[yy, x] > reach
    return out


def dilate(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``cv2.dilate(mask, kernel)`` as bool, compiled for kernels of centred row runs."""
    half = symmetric_half_widths(kernel)
    if half is None:
        import cv2

        return cv2.dilate(np.asarray(mask, np.uint8), kernel).astype(bool)
    return dilate_rows(np.ascontiguousarray(mask, np.bool_), half)


def opening(mask: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """``cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)`` as bool (erosion, then dilation)."""
    half = symmetric_half_widths(kernel)
    if half is None:
        import cv2

        return cv2.morphologyEx(np.asarray(mask, np.uint8), cv2.MORPH_OPEN, kernel).astype(bool)
    return dilate_rows(erode_rows(np.ascontiguousarray(mask, np.bool_), half), half)


@njit(cache=True, nogil=True)
def back_project(disparity, valid, f, baseline, cx, cy, doffs):  # pragma: no cover - compiled
    """float32 (N, 3) points of the pixels where ``valid`` holds, the disparity is finite and
    ``d + doffs > 0``, in image order: what :func:`d3cli.road.pointcloud.disparity_to_points`
    returns (float64 arithmetic, rounded to float32), without its index arrays."""
    h, w = disparity.shape
    n = 0
    for v in range(h):
        for u in range(w):
            d = float(disparity[v, u]) + doffs
            if valid[v, u] and d > 0.0 and np.isfinite(d):
                n += 1
    out = np.empty((n, 3), np.float32)
    fb = f * baseline
    i = 0
    for v in range(h):
        for u in range(w):
            d = float(disparity[v, u]) + doffs
            if valid[v, u] and d > 0.0 and np.isfinite(d):
                z = fb / d
                out[i, 0] = (u - cx) * z / f
                out[i, 1] = (v - cy) * z / f
                out[i, 2] = z
                i += 1
    return out


@njit(cache=True, nogil=True, fastmath=True)
def _value_range(values):  # pragma: no cover - compiled
    # values without NaN (ranks' contract): the least and greatest are exact in any order,
    # so the loop may run on the vector units
    lo = hi = float(values[0])
    for i in range(values.size):
        x = float(values[i])
        lo = min(lo, x)
        hi = max(hi, x)
    return lo, hi


@njit(cache=True, nogil=True)
def _bucket_counts(values, lo, scale, nb):  # pragma: no cover - compiled
    counts = np.zeros(nb, np.int64)
    for i in range(values.size):
        counts[min(int((float(values[i]) - lo) * scale), nb - 1)] += 1
    return counts


@njit(cache=True, nogil=True)
def _bucket_values(values, lo, scale, nb, b0, b1, m):  # pragma: no cover - compiled
    buf = np.empty(m, values.dtype)
    j = 0
    for i in range(values.size):
        b = min(int((float(values[i]) - lo) * scale), nb - 1)
        if b >= b0 and b <= b1:
            buf[j] = values[i]
            j += 1
    return buf


def ranks(values: np.ndarray, k0: int, k1: int):
    """The ``k0``-th and ``k1``-th smallest (0-based, ``k0 <= k1 < n``) of a 1-D array
    without NaN.  A histogram of the values (4096 buckets between the least and the
    greatest, the bucket a monotone function of the value) finds the buckets that hold the
    two ranks, and only those buckets' values are sorted: two passes over the array
    instead of a selection that moves it."""
    nb = 4096
    lo, hi = _value_range(values)
    scale = (nb - 1) / (hi - lo) if hi > lo else 0.0
    if values.size <= 4 * nb or not np.isfinite(scale) or scale == 0.0:
        s = np.sort(values)
        return s[k0], s[k1]
    counts = _bucket_counts(values, lo, scale, nb)
    cum = np.cumsum(counts)
    b0, b1 = int(np.searchsorted(cum, k0, side="right")), int(np.searchsorted(cum, k1, side="right"))
    start = int(cum[b0 - 1]) if b0 else 0
    buf = np.sort(_bucket_values(values, lo, scale, nb, b0, b1, int(cum[b1]) - start))
    return buf[k0 - start], buf[k1 - start]


def median(values: np.ndarray):
    """``np.median(values)`` of a 1-D float array without NaN, the same number (the middle
    value, or the mean of the two middle values in the array's type), found by
    :func:`ranks` instead of a partition of a copy: the report takes medians of every
    height of a 720p map (a million values) several times a map."""
    values = np.ascontiguousarray(values).ravel()
    if values.size <= 16384:  # numpy's partition is as quick there
        return np.median(values)
    n = values.size
    a, b = ranks(values, (n - 1) // 2, n // 2)
    # numpy's own mean of the two middle values: the same rounding in the same type
    return np.median(np.array([a, b], values.dtype))


@njit(cache=True, nogil=True)
def band_medians(band, values, n_bands, min_count):  # pragma: no cover - compiled
    """Per band ``b`` in ``0 .. n_bands - 1``: ``np.median(values[band == b])`` (the middle
    value, or the mean of the two middle values in the values' type), NaN where the band
    holds fewer than ``min_count`` values.  float64 (n_bands,).  The values are grouped by
    band in one pass (a counting sort) and each band's middle found by a partition of its
    own, instead of a sort of all of them by band and a median call per band."""
    counts = np.zeros(n_bands, np.int64)
    for i in range(band.size):
        counts[band[i]] += 1
    starts = np.zeros(n_bands + 1, np.int64)
    for b in range(n_bands):
        starts[b + 1] = starts[b] + counts[b]
    grouped = np.empty(values.size, values.dtype)
    fill = starts[:-1].copy()
    for i in range(band.size):
        b = band[i]
        grouped[fill[b]] = values[i]
        fill[b] += 1
    out = np.full(n_bands, np.nan)
    two = values.dtype.type(2)
    for b in range(n_bands):
        n = counts[b]
        if n < min_count or n == 0:
            continue
        k = n // 2
        part = np.partition(grouped[starts[b]:starts[b + 1]], k)
        out[b] = part[k] if n % 2 else (part[:k].max() + part[k]) / two
    return out


@njit(cache=True, nogil=True)
def window_medians(depth, vs, us, r):  # pragma: no cover - compiled
    """``np.nanmedian`` of ``depth`` over the ``2 r + 1`` square window (cut at the image)
    around each pixel (``vs[i]``, ``us[i]``), the values that are not finite left out; NaN
    where the window holds none.  float64 (N,)."""
    h, w = depth.shape
    out = np.empty(vs.size, np.float64)
    buf = np.empty((2 * r + 1) * (2 * r + 1), depth.dtype)  # the mean of two middle values in their type
    for i in range(vs.size):
        m = 0
        for y in range(max(vs[i] - r, 0), min(vs[i] + r + 1, h)):
            for x in range(max(us[i] - r, 0), min(us[i] + r + 1, w)):
                d = depth[y, x]
                if np.isfinite(d):
                    buf[m] = d
                    m += 1
        if m == 0:
            out[i] = np.nan
            continue
        s = np.sort(buf[:m])
        out[i] = s[m // 2] if m % 2 else (s[m // 2 - 1] + s[m // 2]) / 2
    return out


@njit(cache=True, nogil=True)
def height_colours(height, range_mm, out):  # pragma: no cover - compiled
    """The colours of :func:`d3cli.road.outputs.height_colour` written into ``out`` (uint8
    (H, W, 3), the picture's left part): blue below the plane, white on it, red above,
    saturated at +-``range_mm`` mm; 96 grey where the height is not finite.  The NumPy
    ramp's float32 arithmetic (a float32 map times Python numbers stays float32), per pixel."""
    h, w = height.shape
    scale, span = np.float32(1e3), np.float32(range_mm)
    one, full = np.float32(1.0), np.float32(255.0)
    for v in range(h):
        for u in range(w):
            x = np.float32(height[v, u])
            if not np.isfinite(x):
                out[v, u, 0] = out[v, u, 1] = out[v, u, 2] = 96
                continue
            t = min(max((x * scale) / span, -one), one)
            r = one + t if t < 0 else one
            b = one - t if t > 0 else one
            g = one - abs(t)
            out[v, u, 0] = np.uint8(r * full)
            out[v, u, 1] = np.uint8(g * full)
            out[v, u, 2] = np.uint8(b * full)


@njit(cache=True, nogil=True)
def footprint_grid(h, w, f, f2, cx, cy, normal, offset):  # pragma: no cover - compiled
    """:func:`d3cli.road.plane.plane_footprint` of an (``h``, ``w``) image, float64: per
    pixel the same float64 arithmetic as the NumPy expression (``f2`` is ``f ** 2``), 0
    where the ray misses the plane."""
    out = np.empty((h, w), np.float64)
    us = np.empty(w, np.float64)
    for u in range(w):
        us[u] = (u - cx) / f
    for v in range(h):
        rv = (v - cy) / f
        for u in range(w):
            nr = normal[0] * us[u] + normal[1] * rv + normal[2]
            z = -offset / nr
            area = z ** 2 / (f2 * abs(nr))
            out[v, u] = area if z > 0 and np.isfinite(area) else 0.0
    return out


@njit(cache=True, nogil=True)
def noise_terms(smooth, f, baseline, cx, cy, normal, offset):  # pragma: no cover - compiled
    """Depth ``Z`` and disparity residual ``h f B / (c max(Z, 1e-6))`` of every pixel of a
    height map whose height is finite, in image order (float64 (N,) each): what
    :func:`d3cli.road.defects.prepare_scene` takes the medians of for the disparity noise,
    with NumPy's types (the float32 heights times ``f`` and ``B`` stay float32, the
    division is float64)."""
    h, w = smooth.shape
    n = 0
    for v in range(h):
        for u in range(w):
            if np.isfinite(smooth[v, u]):
                n += 1
    z = np.empty(n, np.float64)
    resid = np.empty(n, np.float64)
    us = np.empty(w, np.float64)
    for u in range(w):
        us[u] = (u - cx) / f
    f32, b32 = np.float32(f), np.float32(baseline)
    i = 0
    for v in range(h):
        rv = (v - cy) / f
        for u in range(w):
            x = smooth[v, u]
            if not np.isfinite(x):
                continue
            nr = normal[0] * us[u] + normal[1] * rv + normal[2]
            zz = (float(x) - offset) / nr
            z[i] = zz
            resid[i] = float(np.float32(np.float32(x * f32) * b32)) / (offset * max(zz, 1e-6))
            i += 1
    return z, resid


@njit(cache=True, nogil=True)
def best_offsets(scores, centre, offsets, step, min_score):  # pragma: no cover - compiled
    """The re-match's choice per pixel (:func:`d3cli.road.rematch.rematch`) from the
    ZNCC ``scores`` (K, H, W) float32 of the ``offsets`` (K,) float32 around ``centre``
    (H, W) float32: the first best offset (``argmax``, a NaN counting as the largest), a
    parabola through it and its neighbours (the ends moved one inward), and whether the
    match is reliable (best score at least ``min_score``, not an end of the search).  The
    NumPy expressions' float32 arithmetic.  Returns (disparity (H, W) float32, reliable
    (H, W) bool)."""
    k, h, w = scores.shape
    new = np.empty((h, w), np.float32)
    reliable = np.empty((h, w), np.bool_)
    two, half, zero = np.float32(2.0), np.float32(0.5), np.float32(0.0)
    step32, floor = np.float32(step), np.float32(min_score)
    # the running argmax offset after offset (each a plane of the scores, read in memory
    # order), then the parabola per pixel
    first = np.zeros((h, w), np.int64)
    top = scores[0].copy()
    for j in range(1, k):
        for v in range(h):
            for u in range(w):
                s, t = scores[j, v, u], top[v, u]
                if s > t or (np.isnan(s) and not np.isnan(t)):
                    first[v, u] = j
                    top[v, u] = s
    for v in range(h):
        for u in range(w):
            raw = first[v, u]
            best = min(max(raw, 1), k - 2)
            a, b, c = scores[best - 1, v, u], scores[best, v, u], scores[best + 1, v, u]
            curvature = (a - two * b) + c
            shift = half * (a - c) / curvature if curvature < 0 else zero
            new[v, u] = (centre[v, u] + offsets[best]) + shift * step32
            reliable[v, u] = b >= floor and raw > 0 and raw < k - 1
    return new, reliable


@njit(cache=True, nogil=True)
def cell_means(disparity, finite, decided, step):  # pragma: no cover - compiled
    """(mean, decided) of the cells of ``step x step`` pixels of a float32 map ``disparity``
    whose pixels count where ``finite`` and the value is finite, for
    :meth:`d3cli.road.grid.Grid.disparities` (the cells of the last row and column hold
    what is left of the map): a cell has a value where at least half of its pixels count
    (their mean, accumulated in float64; inf elsewhere) and is decided where at least half
    of those are ``decided``.  One row of cells at a time, its pixel rows in memory order."""
    h, w = disparity.shape
    rows, cols = (h + step - 1) // step, (w + step - 1) // step
    out = np.empty((rows, cols), np.float32)
    out_decided = np.zeros((rows, cols), np.bool_)
    total = np.empty(cols)
    count = np.empty(cols, np.int64)
    count_decided = np.empty(cols, np.int64)
    for i in range(rows):
        total[:] = 0.0
        count[:] = 0
        count_decided[:] = 0
        v_end = min((i + 1) * step, h)
        for v in range(i * step, v_end):
            for j in range(cols):
                for u in range(j * step, min((j + 1) * step, w)):
                    x = disparity[v, u]
                    if finite[v, u] and np.isfinite(x):
                        total[j] += x
                        count[j] += 1
                        if decided[v, u]:
                            count_decided[j] += 1
        for j in range(cols):
            pixels = (v_end - i * step) * (min((j + 1) * step, w) - j * step)
            n = count[j]
            if 2 * n >= pixels and n > 0:
                out[i, j] = total[j] / n
                out_decided[i, j] = 2 * count_decided[j] >= n
            else:
                out[i, j] = np.inf
    return out, out_decided


@njit(cache=True, nogil=True)
def _reflect(i, n):  # pragma: no cover - compiled
    """Index ``i`` mirrored into ``0 .. n - 1`` (OpenCV's BORDER_REFLECT: ``fedcba|abcdef``)."""
    while i < 0 or i >= n:
        i = -i - 1 if i < 0 else 2 * n - 1 - i
    return i


@njit(cache=True, nogil=True, fastmath=True)
def shifted_rows(image, v0, u0, disparity, offsets):  # pragma: no cover - compiled
    """The right image warped onto the left's box at rows ``v0 ..`` and columns ``u0 ..``
    for each offset: ``out[k, y, x] = image(v0 + y, u0 + x - disparity[y, x] - offsets[k])``,
    float32 (K, h, w) for ``disparity`` (h, w), interpolated along the row with OpenCV's
    bicubic kernel (``A = -0.75``) and mirrored at the image's edges (BORDER_REFLECT).

    What ``cv2.remap(image, u - (d + o), v, INTER_CUBIC, borderMode=BORDER_REFLECT)``
    computes, for a shift along rows only: four taps instead of sixteen, and the exact
    position (float64) instead of OpenCV's 1/32-pixel table (the same values on the table's
    positions, float32 rounding aside).  Offsets a whole number of pixels apart share the
    fraction of their positions, hence the kernel's weights: those are computed once a
    pixel for each distinct fraction (two for the re-match's half-pixel steps), row by row,
    and every offset reads its four taps with them."""
    h, w = disparity.shape
    cols = image.shape[1]
    k_n = offsets.shape[0]
    out = np.empty((k_n, h, w), np.float32)
    # the offsets' classes: offsets a whole number of pixels from the class's first one
    n_classes = 0
    first = np.empty(k_n, np.int64)  # the first offset of each class
    class_of = np.empty(k_n, np.int64)
    whole = np.zeros(k_n, np.int64)  # offsets[k] - offsets[first of its class]
    for k in range(k_n):
        class_of[k] = -1
        for c in range(n_classes):
            diff = float(offsets[k]) - float(offsets[first[c]])
            if diff == np.floor(diff):
                class_of[k], whole[k] = c, int(diff)
                break
        if class_of[k] < 0:
            first[n_classes], class_of[k] = k, n_classes
            n_classes += 1
    a = -0.75
    index = np.empty((n_classes, w), np.int64)
    weights = np.empty((n_classes, 4, w), np.float32)
    for y in range(h):
        row = image[v0 + y]
        for c in range(n_classes):
            o = float(offsets[first[c]])
            for x in range(w):
                pos = float(u0 + x) - (float(disparity[y, x]) + o)
                i = int(np.floor(pos))
                t = pos - i
                t1 = t + 1.0
                c0 = ((a * t1 - 5.0 * a) * t1 + 8.0 * a) * t1 - 4.0 * a
                c1 = ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0
                s = 1.0 - t
                c2 = ((a + 2.0) * s - (a + 3.0)) * s * s + 1.0
                index[c, x] = i
                weights[c, 0, x] = c0
                weights[c, 1, x] = c1
                weights[c, 2, x] = c2
                weights[c, 3, x] = 1.0 - c0 - c1 - c2
        for k in range(k_n):
            c, m = class_of[k], whole[k]
            for x in range(w):
                i = index[c, x] - m
                if i >= 1 and i + 2 < cols:
                    out[k, y, x] = (weights[c, 0, x] * row[i - 1] + weights[c, 1, x] * row[i]
                                    + weights[c, 2, x] * row[i + 1] + weights[c, 3, x] * row[i + 2])
                else:
                    out[k, y, x] = (weights[c, 0, x] * row[_reflect(i - 1, cols)] + weights[c, 1, x] * row[_reflect(i, cols)]
                                    + weights[c, 2, x] * row[_reflect(i + 1, cols)]
                                    + weights[c, 3, x] * row[_reflect(i + 2, cols)])
    return out


@njit(cache=True, nogil=True)
def _reflect_101(i, n):  # pragma: no cover - compiled
    """Index ``i`` mirrored into ``0 .. n - 1`` without repeating the edge (OpenCV's
    BORDER_REFLECT_101, cv2.blur's default: ``dcb|abcd|cba``)."""
    if n == 1:
        return 0
    while i < 0 or i >= n:
        i = -i if i < 0 else 2 * n - 2 - i
    return i


@njit(cache=True, nogil=True, fastmath=True)
def zncc_scores(left, warps, r0, r1, c0, c1, window):  # pragma: no cover - compiled
    """Zero-mean NCC of ``left`` (h, w) with each of ``warps`` (K, h, w) over ``window x
    window`` windows centred on the pixels of rows ``r0:r1`` and columns ``c0:c1``:
    float32 (K, r1 - r0, c1 - c0).  The window sums run down the columns (a running sum
    over ``window`` rows, every column at once), then along the row as differences of its
    prefix sums, in float64; a window reaching past the arrays' edge reads them mirrored
    (BORDER_REFLECT_101, as ``cv2.blur``).  A window's standard deviations are at least
    1e-3 (variance 1e-6).

    What ``cv2.blur`` box filters of the images, their squares and their product and a
    chain of whole-array expressions compute per offset, on the pixels asked for only."""
    h, w = left.shape
    k_n = warps.shape[0]
    half = window // 2
    inv_area = 1.0 / float(window * window)
    rows, cols = r1 - r0, c1 - c0
    n_rows, n_cols = rows + 2 * half, cols + 2 * half
    out = np.empty((k_n, rows, cols), np.float32)
    # the rows and columns each window reads, mirrored at the edges
    ys = np.empty(n_rows, np.int64)
    xs = np.empty(n_cols, np.int64)
    for y in range(n_rows):
        ys[y] = _reflect_101(r0 - half + y, h)
    for x in range(n_cols):
        xs[x] = _reflect_101(c0 - half + x, w)
    lp = np.empty((n_rows, n_cols))
    for y in range(n_rows):
        for x in range(n_cols):
            lp[y, x] = left[ys[y], xs[x]]
    # column sums of the window's rows (va, vb, vc: values, squares, products with the left
    # image), moved down one row at a time; prefix sums of them along the row (pa, pb, pc)
    va = np.zeros(n_cols)
    vb = np.zeros(n_cols)
    vc = np.zeros(n_cols)
    pa = np.zeros(n_cols + 1)
    pb = np.zeros(n_cols + 1)
    pc = np.zeros(n_cols + 1)
    # the left image's window means and inverse standard deviations, once
    l_mean = np.empty((rows, cols))
    l_inv = np.empty((rows, cols))
    for y in range(window - 1):
        for x in range(n_cols):
            v = lp[y, x]
            va[x] += v
            vb[x] += v * v
    for y in range(rows):
        for x in range(n_cols):
            v = lp[y + window - 1, x]
            va[x] += v
            vb[x] += v * v
        s = ss = 0.0
        for x in range(n_cols):
            s += va[x]
            ss += vb[x]
            pa[x + 1] = s
            pb[x + 1] = ss
        for x in range(cols):
            m = (pa[x + window] - pa[x]) * inv_area
            l_mean[y, x] = m
            l_inv[y, x] = 1.0 / np.sqrt(max((pb[x + window] - pb[x]) * inv_area - m * m, 1e-6))
        for x in range(n_cols):
            v = lp[y, x]
            va[x] -= v
            vb[x] -= v * v
    wp = np.empty((n_rows, n_cols))
    for k in range(k_n):
        for y in range(n_rows):
            yy = ys[y]
            for x in range(n_cols):
                wp[y, x] = warps[k, yy, xs[x]]
        va[:] = 0.0
        vb[:] = 0.0
        vc[:] = 0.0
        for y in range(window - 1):
            for x in range(n_cols):
                v = wp[y, x]
                va[x] += v
                vb[x] += v * v
                vc[x] += v * lp[y, x]
        for y in range(rows):
            for x in range(n_cols):
                v = wp[y + window - 1, x]
                va[x] += v
                vb[x] += v * v
                vc[x] += v * lp[y + window - 1, x]
            s = ss = sl = 0.0
            for x in range(n_cols):
                s += va[x]
                ss += vb[x]
                sl += vc[x]
                pa[x + 1] = s
                pb[x + 1] = ss
                pc[x + 1] = sl
            for x in range(cols):
                m = (pa[x + window] - pa[x]) * inv_area
                var = (pb[x + window] - pb[x]) * inv_area - m * m
                out[k, y, x] = ((pc[x + window] - pc[x]) * inv_area - l_mean[y, x] * m) * l_inv[y, x] / np.sqrt(
                    max(var, 1e-6))
            for x in range(n_cols):
                v = wp[y, x]
                va[x] -= v
                vb[x] -= v * v
                vc[x] -= v * lp[y, x]
    return out
