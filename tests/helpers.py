"""Small synthetic stereo pairs and image writers shared by the tests (no fixtures)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def textured_pair(shift: int, size: tuple[int, int] = (48, 96), *, seed: int = 0, colour: bool = False):
    """A rectified pair with one constant disparity ``shift`` and its ground truth.

    The left view is a smoothed random texture; the right view is the same texture
    shifted so that left ``(u, v)`` matches right ``(u - shift, v)``.

    Returns
    -------
    left, right : ndarray, uint8, (H, W) or (H, W, 3)
    gt : ndarray, float32, (H, W)
        ``shift`` everywhere, ``inf`` in the first ``shift`` columns (no match exists).
    """
    height, width = size
    rng = np.random.default_rng(seed)
    channels = 3 if colour else 1
    noise = rng.uniform(0, 255, size=(height, width + shift, channels)).astype(np.float32)
    # A light blur keeps the texture matchable by window costs but not flat.
    tex = cv2.GaussianBlur(noise, (0, 0), 0.8).reshape(height, width + shift, channels)
    tex = np.clip(np.rint(tex), 0, 255).astype(np.uint8)
    left, right = tex[:, :width], tex[:, shift:shift + width]
    if not colour:
        left, right = left[..., 0], right[..., 0]
    gt = np.full((height, width), float(shift), dtype=np.float32)
    gt[:, :shift] = np.inf
    return np.ascontiguousarray(left), np.ascontiguousarray(right), gt


def write_png(path: Path, img: np.ndarray) -> None:
    """Write an RGB or grey uint8 image with OpenCV (which wants BGR)."""
    if img.ndim == 3:
        img = img[..., ::-1]
    if not cv2.imwrite(str(path), img):
        raise OSError(f"cannot write {path}")
