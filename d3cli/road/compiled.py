"""Compiled loops of the road report (numba, cached beside this file like the kernels').

Each function computes what a NumPy expression of :mod:`d3cli.road.plane`,
:mod:`d3cli.road.defects` or :mod:`d3cli.road.morphology` computes, in one pass over the
pixels or points instead of a chain of whole-array temporaries: on a 1280x720 map the
NumPy versions took most of the road report's time (tests/road/test_compiled.py holds each
against its NumPy reference).  May import numpy, numba and the standard library only.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def weighted_scatter(points, normal, offset, tolerance, limit):  # pragma: no cover - compiled
    """Tukey-biweight IRLS round of the plane fit: weights ``(1 - (r / limit)^2)^2`` of the
    residuals ``r = (n . P + c) / tolerance`` (0 beyond ``limit``), their weighted centre and
    the weighted scatter matrix ``sum w (P - centre)(P - centre)^T``.

    ``points`` (N, 3) float32; ``tolerance`` (N,) float64.  Returns (sum of weights, centre
    (3,), scatter (3, 3)); the centre and scatter are zeros when no weight is positive.
    """
    n = points.shape[0]
    w = np.empty(n)
    total = 0.0
    cx = cy = cz = 0.0
    for i in range(n):
        x, y, z = float(points[i, 0]), float(points[i, 1]), float(points[i, 2])
        r = (x * normal[0] + y * normal[1] + z * normal[2] + offset) / tolerance[i]
        if abs(r) < limit:
            q = 1.0 - (r / limit) ** 2
            wi = q * q
        else:
            wi = 0.0
        w[i] = wi
        total += wi
        cx += wi * x
        cy += wi * y
        cz += wi * z
    centre = np.zeros(3)
    scatter = np.zeros((3, 3))
    if total <= 0.0:
        return total, centre, scatter
    centre[0], centre[1], centre[2] = cx / total, cy / total, cz / total
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for i in range(n):
        wi = w[i]
        if wi == 0.0:
            continue
        dx = float(points[i, 0]) - centre[0]
        dy = float(points[i, 1]) - centre[1]
        dz = float(points[i, 2]) - centre[2]
        sxx += wi * dx * dx
        sxy += wi * dx * dy
        sxz += wi * dx * dz
        syy += wi * dy * dy
        syz += wi * dy * dz
        szz += wi * dz * dz
    scatter[0, 0], scatter[0, 1], scatter[0, 2] = sxx, sxy, sxz
    scatter[1, 0], scatter[1, 1], scatter[1, 2] = sxy, syy, syz
    scatter[2, 0], scatter[2, 1], scatter[2, 2] = sxz, syz, szz
    return total, centre, scatter


@njit(cache=True)
def inlier_count(points, normal, offset, tolerance):  # pragma: no cover - compiled
    """Number of (N, 3) ``points`` with ``|n . P + c| < tolerance`` (per point)."""
    count = 0
    for i in range(points.shape[0]):
        r = float(points[i, 0]) * normal[0] + float(points[i, 1]) * normal[1] + float(points[i, 2]) * normal[2]
        if abs(r + offset) < tolerance[i]:
            count += 1
    return count


@njit(cache=True)
def ransac_scores(points, triples, tolerance):  # pragma: no cover - compiled
    """Inliers of the plane through each row of ``triples`` (K, 3) (indices into ``points``):
    ``|n . P + c| < tolerance`` counted over ``points`` (N, 3) float64; -1 for a degenerate
    triple (normal shorter than 1e-12).  Returns (scores (K,), normals (K, 3), offsets (K,))."""
    k = triples.shape[0]
    scores = np.full(k, -1.0)
    normals = np.zeros((k, 3))
    offsets = np.zeros(k)
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
        for i in range(points.shape[0]):
            if abs(points[i, 0] * nx + points[i, 1] * ny + points[i, 2] * nz + off) < tolerance[i]:
                count += 1
        scores[j] = count
        normals[j, 0], normals[j, 1], normals[j, 2] = nx, ny, nz
        offsets[j] = off
    return scores, normals, offsets


@njit(cache=True)
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
