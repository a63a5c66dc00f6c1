"""Step 7: inter-scale decisive disparity inheritance (paper Algorithm 2, eq. 7-9)."""

from __future__ import annotations


def inherit(cost, coarse, *, prc: bool, dfm_pkrn_min: float, epsilon: float, backend):
    """Map decided coarse disparities into 2x2 patches of the finer level.

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
        Cost volume of the finer level.
    coarse : ndarray, int32
        Disparity map of the coarser level (-1 undecided), shape (H // 2, W // 2) or
        larger.
    prc : bool
        Patch reliability + local-minimum constraints (eq. 7-9); False: the DFM-style
        PKRN test in the patch (ablation).
    dfm_pkrn_min, epsilon : float
        PKRN threshold and epsilon of the DFM-style test.
    backend : module

    Returns
    -------
    ndarray, int32, (H, W)
        Sparse map D_i^S (-1 undecided).
    """
    return backend.inherit(cost, coarse, bool(prc), float(dfm_pkrn_min), float(epsilon))
