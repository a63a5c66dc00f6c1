"""Step 2: NCC matching cost volume of one pyramid level."""

from __future__ import annotations


def cost_volume(left, right, *, max_disparity: int, window: int, min_variance: float, backend):
    """NCC cost volume ``C(p, d) = (1 - NCC) / 2`` of one level (DESIGN step 2).

    Parameters
    ----------
    left, right : float32 (H, W) arrays of the backend (``backend.to_device``)
        Grey images of the level, 0-255 scale, C-contiguous.
    max_disparity : int
        Largest disparity of the level (the volume has max_disparity + 1 slices).
    window : int
        Odd NCC window size.
    min_variance : float
        Variance (grey levels^2) at or below which a window counts as flat (cost 1).
    backend : module
        Kernel backend from :func:`d3cli.kernels.get_backend`.

    Returns
    -------
    ndarray, float32, (H, W, max_disparity + 1)
        Lower is better; 1 where u - d < 0 or a window is flat.
    """
    return backend.ncc_cost_volume(left, right, int(max_disparity), int(window), float(min_variance))
