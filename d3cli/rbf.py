"""Step 3: cost aggregation by recursive bilateral filtering (paper eq. 2-3)."""

from __future__ import annotations


def aggregate(
    cost,
    image,
    *,
    rbf: bool,
    t_max: int,
    sigma_space: float,
    sigma_color: float,
    kappa_a: int,
    backend,
    overwrite_input: bool = False,
):
    """Aggregate a cost volume with RBF, or with one plain bilateral pass (ablation).

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    image : float32 (H, W) array of the backend (``backend.to_device``)
        Left grey image of the level; guides the bilateral weights.
    rbf : bool
        True: ``t_max`` passes of the 3x3 kernel of eq. 3 with weights computed once
        (paper eq. 2).  False: one pass of a (2 kappa_a + 1)^2 bilateral filter.
    t_max, sigma_space, sigma_color, kappa_a
        Filter parameters (sigma_1, sigma_2 of eq. 3 in pixels and grey levels).
    backend : module
    overwrite_input : bool
        ``cost`` may be clobbered (RBF uses it as a buffer): one volume less at the peak.

    Returns
    -------
    ndarray, float32, (H, W, D)
        Cells with u - d < 0 stay exactly 1.
    """
    if rbf:
        if t_max == 0:
            return cost
        weights = backend.rbf_weights(image, float(sigma_space), float(sigma_color))
        out = backend.rbf_filter(cost, weights, int(t_max), overwrite_input=overwrite_input)
    else:
        if kappa_a == 0:
            return cost
        out = backend.bilateral_filter(cost, image, int(kappa_a), float(sigma_space), float(sigma_color))
    # Filtering mixes the out-of-view cells (u - d < 0, cost 1) with valid neighbours;
    # put them back to 1 so that they never win.
    return backend.invalidate_out_of_view(out)
