"""Shared fixtures: tiny synthetic stereo pairs built in tmp_path."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest


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


@pytest.fixture
def make_pair_folder():
    """Factory: ``make_pair_folder(root, name="pair", shift=6, size=(48, 96), ...) -> Path``.

    Writes ``root/name/left.png``, ``right.png`` and (``gt=True``) ``disp_gt.pfm`` with a
    SOURCE.txt stating ``gt_scale: 1`` and ``gt_invalid: inf``.
    """

    def _make(root, name="pair", shift=6, size=(48, 96), *, seed=0, colour=False, gt=True):
        from d3cli.io import write_pfm

        folder = Path(root) / name
        folder.mkdir(parents=True, exist_ok=True)
        left, right, disp = textured_pair(shift, size, seed=seed, colour=colour)
        write_png(folder / "left.png", left)
        write_png(folder / "right.png", right)
        if gt:
            write_pfm(folder / "disp_gt.pfm", disp)
            (folder / "SOURCE.txt").write_text(
                "provenance: synthetic test pair (tests/conftest.py)\ngt_scale: 1\ngt_invalid: inf\n"
            )
        return folder

    return _make


@pytest.fixture
def pairs_root(tmp_path, make_pair_folder):
    """A folder of three small pair folders ``a``, ``b``, ``c`` (shifts 4, 6, 8)."""
    root = tmp_path / "pairs"
    for i, name in enumerate("abc"):
        make_pair_folder(root, name, shift=4 + 2 * i, seed=i)
    return root
