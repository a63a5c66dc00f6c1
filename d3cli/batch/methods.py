"""The one place that maps a method name (``--method``) to code.

- ``d3stereo``: :class:`d3cli.method.D3Stereo` (the paper's method),
- ``sgbm``: OpenCV's semi-global block matching (:func:`d3cli.baselines.sgbm_disparity`),
- ``pt-sgm``: SGBM after the same perspective transformation as PT-D3Stereo
  (:func:`d3cli.baselines.pt_sgm_disparity`),
- ``elas``, ``pandora-sgm``: optional peers (:mod:`d3cli.baselines.peers`, extra ``peers``).
"""

from __future__ import annotations

import numpy as np

from ..baselines import elas_disparity, pandora_sgm_disparity, pt_sgm_disparity, sgbm_disparity
from ..config import METHODS, Config
from ..errors import ConfigError
from ..method import D3Stereo, DisparityResult


def compute_pair(
    method: str,
    cfg: Config,
    left: np.ndarray,
    right: np.ndarray,
    *,
    max_disparity: int,
    pair_dir=None,
) -> DisparityResult:
    """Run the stereo method named ``method`` on one pair.

    Parameters
    ----------
    method : {"d3stereo", "sgbm", "pt-sgm", "elas", "pandora-sgm"}
    cfg : Config
        Full configuration; each method reads its own sections.
    left, right : ndarray, (H, W) or (H, W, 3)
        Raw images of equal shape (any dtype).
    max_disparity : int
        Largest disparity searched, pixels.
    pair_dir : path-like, optional
        Folder of the pair's input images: where d3stereo looks up a relative
        ``features.npz`` (precomputed feature maps).

    Returns
    -------
    DisparityResult
    """
    if method == "sgbm":
        return sgbm_disparity(left, right, max_disparity=max_disparity, cfg=cfg.sgbm)
    if method == "d3stereo":
        return D3Stereo(cfg).compute(left, right, max_disparity=max_disparity, pair_dir=pair_dir)
    if method == "pt-sgm":
        return pt_sgm_disparity(left, right, max_disparity=max_disparity, cfg=cfg)
    if method == "elas":
        return elas_disparity(left, right, max_disparity=max_disparity, cfg=cfg.peers)
    if method == "pandora-sgm":
        return pandora_sgm_disparity(left, right, max_disparity=max_disparity, cfg=cfg.peers)
    raise ConfigError(f"--method {method}: unknown method; use one of {', '.join(METHODS)}")
