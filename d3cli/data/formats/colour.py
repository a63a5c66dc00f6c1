"""Disparity maps as colour pictures (turbo colour map, black = invalid)."""

from __future__ import annotations

import cv2
import numpy as np


def colorize_disparity(disp: np.ndarray, vmin: float, vmax: float) -> np.ndarray:
    """Colour-code a disparity map over a fixed range (turbo colour map).

    Parameters
    ----------
    disp : ndarray, float, (H, W)
        Disparity in pixels; non-finite = invalid.
    vmin, vmax : float
        Disparities mapped to the two ends of the colour map (values outside clip).

    Returns
    -------
    ndarray, uint8, (H, W, 3)
        RGB image; invalid pixels black.
    """
    if not vmax > vmin:
        raise ValueError(f"colorize_disparity needs vmax > vmin, got vmin={vmin}, vmax={vmax}")
    disp = np.asarray(disp, dtype=np.float32)
    valid = np.isfinite(disp)
    scaled = np.zeros(disp.shape, dtype=np.float32)
    scaled[valid] = (disp[valid] - vmin) / (vmax - vmin)
    levels = np.round(np.clip(scaled, 0.0, 1.0) * 255.0).astype(np.uint8)
    bgr = cv2.applyColorMap(levels, cv2.COLORMAP_TURBO)
    bgr[~valid] = 0
    return np.ascontiguousarray(bgr[:, :, ::-1])
