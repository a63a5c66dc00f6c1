"""PT-SGM: OpenCV SGBM after the perspective transformation of PT-D3Stereo.

The same road model, warp and restore as :mod:`d3cli.method.perspective`, so that the
comparison isolates the matcher.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from ..config import Config
from ..data.formats import to_grey
from ..errors import InputError
from ..method import DisparityResult
from ..method.perspective import fit_road_model, restored_validity
from ..method.pyramid import build_pyramid, level_max_disparity, usable_levels
from .sgbm import _num_disparities, _sgbm_raw, _to_uint8, fill_holes_rowwise, sgbm_disparity, sgbm_peak_bytes

log = logging.getLogger(__name__)


def pt_sgm_peak_bytes(shape, max_disparity: int, cfg: Config) -> int:
    """Estimated peak memory of one PT-SGM pair: SGBM's (:func:`~d3cli.baselines.sgbm.sgbm_peak_bytes`
    over the full range, the worst case of a fallback) plus the warped right image and
    the shift map, float32 each."""
    pixels = max(int(shape[0]), 0) * max(int(shape[1]), 0)
    return sgbm_peak_bytes(shape, max_disparity, cfg) + 2 * 4 * pixels


def pt_sgm_disparity(left: np.ndarray, right: np.ndarray, *, max_disparity: int, cfg: Config) -> DisparityResult:
    """PT-SGM: OpenCV SGBM after the perspective transformation of PT-D3Stereo.

    The road model (docs/design.md, 'Perspective transformation') is fitted with :func:`d3cli.method.perspective.fit_road_model` to
    SGBM on the pair downsampled to the coarsest pyramid level (``cfg.pyramid.levels``,
    area averaging, range ``ceil(max_disparity / 2^(k-1))``; a finer level when SGBM's
    empty left strip would cover more than half of the coarse image); the right image is warped
    with the same kernel as PT-D3Stereo (``kernels.host.pt_warp``), SGBM searches the
    narrow range [0, 2 margin + slack] (``numDisparities = 16 ceil((2 margin + slack + 1)
    / 16)``), and the disparity is restored with ``d = d' (1 - b2) + s(u, v)``.
    Estimates at the ends of the narrow range, and matches left of the right image,
    become holes; holes are filled as for ``sgbm``.  When the scene is not road-like
    this is plain SGBM over the full range, with a warning.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3)
        Rectified pair of equal shape.
    max_disparity : int, keyword-only
        Largest disparity of the full-range search (coarse fit), pixels.
    cfg : Config, keyword-only
        Reads the ``sgbm``, ``pt`` and ``pyramid`` sections.

    Returns
    -------
    DisparityResult
        As :func:`sgbm_disparity`; ``info['pt']`` holds the fitted model.
    """
    from ..kernels import host  # compiled numba code: loaded when PT-SGM actually runs

    if max_disparity < 1:
        raise InputError(f"pair: max disparity {max_disparity} must be >= 1; pass --max-disparity 1 or more")
    t0 = time.perf_counter()
    pt = cfg.pt
    grey_l, grey_r = to_grey(left), to_grey(right)
    model = _coarse_road_model(grey_l, grey_r, max_disparity, cfg)
    narrow = pt.narrow_range
    pt_info = model.to_info(narrow_range=narrow)
    if not model.road_like:
        msg = model.fallback_warning(max_disparity)
        log.debug(msg)  # returned in result.warnings; the batch logs those once
        result = sgbm_disparity(left, right, max_disparity=max_disparity, cfg=cfg.sgbm)
        result.info.update(method="pt-sgm", pt=pt_info)
        result.warnings.append(msg)
        result.timings["total"] = time.perf_counter() - t0
        return result
    margin = float(pt.margin)
    warped = host.pt_warp(np.ascontiguousarray(grey_r, dtype=np.float32), model.a0, model.b1, model.b2, margin)
    d_prime, valid = _sgbm_raw(_to_uint8(grey_l), _to_uint8(warped), narrow, cfg.sgbm)
    disp = host.pt_restore(np.where(valid, d_prime, np.inf).astype(np.float32), model.a0, model.b1, model.b2, margin)
    valid, shares = restored_validity(valid, d_prime, disp, narrow_range=narrow)  # as PT-D3Stereo
    pt_info.update(shares)
    disp[~valid] = np.inf
    warnings = [] if valid.any() else ["pt-sgm found no valid disparity; the output is empty"]
    if cfg.sgbm.fill:
        disp = fill_holes_rowwise(disp, valid)
    info = {
        "method": "pt-sgm",
        "backend": "opencv",
        "num_disparities": _num_disparities(narrow),
        "block_size": cfg.sgbm.block_size,
        "mode": cfg.sgbm.mode,
        "filled": bool(cfg.sgbm.fill),
        "valid_share": float(valid.mean()),
        "pt": pt_info,
    }
    return DisparityResult(
        disparity=disp, valid=valid, timings={"total": time.perf_counter() - t0}, info=info, warnings=warnings
    )


def _coarse_road_model(grey_l: np.ndarray, grey_r: np.ndarray, max_disparity: int, cfg: Config):
    """The road model of :func:`pt_sgm_disparity`: fitted to SGBM on a coarse pyramid level."""
    pt = cfg.pt
    levels = usable_levels(grey_l.shape, cfg.pyramid.levels)
    top = levels - 1
    # SGBM leaves the leftmost numDisparities columns empty: go finer until at least half
    # of the columns can hold an estimate.
    while top > 0 and grey_l.shape[1] >> top < 2 * _num_disparities(level_max_disparity(max_disparity, top)):
        top -= 1
    coarse_l = _to_uint8(build_pyramid(grey_l, top + 1)[top])
    coarse_r = _to_uint8(build_pyramid(grey_r, top + 1)[top])
    coarse, _ = _sgbm_raw(coarse_l, coarse_r, level_max_disparity(max_disparity, top), cfg.sgbm)
    return fit_road_model(
        coarse,
        scale=2**top,
        inlier_threshold=pt.inlier_threshold,
        iterations=pt.iterations,
        min_inlier_share=pt.min_inlier_share,
    )
