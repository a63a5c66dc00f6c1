"""Cost volumes as bands of disparities per pixel (fine levels search only a band).

A volume is a flat float32 array ``cost`` plus an int32 (H, W, 3) ``index`` holding
``[off, lo, hi]`` per pixel: pixel (u, v) has the disparities ``lo <= d < hi`` and the
cell (u, v, d) is ``cost[off + d]``.  The full-range volume (:func:`dense_index`) is
the band ``[0, D)`` everywhere with ``off = (v W + u) D``, i.e. exactly the (H, W, D)
array with the disparity innermost, so ``cost.reshape(H, W, D)`` is a view of it.

The drivers of :mod:`d3cli.kernels.cpu` and :mod:`d3cli.kernels.cuda` take a
:class:`Volume` or, for convenience (tests, the ablation), a plain (H, W, D) array, and
give back the same kind.  This module is NumPy only (host side).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

#: Largest number of cells of one volume: ``off + d`` is computed from int32 offsets.
MAX_CELLS = 2**31 - 1


class Volume(NamedTuple):
    """A banded cost volume (see the module docstring).

    Attributes
    ----------
    cost : array, float32, (n_cells,)
        The cells, pixel after pixel in row-major order; a backend array.
    index : array, int32, (H, W, 3)
        ``[off, lo, hi]`` per pixel; a backend array.
    n_disp : int
        The level's full range: disparities ``0 .. n_disp - 1`` (``hi <= n_disp``).
    """

    cost: Any
    index: Any
    n_disp: int

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the level."""
        return int(self.index.shape[0]), int(self.index.shape[1])


def dense_index(height: int, width: int, n_disp: int) -> np.ndarray:
    """Index of the full-range volume: band ``[0, n_disp)`` at ``off = (v W + u) n_disp``.

    Raises
    ------
    MemoryError
        The volume would have more than :data:`MAX_CELLS` cells.
    """
    n_cells = int(height) * int(width) * int(n_disp)
    if n_cells > MAX_CELLS:
        raise MemoryError(f"a {height}x{width}x{n_disp} cost volume has more than 2^31 cells")
    index = np.empty((height, width, 3), np.int32)
    index[:, :, 0] = (np.arange(height * width, dtype=np.int64) * n_disp).reshape(height, width)
    index[:, :, 1] = 0
    index[:, :, 2] = n_disp
    return index


def banded_index(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, int]:
    """Index of a volume storing the bands ``lo <= d < hi`` (int arrays (H, W)), packed.

    Returns
    -------
    index : ndarray, int32, (H, W, 3)
    n_cells : int
        Length of the flat cost array.
    """
    lo = np.asarray(lo, np.int64)
    hi = np.maximum(np.asarray(hi, np.int64), lo)
    sizes = (hi - lo).ravel()
    base = np.empty(sizes.size + 1, np.int64)
    base[0] = 0
    np.cumsum(sizes, out=base[1:])
    n_cells = int(base[-1])
    if n_cells > MAX_CELLS:
        raise MemoryError(f"a banded cost volume of {n_cells} cells has more than 2^31 cells")
    index = np.empty(lo.shape + (3,), np.int32)
    index[:, :, 0] = base[:-1].reshape(lo.shape) - lo
    index[:, :, 1] = lo
    index[:, :, 2] = hi
    return index, n_cells


def is_dense(index: np.ndarray, n_disp: int) -> bool:
    """Whether a host index is the full-range layout of :func:`dense_index`."""
    h, w = index.shape[:2]
    return bool((index[:, :, 1] == 0).all() and (index[:, :, 2] == n_disp).all()
                and (index[:, :, 0].ravel() == np.arange(h * w, dtype=np.int64) * n_disp).all())


def to_dense(cost: np.ndarray, index: np.ndarray, n_disp: int, *, fill: float = np.nan) -> np.ndarray:
    """The (H, W, n_disp) array of a host volume; cells outside a band hold ``fill``."""
    cost = np.asarray(cost)
    index = np.asarray(index)
    h, w = index.shape[:2]
    out = np.full((h, w, n_disp), fill, np.float32)
    d = np.arange(n_disp)
    inside = (d >= index[:, :, 1:2]) & (d < index[:, :, 2:3])
    flat = index[:, :, 0:1].astype(np.int64) + d
    out[inside] = cost[flat[inside]]
    return out
