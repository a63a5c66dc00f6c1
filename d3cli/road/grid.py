"""The measuring grid: the resolution potholes and bumps are found and measured at.

A map at least twice :data:`GRID_COLUMNS` pixels wide is measured on cells of ``step x
step`` pixels (``step = width // GRID_COLUMNS``: 2 for 1280 columns, 3 for 1920), each
holding the mean disparity of its pixels.  The disparity of a road pair is
matched with a 25-pixel window and smoothed over a radius of 15 (``configs/road.yaml``),
so its errors are correlated over about 30 pixels (``noise_cell_px``) and a 2x2 cell
holds no detail the map has: the depths, areas and volumes read the same, and every
per-pixel step of the road report (median filter, rings, walls, splitting, noise) costs a
quarter.  The re-match (:mod:`d3cli.road.rematch`) and the match margin stay at the
images' resolution (sub-pixel disparities need the image's own pixels); their maps are
brought to the grid after matching.

:class:`Grid` owns the correspondence: the camera of the grid (a cell is a pixel of an
image ``step`` times smaller), the per-pixel settings in grid cells, the maps down to the
grid and the defects (their boxes, centroids, outlines and masks) back to the image's
pixels.  May import numpy, the road package's own modules and the standard library.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .compiled import cell_means
from .confidence import ConfidenceRules
from .defects import outline
from .pointcloud import Camera
from .threads import map_on_threads

#: A map at least twice as wide is measured on cells of ``width // GRID_COLUMNS`` pixels.
GRID_COLUMNS = 640


def grid_step(shape: tuple) -> int:
    """Side of a cell, pixels, for a map of ``shape`` (H, W): ``W // GRID_COLUMNS``, at least 1."""
    return max(1, int(shape[1]) // GRID_COLUMNS)


def _odd(x: float) -> int:
    """The odd integer nearest ``x``, at least 1 (a filter's side)."""
    return max(1, 2 * int(round((x - 1) / 2)) + 1)


@dataclass(frozen=True)
class Grid:
    """Cells of ``step x step`` pixels over an image of ``shape`` (H, W) pixels; the last row
    and column of cells hold what is left of the image when ``step`` does not divide it."""

    step: int
    shape: tuple

    @classmethod
    def for_shape(cls, shape: tuple, step: int | None = None) -> "Grid":
        """The grid of a map of ``shape``: cells of ``step`` pixels, by default :func:`grid_step`'s."""
        return cls(grid_step(shape) if step is None else int(step), tuple(int(n) for n in shape[:2]))

    @property
    def cells(self) -> tuple:
        """(rows, columns) of cells."""
        return tuple(-(-n // self.step) for n in self.shape)

    # -- the camera and the settings in cells ---------------------------------------------

    def camera(self, camera: Camera) -> Camera:
        """The camera whose pixels are the cells: a cell's centre, pixel ``s i + (s - 1) / 2``
        of the image, is its pixel ``i``; disparities in cells are ``d / s``."""
        s = self.step
        if s == 1:
            return camera
        return Camera(f=camera.f / s, baseline=camera.baseline, cx=(camera.cx - (s - 1) / 2) / s,
                      cy=(camera.cy - (s - 1) / 2) / s, doffs=camera.doffs / s)

    def road(self, road_cfg):
        """``road_cfg`` with its widths in cells (``ring_px``)."""
        if self.step == 1:
            return road_cfg
        return replace(road_cfg, ring_px=max(2, int(round(road_cfg.ring_px / self.step))))

    def tuning(self, tuning):
        """A :class:`~d3cli.road.defects.DefectTuning` with its sizes in cells: lengths
        divided by the step, pixel counts (``peak_px``, ``noise_cell_px``) by its square."""
        s = self.step
        if s == 1:
            return tuning
        return replace(tuning, median_px=max(3, _odd(tuning.median_px / s)),
                       noise_cell_px=tuning.noise_cell_px / s ** 2,
                       split_smooth_px=tuning.split_smooth_px / s,
                       local_noise_px=max(1, int(round(tuning.local_noise_px / s))),
                       peak_px=max(1, math.ceil(tuning.peak_px / s ** 2)),
                       gap_px=max(1, int(round(tuning.gap_px / s))),
                       wall_step_px=max(1, int(round(tuning.wall_step_px / s))))

    def rules(self, rules: ConfidenceRules | None = None) -> ConfidenceRules:
        """``rules`` (default :class:`ConfidenceRules`) with ``spike_px`` in cells."""
        rules = ConfidenceRules() if rules is None else rules
        if self.step == 1:
            return rules
        return replace(rules, spike_px=max(3, _odd(rules.spike_px / self.step)))

    # -- maps down to the grid ------------------------------------------------------------

    def disparities(self, disparity: np.ndarray, finite: np.ndarray, decided: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(disparity, decided) of the cells, the disparity in the grid camera's pixels
        (:meth:`camera`): a cell has a disparity where at least half of its pixels are
        ``finite`` (the mean of theirs, over ``step``; inf elsewhere) and is decided where at
        least half of those were decided by the method (not filled)."""
        if self.step == 1:
            return np.where(finite, disparity, np.inf).astype(np.float32), decided
        disparity = np.ascontiguousarray(disparity, np.float32)
        finite, decided = np.ascontiguousarray(finite, bool), np.ascontiguousarray(decided, bool)
        split = self.cells[0] // 2 * self.step  # the top and bottom halves' cells on both threads
        parts = map_on_threads(lambda rows: cell_means(disparity[rows], finite[rows], decided[rows], self.step),
                               (slice(0, split), slice(split, None)))
        cells, cells_decided = (np.concatenate([p[i] for p in parts]) for i in range(2))
        return cells / np.float32(self.step), cells_decided

    def patched(self, cells: np.ndarray, disparity: np.ndarray, finite: np.ndarray, changed: np.ndarray) -> np.ndarray:
        """``cells`` (:meth:`disparities` of a map) with the cells that hold a pixel of
        ``changed`` made again from ``disparity``, a map that differs from that one only
        there: the same values as :meth:`disparities` of all of ``disparity``, at the cost
        of the changed pixels' bounding box."""
        rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
        if rows.size == 0:
            return cells
        s = self.step
        (i0, i1), (j0, j1) = (rows[0] // s, rows[-1] // s + 1), (cols[0] // s, cols[-1] // s + 1)
        box = (slice(i0 * s, i1 * s), slice(j0 * s, j1 * s))
        out = cells.copy()
        out[i0:i1, j0:j1] = self.for_shape(disparity[box].shape, s).disparities(
            disparity[box], finite[box], np.zeros(finite[box].shape, bool))[0]
        return out

    def decimate(self, every: int) -> int:
        """Every how many-th cell holds as many points of the map as every ``every``-th pixel."""
        return max(1, every // self.step ** 2)

    def any_of(self, mask: np.ndarray) -> np.ndarray:
        """bool cells holding a pixel of ``mask``."""
        if self.step == 1:
            return mask
        s, (h, w), (r, c) = self.step, self.shape, self.cells
        padded = np.zeros((r * s, c * s), bool)
        padded[:h, :w] = mask
        out = np.zeros((r, c), bool)
        for i in range(s):  # s^2 strided ORs: a reduction over reshaped axes costs ten times more
            for j in range(s):
                out |= padded[i::s, j::s]
        return out

    # -- back to the image's pixels -------------------------------------------------------

    def defect(self, defect, cells: np.ndarray):
        """(defect, mask) in the image's pixels of a defect measured on the grid: its mask
        ``cells``' pixels, its box and outline theirs, its centroid the cell centre's pixel."""
        if self.step == 1:
            return defect, cells
        s, (h, w) = self.step, self.shape
        u0, v0, u1, v1 = defect.bbox_px
        bbox = (u0 * s, v0 * s, min(u1 * s + s - 1, w - 1), min(v1 * s + s - 1, h - 1))
        centre = tuple(x * s + (s - 1) / 2 for x in defect.centroid_px)
        box = (slice(bbox[1], bbox[3] + 1), slice(bbox[0], bbox[2] + 1))
        mask = np.zeros(self.shape, bool)  # the cells' pixels, made on the box only
        mask[box] = np.repeat(np.repeat(cells[v0:v1 + 1, u0:u1 + 1], s, axis=0), s, axis=1)[
            :box[0].stop - box[0].start, :box[1].stop - box[1].start]
        shape = outline(mask[box], offset=(bbox[1], bbox[0])) if defect.outline_px else ()
        return replace(defect, bbox_px=bbox, centroid_px=centre, outline_px=shape), mask
