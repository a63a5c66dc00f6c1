"""The one place that runs a method by its name (``--method``).

Each method is declared once, in :data:`d3cli.config.methods.METHOD_SPECS`: its name,
its entry point in :mod:`d3cli.method` or :mod:`d3cli.baselines` and the configuration
it is handed.  :func:`compute_pair` looks the name up there, imports the entry point
and calls it; nothing here names a method.
"""

from __future__ import annotations

import numpy as np

from ..config import METHODS, Config, MethodSpec, method_spec
from ..errors import ConfigError
from ..method import DisparityResult


def spec_of(method: str) -> MethodSpec:
    """The :class:`~d3cli.config.MethodSpec` of ``method``.

    Raises
    ------
    ConfigError
        No method of that name.
    """
    spec = method_spec(method)
    if spec is None:
        raise ConfigError(f"--method {method}: unknown method; use one of {', '.join(METHODS)}")
    return spec


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
    method : str
        One of :data:`d3cli.config.METHODS`.
    cfg : Config
        Full configuration; the method is handed its own section
        (:attr:`~d3cli.config.MethodSpec.section`) or the whole of it.
    left, right : ndarray, (H, W) or (H, W, 3)
        Raw images of equal shape (any dtype).
    max_disparity : int
        Largest disparity searched, pixels.
    pair_dir : path-like, optional
        Folder of the pair's input images, handed to a method that reads per-pair files
        there (d3stereo: a relative ``features.npz``).

    Returns
    -------
    DisparityResult

    Raises
    ------
    ConfigError
        No method of that name.
    """
    spec = spec_of(method)
    handed = cfg if spec.section is None else getattr(cfg, spec.section)
    extra = {"pair_dir": pair_dir} if spec.pair_dir else {}
    return spec.entry_point()(left, right, max_disparity=max_disparity, cfg=handed, **extra)
