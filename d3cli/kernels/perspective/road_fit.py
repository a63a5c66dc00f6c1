"""Numba kernel of the road model fit (step 6, ``d3cli.method.perspective``), host side
for every backend like the finishing kernels.  May import: numpy, numba."""

from __future__ import annotations

import numpy as np
from numba import njit

# compile_cache.py chooses a writable numba cache folder (NUMBA_CACHE_DIR) for a read-only install
# when it is imported; the decorator below reads that setting, so it must run first.
from .. import compile_cache as _compile_cache  # noqa: F401,E402  (import for its side effect)


@njit(cache=True, nogil=True, error_model="numpy")
def ransac_inlier_counts(sols, us, vs, ds, threshold):
    """Inliers of every RANSAC hypothesis of ``d = a0 + b1 v + b2 u`` (the host fit of
    :func:`d3cli.method.perspective.fit_road_model`).

    Parameters
    ----------
    sols : ndarray, float64, (N, 3)
        Hypotheses (a0, b1, b2).
    us, vs, ds : ndarray, float64, (M,)
        Scored points.
    threshold : float

    Returns
    -------
    ndarray, int64, (N,)
        ``count_nonzero(|ds - (a0 + b1 vs + b2 us)| <= threshold)`` per hypothesis: the
        same float64 expression, in the same order, as the NumPy broadcast of the
        reference (which builds 50 x M temporaries per chunk), so the same counts.
    """
    out = np.empty(sols.shape[0], np.int64)
    for j in range(sols.shape[0]):
        a0 = sols[j, 0]
        b1 = sols[j, 1]
        b2 = sols[j, 2]
        count = 0
        for i in range(ds.shape[0]):
            if abs(ds[i] - (a0 + b1 * vs[i] + b2 * us[i])) <= threshold:
                count += 1
        out[j] = count
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def solve_weighted(u, v, d, w, singular):
    """Weighted least squares of d = a0 + b1 v + b2 u by the centred normal equations
    (the road fit's one solver: the RANSAC refit through
    :func:`d3cli.method.perspective.solve_road_model`, and every IRLS round), one compiled pass per
    sum, in index order.  Returns ``(ok, a0, b1, b2)``; ``ok`` False with no weight or
    collinear points (the centred 2x2 determinant below ``singular`` times its diagonal's
    product)."""
    n = u.shape[0]
    sw = 0.0
    swu = 0.0
    swv = 0.0
    swd = 0.0
    for i in range(n):
        sw += w[i]
        swu += w[i] * u[i]
        swv += w[i] * v[i]
        swd += w[i] * d[i]
    if not sw > 0.0:
        return False, 0.0, 0.0, 0.0
    uc = swu / sw
    vc = swv / sw
    svv = 0.0
    suu = 0.0
    svu = 0.0
    svd = 0.0
    sud = 0.0
    for i in range(n):
        du = u[i] - uc
        dv = v[i] - vc
        wdu = w[i] * du
        wdv = w[i] * dv
        svv += wdv * dv
        suu += wdu * du
        svu += wdv * du
        svd += wdv * d[i]
        sud += wdu * d[i]
    det = svv * suu - svu * svu
    if not det > singular * svv * suu:
        return False, 0.0, 0.0, 0.0
    b1 = (suu * svd - svu * sud) / det
    b2 = (svv * sud - svu * svd) / det
    return True, swd / sw - b1 * vc - b2 * uc, b1, b2


@njit(cache=True, nogil=True, error_model="numpy")
def irls(u, v, d, sol, threshold, iterations, tukey_c, singular):
    """Tukey-biweight IRLS of the road model from ``sol`` (a0, b1, b2): the loop of
    :func:`d3cli.method.perspective.reweighted_refit` compiled (a round there makes about 25 NumPy
    calls over the 14,000 coarse points of a 720p road pair: 2.9 ms a fit in all, here
    a few passes).  Each round: residuals, their median absolute value as the scale
    (never below ``threshold / 2.5``), the biweights, and :func:`solve_weighted`; it
    stops after ``iterations`` rounds, when fewer than 3 points keep a weight, when the
    system is singular or when no coefficient moved by 1e-9.  Returns the model."""
    n = u.shape[0]
    r = np.empty(n)
    a = np.empty(n)
    w = np.empty(n)
    s0, s1, s2 = sol[0], sol[1], sol[2]
    for _ in range(iterations):
        for i in range(n):
            r[i] = d[i] - (s0 + s1 * v[i] + s2 * u[i])
            a[i] = abs(r[i])
        sigma = 1.4826 * np.median(a)
        c = tukey_c * max(sigma, threshold / 2.5)
        kept = 0
        for i in range(n):
            z = r[i] / c
            if abs(z) < 1.0:
                w[i] = (1.0 - z * z) ** 2
                kept += w[i] != 0.0
            else:
                w[i] = 0.0
        if kept < 3:
            break
        ok, n0, n1, n2 = solve_weighted(u, v, d, w, singular)
        if not ok:
            break
        done = max(abs(n0 - s0), max(abs(n1 - s1), abs(n2 - s2))) < 1e-9
        s0, s1, s2 = n0, n1, n2
        if done:
            break
    out = np.empty(3)
    out[0] = s0
    out[1] = s1
    out[2] = s2
    return out
