"""Numba kernel of the road model fit (step 6, ``d3cli.method.perspective``), host side
for every backend like the finishing kernels.  May import: numpy, numba."""

from __future__ import annotations

import numpy as np
from numba import njit

# cache.py chooses a writable numba cache folder (NUMBA_CACHE_DIR) for a read-only install
# when it is imported; the decorator below reads that setting, so it must run first.
from .. import cache as _cache  # noqa: F401,E402  (import for its side effect)


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
        same float64 expression, in the same order, as the NumPy broadcast it replaced
        (which built 50 x M temporaries per chunk), so the same counts.
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
