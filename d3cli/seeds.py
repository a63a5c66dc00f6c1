"""Step 4: decisive seeds at the coarsest level (WTA + PKRN + left-right check)."""

from __future__ import annotations


def decisive_seeds(cost, *, pkrn_min: float, epsilon: float, lr_tolerance: int, exclusion: int, backend):
    """Sparse decisive disparity map D_k^S (paper section III-B, DESIGN step 4).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
        Aggregated cost volume of the coarsest level.
    pkrn_min : float
        Keep the WTA disparity when (c2 + eps) / (c1 + eps) >= pkrn_min.
    epsilon : float
    lr_tolerance : int
        Largest |d_left - d_right| accepted by the left-right check; the right view's
        costs are the same volume re-indexed.
    exclusion : int
        0: naive PKRN (c2 over every other disparity); r > 0 ignores |d - d*| <= r.
    backend : module

    Returns
    -------
    ndarray, int32, (H, W)
        Seed disparities, -1 where undecided.
    """
    return backend.decisive_seeds(cost, float(pkrn_min), float(epsilon), int(lr_tolerance), int(exclusion))
