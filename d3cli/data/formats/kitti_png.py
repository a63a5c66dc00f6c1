"""KITTI disparity PNGs: uint16 = disparity * 256, 0 = invalid."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ...errors import InputError, where_what_fix
from .atomic import atomic_write
from . import images
from .images import _decode_unchanged, _single_channel, regular_file


def read_kitti_png(path: str | os.PathLike) -> np.ndarray:
    """Read a KITTI disparity PNG.

    Parameters
    ----------
    path : str or path-like
        16-bit single-channel PNG, disparity = value / 256, 0 = no ground truth.

    Returns
    -------
    ndarray, float32, (H, W)
        Disparity in pixels, inf where the stored value is 0.
    """
    path = regular_file(path, "disparity file")
    raw = _single_channel(path, _decode_unchanged(path), "KITTI disparity PNG")
    if raw.dtype != np.uint16:
        raise InputError(
            where_what_fix(
                str(path),
                f"KITTI disparity PNGs are 16-bit but this one is {raw.dtype}",
                "give the uint16 PNG (or read it with read_disparity and its scale)",
            )
        )
    disp = raw.astype(np.float32) / np.float32(256.0)
    disp[raw == 0] = np.inf
    return disp


def encode_kitti(disp: np.ndarray) -> np.ndarray:
    """Disparity (float, inf invalid) -> KITTI uint16: round(d * 256) in [1, 65535], 0 invalid."""
    disp = np.asarray(disp, dtype=np.float64)
    if disp.ndim != 2:
        raise ValueError(f"KITTI disparity maps are (H, W), got shape {disp.shape}")
    valid = np.isfinite(disp) & (disp > 0)
    out = np.zeros(disp.shape, dtype=np.uint16)
    out[valid] = np.clip(np.round(disp[valid] * 256.0), 1, 65535).astype(np.uint16)
    return out


def write_kitti_png(path: str | os.PathLike, disp: np.ndarray) -> Path:
    """Write a disparity map as a KITTI uint16 PNG atomically.

    Parameters
    ----------
    path : str or path-like
        Output ``.png`` file.
    disp : ndarray, float, (H, W)
        Disparity in pixels; inf, nan and values <= 0 are written as 0 (invalid), finite
        values as ``round(d * 256)`` clipped to [1, 65535].

    Returns
    -------
    Path
        The written file.
    """
    encoded = encode_kitti(disp)
    return atomic_write(path, lambda tmp: images.write_encoded(tmp, encoded))
