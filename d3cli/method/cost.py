"""Steps 2-3: the aggregated matching cost volume of one pyramid level.

Step 2 (docs/design.md, 'Cost volumes'): NCC cost ``C(p, d) = (1 - NCC) / 2`` over a w x w window.
Step 3 (paper eq. 2-3): recursive bilateral filtering (RBF) of every disparity slice,
or the plain bilateral filter of the ablation.  :func:`level_cost` turns the
configuration into the scalars the kernels take; the kernels live in
:mod:`d3cli.kernels`.
"""

from __future__ import annotations

import time

from ..config import Config
from ..kernels.host import Volume
from .pyramid import level_max_disparity
from ..kernels.backend import Backend


def cost_volume(left, right, *, max_disparity: int, window: int, min_variance: float, backend: Backend, index=None):
    """NCC cost volume ``C(p, d) = (1 - NCC) / 2`` of one level (docs/design.md, 'Cost volumes').

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
    backend : Backend
        Kernel backend from :func:`d3cli.kernels.get_backend`.
    index : int32 (H, W, 3) backend array, optional
        The bands to compute (:mod:`d3cli.kernels.volume`); default the full range.

    Returns
    -------
    ndarray, float32, (H, W, max_disparity + 1), or a Volume with ``index``
        Lower is better; 1 where u - d < 0 or a window is flat.
    """
    return backend.ncc_cost_volume(left, right, int(max_disparity), int(window), float(min_variance), index=index)


def aggregate(
    cost,
    image,
    *,
    rbf: bool,
    t_max: int,
    sigma_space: float,
    sigma_color: float,
    kappa_a: int,
    backend: Backend,
    overwrite_input: bool = False,
    bf_sigma_space: float | None = None,
):
    """Aggregate a cost volume with RBF, or with one plain bilateral pass (ablation).

    Parameters
    ----------
    cost : Volume or ndarray, float32, (H, W, D)
    image : float32 (H, W) array of the backend (``backend.to_device``)
        Left grey image of the level; guides the bilateral weights.
    rbf : bool
        True: ``t_max`` passes of the 3x3 kernel of eq. 3 with weights computed once
        (paper eq. 2).  False: one pass of a (2 kappa_a + 1)^2 bilateral filter.
    t_max, sigma_space, sigma_color, kappa_a
        Filter parameters (sigma_1, sigma_2 of eq. 3 in pixels and grey levels).
    backend : Backend
    overwrite_input : bool
        ``cost`` may be clobbered (RBF uses it as a buffer): one volume less at the peak.
    bf_sigma_space : float, optional
        sigma_1 of the plain bilateral filter; default :func:`bilateral_sigma_space`.

    Returns
    -------
    Volume or ndarray, float32, (H, W, D)
        The kind of ``cost``; cells with u - d < 0 stay exactly 1.
    """
    if rbf:
        if t_max == 0:
            return cost
        weights = backend.rbf_weights(image, float(sigma_space), float(sigma_color))
        out = backend.rbf_filter(cost, weights, int(t_max), overwrite_input=overwrite_input)
    else:
        if kappa_a == 0:
            return cost
        sigma_bf = bilateral_sigma_space(sigma_space, kappa_a) if bf_sigma_space is None else bf_sigma_space
        out = backend.bilateral_filter(cost, image, int(kappa_a), float(sigma_bf), float(sigma_color))
    # Filtering mixes the out-of-view cells (u - d < 0, cost 1) with valid neighbours;
    # put them back to 1 so that they never win.
    return backend.invalidate_out_of_view(out)


def bilateral_sigma_space(sigma_space: float, kappa_a: int) -> float:
    """sigma_1 of the plain bilateral filter of the ablation: ``sigma_space * kappa_a``.

    The paper's baseline (Table I, Fig. 4) is a bilateral filter with the same receptive
    field as RBF: radius kappa_a = t_max.  Reusing RBF's sigma_1 = 1.5 in a 9x9 window
    gives its outer ring weights below exp(-16 / 2.25) = 0.001: it acts like a 5x5 filter.
    Scaling sigma_1 with the radius stretches the 3x3 kernel of eq. 3 over the (2 kappa_a
    + 1)^2 window: the spatial weight at distance kappa_a (exp(-1 / sigma_1^2)) and at
    the window's corner are those of the 3x3 kernel at distance 1 and at its corner.

    Parameters
    ----------
    sigma_space : float
        sigma_1 of eq. 3 (pixels), the RBF kernel's.
    kappa_a : int
        Radius of the plain filter (pixels).

    Returns
    -------
    float
        sigma_1 of the plain filter, pixels.
    """
    return float(sigma_space) * max(1, int(kappa_a))


def feature_cost_volume(features, *, max_disparity: int, backend: Backend, index=None):
    """Deep-feature cost volume ``(1 - cos) / 2`` of one level (paper section III-A).

    Parameters
    ----------
    features : d3cli.method.features.LevelFeatures
        Normalised feature maps of the level (left and right).
    max_disparity : int
        Largest disparity of the level (the volume has max_disparity + 1 slices).
    backend : Backend
    index : int32 (H, W, 3) backend array, optional
        The bands to compute; default the full range.

    Returns
    -------
    ndarray, float32, (H, W, max_disparity + 1), or a Volume with ``index``
        1 where u - d < 0 or a feature vector is zero.
    """
    return backend.cosine_cost_volume(features.left, features.right, features.left_norm, features.right_norm,
                                      int(max_disparity), index=index)


def aggregation_halo(cfg: Config, level: int) -> int:
    """How far (pixels) aggregation mixes costs at ``level``: RBF passes, or the bilateral radius."""
    agg = cfg.aggregation
    return int(cfg.level_t_max(level)) if agg.rbf else int(agg.kappa_a)


def level_cost(left, right, *, level: int, max_disparity: int, cfg: Config, backend: Backend, features=None,
               bands=None, step_times: dict | None = None) -> Volume:
    """Aggregated cost volume of one level (steps 2-3).

    Parameters
    ----------
    left, right : float32 (H, W) arrays of the backend
        Grey images of the level.
    level : int
        Pyramid level, 0 = full resolution; the level searches
        ``ceil(max_disparity / 2^level)`` disparities and uses ``cfg.level_window(level)``.
    max_disparity : int
        Largest disparity at full resolution.
    cfg : Config
    backend : Backend
    features : LevelFeatures, optional
        The level's deep features (``cost.kind: features``): the cosine cost replaces NCC.
    bands : (store, visible, ...) int32 (H, W, 3) backend arrays, optional
        From ``backend.band_indexes``: the cells to compute and aggregate, and the band each
        pixel shows afterwards.  Default: the full range.
    step_times : dict, optional
        Gets ``time_sgm``, the seconds of the semi-global smoothing, where it runs (a
        step of ``result.timings`` of its own: ``sgm``).

    Returns
    -------
    Volume
        The aggregated volume with the visible bands (backend arrays); at level 0 with
        ``aggregation.sgm_p2 > 0`` the mean of four semi-global path costs of it
        (``backend.sgm_smooth``).
    """
    level_dmax = level_max_disparity(max_disparity, level)
    # The store index is a backend array (built where the volume is); the result carries it.
    if bands is None:
        h, w = left.shape
        store = backend.dense_index(h, w, level_dmax + 1)
        visible = None
    else:
        store = bands[0]
        visible = backend.to_device(bands[1])
    if features is not None:
        cost = feature_cost_volume(features, max_disparity=level_dmax, backend=backend, index=store)
    else:
        cost = cost_volume(
            left,
            right,
            max_disparity=level_dmax,
            window=cfg.level_window(level),
            min_variance=cfg.cost.min_variance,
            backend=backend,
            index=store,
        )
    agg = cfg.aggregation
    cost = aggregate(
        cost,
        left,
        rbf=agg.rbf,
        t_max=cfg.level_t_max(level),
        sigma_space=agg.sigma_space,
        sigma_color=agg.sigma_color,
        kappa_a=agg.kappa_a,
        backend=backend,
        overwrite_input=True,  # the raw NCC volume is not needed afterwards
        bf_sigma_space=agg.bf_sigma_space,
    )
    cost = cost if visible is None else Volume(cost.cost, visible, cost.n_disp)
    if level == 0 and agg.sgm_p2 > 0:
        # Semi-global smoothing of the finest aggregated cost, four paths: it lowers
        # PEP1 on driving scenes (docs/design.md, 'Semi-global smoothing'; configs/kitti.yaml)
        t0 = time.perf_counter()
        cost = backend.sgm_smooth(cost, agg.sgm_p1, agg.sgm_p2)
        if step_times is not None:
            step_times["time_sgm"] = time.perf_counter() - t0
    return cost
