"""OpenCV semi-global block matching (SGBM), the reference baseline.

:func:`fill_holes_rowwise` is the hole filling of the SGBM baselines (the peers' fill
of the comparison tables): an invalid pixel takes the smaller of its nearest valid left
and right neighbours on the same row, i.e. the background side, since holes next to an
object boundary are mostly occlusions of the farther surface.
"""

from __future__ import annotations

import logging
import time

import cv2
import numpy as np

from ..config import SGBMConfig
from ..data.formats import to_grey
from ..errors import InputError
from ..method import DisparityResult

log = logging.getLogger(__name__)

#: Bytes per pixel around OpenCV SGBM: raw images, grey float32 and uint8, int16
#: disparity, float32 disparity and filled copy, valid mask, index maps of the filling.
SGBM_BYTES_PER_PIXEL = 12 + 2 * (4 + 1) + 2 + 2 * 4 + 1 + 4 * 8
#: Rows of SGBM path buffers kept by the one-pass modes (a generous bound).
SGBM_BUFFER_ROWS = 16

_SGBM_MODES = {
    "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
    "hh": cv2.STEREO_SGBM_MODE_HH,
    "3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    "hh4": cv2.STEREO_SGBM_MODE_HH4,
}


def fill_holes_rowwise(disp: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fill invalid pixels from the nearest valid pixels of the same row.

    Each invalid pixel takes the smaller (farther, background-side) of the nearest
    valid values to its left and to its right; a pixel with a valid neighbour on one
    side only takes that one.  Rows without any valid pixel stay ``inf``.

    Parameters
    ----------
    disp : ndarray, float, (H, W)
        Disparity in pixels; values at invalid pixels are ignored.
    valid : ndarray, bool, (H, W)
        True where ``disp`` holds an estimate.  Non-finite values of ``disp`` count as
        invalid even where ``valid`` is True.

    Returns
    -------
    ndarray, float32, (H, W)
        A new array: ``disp`` at valid pixels, the filled value elsewhere.
    """
    disp = np.asarray(disp, dtype=np.float32)
    valid = np.asarray(valid, dtype=bool) & np.isfinite(disp)
    if disp.ndim != 2 or valid.shape != disp.shape:
        raise ValueError(f"disp and valid must be equal 2-D shapes, got {disp.shape} and {valid.shape}")
    h, w = disp.shape
    cols = np.arange(w)
    # Index of the nearest valid pixel at or before each column (-1: none) and at or
    # after it (w: none), by running max/min over the masked column indices.
    left_idx = np.maximum.accumulate(np.where(valid, cols, -1), axis=1)
    right_idx = np.minimum.accumulate(np.where(valid, cols, w)[:, ::-1], axis=1)[:, ::-1]
    left_val = np.take_along_axis(disp, np.clip(left_idx, 0, w - 1), axis=1)
    right_val = np.take_along_axis(disp, np.clip(right_idx, 0, w - 1), axis=1)
    left_val = np.where(left_idx >= 0, left_val, np.inf)
    right_val = np.where(right_idx < w, right_val, np.inf)
    filled = np.minimum(left_val, right_val).astype(np.float32)
    return np.where(valid, disp, filled).astype(np.float32)


def _num_disparities(max_disparity: int) -> int:
    """OpenCV needs a multiple of 16 covering 0..max_disparity."""
    return int(np.ceil((max_disparity + 1) / 16.0)) * 16


def sgbm_peak_bytes(shape, max_disparity: int, cfg) -> int:
    """Estimated peak memory of one SGBM pair (the memory model of ``--method sgbm``).

    OpenCV's int16 path buffers: for the full-DP modes (``hh``, ``hh4``) a cost and a sum
    volume ``(H, W, D16)`` each, for ``sgbm``/``3way`` :data:`SGBM_BUFFER_ROWS` rows of
    them; plus :data:`SGBM_BYTES_PER_PIXEL` of per-pixel maps.

    Parameters
    ----------
    shape : sequence of int
        ``(H, W)`` (or ``(H, W, C)``) of the images, pixels.
    max_disparity : int
        Largest disparity searched, pixels.
    cfg : Config
        Full configuration (its ``sgbm.mode``).

    Returns
    -------
    int
        Bytes, an upper estimate.
    """
    height, width = int(shape[0]), int(shape[1])
    pixels = max(height, 0) * max(width, 0)
    d16 = _num_disparities(max(int(max_disparity), 1))
    rows = height if cfg.sgbm.mode in ("hh", "hh4") else min(height, SGBM_BUFFER_ROWS)
    path_buffers = 2 * rows * width * d16 * 2  # int16 cost + sum buffers
    return int(path_buffers + SGBM_BYTES_PER_PIXEL * pixels)


def sgbm_disparity(
    left: np.ndarray,
    right: np.ndarray,
    *,
    max_disparity: int,
    cfg: SGBMConfig | None = None,
) -> DisparityResult:
    """Disparity by OpenCV StereoSGBM on the grey images.

    Parameters
    ----------
    left, right : ndarray, (H, W) or (H, W, 3), uint8/uint16/float
        Rectified pair of equal shape; converted to grey uint8 with
        :func:`d3cli.data.formats.to_grey`.
    max_disparity : int
        Largest disparity searched, pixels (> 0).  OpenCV searches
        ``numDisparities = ceil((max_disparity + 1) / 16) * 16`` values starting at 0;
        estimates above ``max_disparity`` are treated as invalid.
    cfg : SGBMConfig, optional
        Block size, mode, uniqueness, speckle and left-right parameters; ``fill``
        fills the invalid pixels with :func:`fill_holes_rowwise`.
        P1 = 8 * block_size**2, P2 = 32 * block_size**2 (one channel).

    Returns
    -------
    DisparityResult
        ``disparity`` float32 (H, W) in pixels, ``inf`` where invalid and not filled;
        ``valid`` bool (H, W) where SGBM itself gave an estimate; ``timings`` with
        ``total`` in seconds.
    """

    cfg = cfg if cfg is not None else SGBMConfig()
    if max_disparity < 1:
        raise InputError(f"pair: max disparity {max_disparity} must be >= 1; pass --max-disparity 1 or more")
    t0 = time.perf_counter()
    grey_l = _to_uint8(to_grey(left))
    grey_r = _to_uint8(to_grey(right))
    bs = cfg.block_size
    num_disp = _num_disparities(max_disparity)
    disp, valid = _sgbm_raw(grey_l, grey_r, max_disparity, cfg)
    warnings = []
    if not valid.any():
        warnings.append("sgbm found no valid disparity; the output is empty")
    if cfg.fill:
        disp = fill_holes_rowwise(disp, valid)
    info = {
        "method": "sgbm",
        "backend": "opencv",
        "num_disparities": num_disp,
        "block_size": bs,
        "mode": cfg.mode,
        "filled": bool(cfg.fill),
        "valid_share": float(valid.mean()) if valid.size else 0.0,
    }
    return DisparityResult(
        disparity=disp,
        valid=valid,
        timings={"total": time.perf_counter() - t0},
        info=info,
        warnings=warnings,
    )


def _sgbm_raw(grey_l: np.ndarray, grey_r: np.ndarray, max_disparity: int, cfg: SGBMConfig):
    """OpenCV SGBM on uint8 grey images: float32 disparity (inf invalid) and validity.

    OpenCV needs ``W - numDisparities > block_size // 2`` (it fails with a memory or
    buffer assertion otherwise); narrower images are padded on the right by replicating
    the last column, and the padding is cropped from the result.
    """
    if grey_l.shape != grey_r.shape:
        raise InputError(
            f"pair: left is {grey_l.shape[0]}x{grey_l.shape[1]} but right is "
            f"{grey_r.shape[0]}x{grey_r.shape[1]}; a stereo pair needs equal sizes"
        )
    bs = cfg.block_size
    width = grey_l.shape[1]
    need = _num_disparities(max_disparity) + bs // 2 + 1
    if width < need:
        pad = ((0, 0), (0, need - width))
        grey_l = np.pad(grey_l, pad, mode="edge")
        grey_r = np.pad(grey_r, pad, mode="edge")
    matcher = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=_num_disparities(max_disparity),
        blockSize=bs,
        P1=8 * bs * bs,
        P2=32 * bs * bs,
        disp12MaxDiff=cfg.disp12_max_diff,
        uniquenessRatio=cfg.uniqueness_ratio,
        speckleWindowSize=cfg.speckle_window,
        speckleRange=cfg.speckle_range,
        mode=_SGBM_MODES[cfg.mode],
    )
    raw = matcher.compute(grey_l, grey_r)[:, :width]  # int16, 4 fractional bits
    disp = raw.astype(np.float32) / 16.0
    valid = (disp >= 0) & (disp <= max_disparity)
    disp[~valid] = np.inf
    return disp, valid


def _to_uint8(grey: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)
