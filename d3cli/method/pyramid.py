"""Image pyramids and disparity ranges per level (docs/design.md, 'Pyramid and bands')."""

from __future__ import annotations

import math

import numpy as np

from ..kernels.host import halve_area


def downsample(img: np.ndarray) -> np.ndarray:
    """Halve a grey image by 2x2 area averaging.

    An odd last row/column is dropped, so that pixel (u, v) of the result covers exactly
    pixels 2u..2u+1, 2v..2v+1 of the input (the 2x2 patches of inheritance, paper Fig. 3).

    Parameters
    ----------
    img : ndarray, float32, (H, W)

    Returns
    -------
    ndarray, float32, (H // 2, W // 2)
    """
    # the kernel: the float32 sum of the four, in that order, times 0.25 (a NumPy
    # expression's bytes, bit for bit; d3cli.kernels.pyramid)
    return halve_area(img)


def build_pyramid(img: np.ndarray, levels: int) -> list[np.ndarray]:
    """List of ``levels`` images, full resolution first, each half the previous."""
    pyramid = [np.ascontiguousarray(img, dtype=np.float32)]
    for _ in range(levels - 1):
        pyramid.append(downsample(pyramid[-1]))
    return pyramid


def level_max_disparity(max_disparity: int, level: int) -> int:
    """ceil(dmax / 2^level): the disparity bound of ``level`` (0 = full resolution)."""
    return max(1, math.ceil(max_disparity / (2 ** level)))


def usable_levels(shape: tuple[int, int], levels: int, *, min_size: int = 8) -> int:
    """The number of levels (<= ``levels``) whose coarsest image is at least ``min_size``."""
    h, w = shape
    k = 1
    while k < levels and min(h >> k, w >> k) >= min_size:
        k += 1
    return k
