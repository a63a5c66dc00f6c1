"""Optional peers for side-by-side tables: ELAS (libelas via pyelas) and pandora's
census + SGM pipeline (CNES, with pandora_plugin_libsgm).

Neither is a dependency: each is imported when its method runs, and a missing package is
a :class:`~d3cli.errors.BackendUnavailable` naming the install command (extra ``peers``).
Both run with the settings of the comparison in the README, every one a key of
the ``peers`` config section or a constant named here:

- ELAS: the library's Middlebury or robotics preset (``peers.elas_preset``), range
  [0, max disparity]; its invalid estimates (negative values) become holes.
- pandora: census 5x5, SGM with P1 8 / P2 32 (constant penalties), WTA, vfit sub-pixel,
  median 3, accurate cross-checking with threshold 1, median 3 again.  pandora defines
  the disparity as x_right - x_left, so it searches [-max disparity, 0] and the sign is
  flipped on the way out.

Holes are filled row-wise like SGBM's (background side) when ``peers.fill`` is true, so
that a dense comparison is fair; ``valid`` always marks what the peer decided itself.
"""

from __future__ import annotations

import os
import tempfile
import time

import cv2
import numpy as np

from ..config import INSTALL_ELAS, INSTALL_PANDORA, PeersConfig
from ..data.formats import to_grey
from ..errors import BackendUnavailable, InputError
from ..method import DisparityResult
from .sgbm import SGBM_BYTES_PER_PIXEL, _to_uint8, fill_holes_rowwise

#: Bytes per pixel around libelas: 8-bit images, two 16-byte descriptor images, two float
#: disparity maps, the support grid and the filled copy (a generous bound).
ELAS_BYTES_PER_PIXEL = 2 + 2 * 16 + 2 * 4 + 16 + SGBM_BYTES_PER_PIXEL

#: pandora pipeline of the comparison (census 5, SGM 8/32, WTA, vfit, median, cross-check).
PANDORA_CENSUS_WINDOW = 5
PANDORA_CROSS_CHECK = 1.0
PANDORA_MEDIAN = 3


def elas_peak_bytes(shape, max_disparity: int, cfg) -> int:
    """Estimated peak memory of one ELAS pair: :data:`ELAS_BYTES_PER_PIXEL` per pixel."""
    return int(ELAS_BYTES_PER_PIXEL * max(int(shape[0]), 0) * max(int(shape[1]), 0))


def pandora_sgm_peak_bytes(shape, max_disparity: int, cfg) -> int:
    """Estimated peak memory of one pandora census + SGM pair: the float32 cost volume,
    SGM's aggregated volume and the right view's for the cross-check, plus an xarray copy
    of each (a generous four volumes), and SGBM's per-pixel maps around them."""
    pixels = max(int(shape[0]), 0) * max(int(shape[1]), 0)
    n_disp = max(int(max_disparity), 0) + 1
    return int(4 * pixels * n_disp * 4 + SGBM_BYTES_PER_PIXEL * pixels)


def _checked_pair(left, right, max_disparity: int) -> tuple[np.ndarray, np.ndarray]:
    if max_disparity < 1:
        raise InputError(f"pair: max disparity {max_disparity} must be >= 1; pass --max-disparity 1 or more")
    grey_l, grey_r = to_grey(left), to_grey(right)
    if grey_l.shape != grey_r.shape:
        raise InputError(f"pair: left is {grey_l.shape[0]}x{grey_l.shape[1]} but right is "
                         f"{grey_r.shape[0]}x{grey_r.shape[1]}; a stereo pair needs equal sizes")
    return grey_l, grey_r


def _result(disp: np.ndarray, valid: np.ndarray, *, method: str, t0: float, cfg: PeersConfig, info: dict):
    disp = np.where(valid, disp, np.inf).astype(np.float32)
    warnings = [] if valid.any() else [f"{method} found no valid disparity; the output is empty"]
    if cfg.fill and valid.any():
        disp = fill_holes_rowwise(disp, valid)
    info = {"method": method, "filled": bool(cfg.fill), "valid_share": float(valid.mean()), **info}
    return DisparityResult(disparity=disp, valid=valid, timings={"total": time.perf_counter() - t0},
                           info=info, warnings=warnings)


def elas_disparity(left, right, *, max_disparity: int, cfg: PeersConfig | None = None) -> DisparityResult:
    """Disparity by ELAS (Geiger et al., ACCV 2010) through pyelas.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3)
        Rectified pair of equal shape, any dtype (converted to 8-bit grey).
    max_disparity : int, keyword-only
        Largest disparity searched, pixels.
    cfg : PeersConfig, optional, keyword-only
        ``elas_preset`` and ``fill``.

    Raises
    ------
    BackendUnavailable
        pyelas is not installed (the message names the install command).
    """
    cfg = cfg if cfg is not None else PeersConfig()
    try:
        import elas
    except ImportError:
        raise BackendUnavailable(f"--method elas needs pyelas; install it with {INSTALL_ELAS}") from None
    t0 = time.perf_counter()
    grey_l, grey_r = _checked_pair(left, right, max_disparity)
    matcher = elas.Elas()
    matcher.set_preset(elas.PRESET_ROBOTICS if cfg.elas_preset == "robotics" else elas.PRESET_MIDDLEBURY)
    matcher.disp_min, matcher.disp_max = 0, int(max_disparity)
    disp_l, _ = matcher.process(np.ascontiguousarray(_to_uint8(grey_l)), np.ascontiguousarray(_to_uint8(grey_r)))
    disp_l = np.asarray(disp_l, dtype=np.float32)
    valid = np.isfinite(disp_l) & (disp_l >= 0)
    return _result(disp_l, valid, method="elas", t0=t0, cfg=cfg,
                   info={"backend": "libelas", "preset": cfg.elas_preset})


def pandora_config(left_path: str, right_path: str, max_disparity: int, cfg: PeersConfig) -> dict:
    """The pandora user configuration of the comparison for two image files."""
    return {
        "input": {
            "left": {"img": left_path, "disp": [-int(max_disparity), 0], "nodata": "NaN"},
            "right": {"img": right_path, "nodata": "NaN"},
        },
        "pipeline": {
            "matching_cost": {"matching_cost_method": "census", "window_size": PANDORA_CENSUS_WINDOW, "subpix": 1},
            "optimization": {"optimization_method": "sgm",
                             "penalty": {"P1": cfg.pandora_p1, "P2": cfg.pandora_p2,
                                         "penalty_method": "sgm_penalty", "p2_method": "constant"}},
            "disparity": {"disparity_method": "wta", "invalid_disparity": "NaN"},
            "refinement": {"refinement_method": "vfit"},
            "filter": {"filter_method": "median", "filter_size": PANDORA_MEDIAN},
            "validation": {"validation_method": "cross_checking_accurate",
                           "cross_checking_threshold": PANDORA_CROSS_CHECK},
            "filter.after.validation": {"filter_method": "median", "filter_size": PANDORA_MEDIAN},
        },
    }


def pandora_sgm_disparity(left, right, *, max_disparity: int, cfg: PeersConfig | None = None) -> DisparityResult:
    """Disparity by pandora's census + SGM pipeline (CNES).

    The grey images are handed to pandora as float32 TIFF files in a temporary folder
    (pandora reads its inputs with rasterio).

    Raises
    ------
    BackendUnavailable
        pandora or its libsgm plugin is not installed (the message names the command).
    """
    cfg = cfg if cfg is not None else PeersConfig()
    try:
        import pandora
        from pandora import check_configuration, import_plugin
        from pandora.img_tools import create_dataset_from_inputs
        from pandora.state_machine import PandoraMachine
        import pandora_plugin_libsgm  # noqa: F401 # pyflakes: ignore - the SGM optimisation lives here
    except ImportError:
        raise BackendUnavailable(f"--method pandora-sgm needs pandora with its SGM plugin; install it with "
                                 f"{INSTALL_PANDORA}") from None
    t0 = time.perf_counter()
    grey_l, grey_r = _checked_pair(left, right, max_disparity)
    import_plugin()
    with tempfile.TemporaryDirectory(prefix="d3stereo-pandora-") as tmp:
        paths = [os.path.join(tmp, name) for name in ("left.tif", "right.tif")]
        for path, grey in zip(paths, (grey_l, grey_r)):
            if not cv2.imwrite(path, grey.astype(np.float32)):
                raise InputError(f"{path}: cannot write pandora's input; check the temporary folder")
        machine = PandoraMachine()
        conf = check_configuration.check_conf(pandora_config(*paths, max_disparity, cfg), machine)
        img_left = create_dataset_from_inputs(conf["input"]["left"])
        img_right = create_dataset_from_inputs(conf["input"]["right"])
        out_left, _ = pandora.run(machine, img_left, img_right, conf)
    disp = -np.asarray(out_left["disparity_map"].values, dtype=np.float32)  # x_right - x_left -> d
    valid = np.isfinite(disp) & (disp >= 0)
    return _result(disp, valid, method="pandora-sgm", t0=t0, cfg=cfg,
                   info={"backend": "pandora", "p1": cfg.pandora_p1, "p2": cfg.pandora_p2})
