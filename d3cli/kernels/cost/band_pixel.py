"""Per-tile and per-pixel functions of the band search (``band.py`` says what the bands are).

Compiled for the CPU (``band.py``, ``numba.njit``) and for CUDA (``band_cuda.py``,
``numba.cuda.jit(device=True)``) by :func:`build`: both targets give the same indexes from
the same integer arithmetic.
"""

from __future__ import annotations

from types import SimpleNamespace


def build(jit):
    """``own_band``, ``tiles_within`` and ``hull`` compiled with ``jit``."""

    @jit
    def own_band(t_min, t_max, n_disp, margin):
        """A tile's own band ``[2 min dc - margin, 2 max dc + margin]`` clipped to the range
        (at least one disparity), from the least and largest decided coarse disparity under
        it; the full range ``[0, n_disp)`` when none is decided (``t_max < 0``)."""
        if t_max < 0:
            return 0, n_disp
        lo = min(max(2 * t_min - margin, 0), n_disp - 1)
        hi = min(max(2 * t_max + margin + 1, 1), n_disp)
        return lo, max(hi, lo + 1)

    @jit
    def tiles_within(x, tile, halo, n_tiles):
        """First and last tile (along one axis) within ``halo`` pixels of pixel ``x``."""
        first = min(max((x - halo) // tile, 0), n_tiles - 1)
        last = min(max((x + halo) // tile, 0), n_tiles - 1)
        return first, last

    @jit
    def hull(t_lo, t_hi, ty0, ty1, tx0, tx1, lo, hi):
        """``[lo, hi)`` widened by the bands of the tiles ``ty0..ty1`` x ``tx0..tx1``."""
        for yy in range(ty0, ty1 + 1):
            for xx in range(tx0, tx1 + 1):
                lo = min(lo, t_lo[yy, xx])
                hi = max(hi, t_hi[yy, xx])
        return lo, hi

    return SimpleNamespace(own_band=own_band, tiles_within=tiles_within, hull=hull)
