"""Step 5: intra-scale decisive disparity diffusion (paper Algorithm 1, eq. 5-6)."""

from __future__ import annotations

import numpy as np


def diffuse(cost, disparity, *, max_gap: float = -1.0, tau: int, kappa_d: int, adversarial: bool, max_sweeps: int, backend):
    """Grow a sparse decisive map over one level with a frontier of changed pixels.

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
    disparity : ndarray, int32, (H, W)
        Sparse map (-1 undecided); not modified.
    max_gap : float
        Accepted states cost at most the pixel's least cost + ``max_gap`` (an addition
        to the paper, see ``DiffusionConfig.max_gap``); < 0 turns the test off.
    tau : int
        Candidates are neighbour disparities + r, r in [-tau, tau] (eq. 5).
    kappa_d : int
        Neighbourhood radius.
    adversarial : bool
        Decided pixels switch to a strictly cheaper accepted candidate (eq. 6).
    max_sweeps : int
        Safeguard; diffusion stops earlier when a sweep changes nothing.
    backend : module

    Returns
    -------
    disparity : ndarray, int32, (H, W)
    sweeps : int
    """
    if max_gap >= 0:
        least = backend.min_cost(cost)
    else:
        least = backend.to_device(np.zeros((1, 1), np.float32))  # never read
    return backend.diffuse(cost, disparity, least, float(max_gap), int(tau), int(kappa_d), bool(adversarial), int(max_sweeps))
