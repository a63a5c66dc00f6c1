"""Steps 4, 5 and 7: the decisive disparities of a level.

- Step 4, decisive seeds at the coarsest level (WTA + PKRN + left-right check, paper
  section III-B);
- step 5, intra-scale decisive diffusion (paper Algorithm 1, eq. 4-5);
- step 7, inter-scale decisive inheritance (paper Algorithm 2, eq. 6-8).

Each function turns keyword scalars into one kernel call of the backend
(:mod:`d3cli.kernels`); the per-pixel rules live in the kernels' ``decisive/pixel_*.py``.
"""

from __future__ import annotations

from ..kernels.backend import Backend


def decisive_seeds(cost, *, pkrn_min: float, epsilon: float, lr_tolerance: int, exclusion: int, backend: Backend,
                   skip=None):
    """Sparse decisive disparity map D_k^S (paper section III-B; docs/design.md, 'Decisive seeds').

    Parameters
    ----------
    cost : Volume or ndarray, float32, (H, W, D)
        Aggregated cost volume of the level.
    pkrn_min : float
        Keep the WTA disparity when (c2 + eps) / (c1 + eps) >= pkrn_min.
    epsilon : float
    lr_tolerance : int
        Largest |d_left - d_right| accepted by the left-right check; the right view's
        costs are the same volume re-indexed.
    exclusion : int
        0: naive PKRN (c2 over every other disparity); r > 0 ignores |d - d*| <= r.
    backend : Backend
    skip : int32 (H, W) backend array, optional
        Pixels decided here (>= 0) are not examined and stay -1: below the coarsest
        level fresh seeds only fill what inheritance left undecided.

    Returns
    -------
    ndarray, int32, (H, W)
        Seed disparities, -1 where undecided.
    """
    return backend.decisive_seeds(cost, float(pkrn_min), float(epsilon), int(lr_tolerance), int(exclusion),
                                  skip=skip)


def diffuse(cost, disparity, *, max_gap: float = -1.0, tau: int, kappa_d: int, adversarial: bool, max_sweeps: int,
            backend: Backend):
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
        Candidates are neighbour disparities + r, r in [-tau, tau] (eq. 4).
    kappa_d : int
        Neighbourhood radius.
    adversarial : bool
        Decided pixels switch to a strictly cheaper accepted candidate (eq. 5).
    max_sweeps : int
        Safeguard; diffusion stops earlier when a sweep changes nothing.
    backend : Backend

    Returns
    -------
    disparity : ndarray, int32, (H, W)
    sweeps : int
    """
    # min_cost None: each backend finds the least costs the gap test needs (the CPU for the
    # few pixels that reach it, CUDA in one pass over the volume)
    return backend.diffuse(cost, disparity, None, float(max_gap), int(tau), int(kappa_d), bool(adversarial),
                           int(max_sweeps))


#: ``inheritance.candidates`` -> the kernels' int argument (``pixel.candidate_range``).
CANDIDATE_MODES = {"symmetric": 0, "paper": 1}


def inherit(cost, coarse, *, prc: bool, dfm_pkrn_min: float, epsilon: float, backend: Backend,
            candidates: str = "symmetric"):
    """Map decided coarse disparities into 2x2 patches of the finer level.

    Parameters
    ----------
    cost : ndarray, float32, (H, W, D)
        Cost volume of the finer level.
    coarse : ndarray, int32
        Disparity map of the coarser level (-1 undecided), shape (H // 2, W // 2) or
        larger.
    prc : bool
        Patch reliability + local-minimum constraints (eq. 6-8); False: the DFM-style
        PKRN test in the patch (ablation).
    dfm_pkrn_min, epsilon : float
        PKRN threshold and epsilon of the DFM-style test.
    backend : Backend
    candidates : {"symmetric", "paper"}
        Which disparities a patch pixel tests, with d = 2 dc.  ``symmetric``: {d-1, d,
        d+1} in the patch and {d-2, d+2} outside, for every pixel.  ``paper``: eq. 6-7 of
        the paper read literally, the co-row partner pixels of the other view's patch and
        the two pixels beside it: a left pixel in patch column 0 tests {d-1, d} (outside
        {d-2, d+1}), in column 1 {d, d+1} (outside {d-1, d+2}); the right view mirrored.

    Returns
    -------
    ndarray, int32, (H, W)
        Sparse map D_i^S (-1 undecided).
    """
    return backend.inherit(cost, coarse, bool(prc), float(dfm_pkrn_min), float(epsilon),
                           CANDIDATE_MODES[candidates])
