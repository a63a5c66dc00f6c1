"""The road surface ``z = h(x, y)``: multi-octave value noise, cross slope and grade,
elliptical potholes with rough floors and an optional bump; the sampled height field
with per-tile Lipschitz bounds for sphere tracing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .potholes import Pothole, normalised_radius as _normalised_radius, pothole_weight as _pothole_weight
from .potholes import FAMILIES, varied_pothole
from .rig import StereoRig


@dataclass(frozen=True)
class _HeightField:
    """The road surface sampled on a regular grid; bilinear in between."""

    h: np.ndarray  # float64 (ny, nx), metres
    grad_x: np.ndarray  # float64 (ny, nx), dh/dx
    grad_y: np.ndarray
    lipschitz: np.ndarray  # float64 (ty, tx): bound on |grad h| near each tile
    tile: int  # tile size in grid cells
    x0: float
    y0: float
    spacing: float
    pothole_weight: np.ndarray  # float32 (ny, nx) in [0, 1], 1 = pothole floor
    # How far the potholes (profiles, floor relief, water) lower the road, metres, float64
    # (ny, nx); 1 where water stands.  None/(1, 1) zeros without potholes.
    sink: np.ndarray | None = None
    water: np.ndarray | None = None


def _value_noise(rng: np.random.Generator, shape: tuple[int, int], cell: float) -> np.ndarray:
    """Smooth zero-mean noise, float64 ``shape``, with features ``cell`` grid units apart.

    Bicubic interpolation of a random lattice (value noise, a cheap Perlin stand-in).
    Lattices finer than two grid units would alias, so they degrade to white noise with
    the variance that averaging over a grid cell leaves.
    """
    ny, nx = shape
    if cell < 2.0:
        return rng.standard_normal(shape) * min(1.0, cell / 2.0)
    gy, gx = int(math.ceil(ny / cell)) + 3, int(math.ceil(nx / cell)) + 3
    lattice = rng.standard_normal((gy, gx))
    big = cv2.resize(lattice, (int(round(gx * cell)), int(round(gy * cell))), interpolation=cv2.INTER_CUBIC)
    oy, ox = int(rng.integers(0, max(big.shape[0] - ny, 0) + 1)), int(rng.integers(0, max(big.shape[1] - nx, 0) + 1))
    return big[oy:oy + ny, ox:ox + nx] / 0.7  # bicubic lattice noise has std ~0.7


def _fractal_noise(rng, shape, spacing: float, wavelengths_m, exponent: float = 0.8) -> np.ndarray:
    """Sum of value-noise octaves with amplitude ~ wavelength**exponent, unit std."""
    total = np.zeros(shape)
    for wavelength in wavelengths_m:
        total += wavelength ** exponent * _value_noise(rng, shape, wavelength / spacing)
    return (total - total.mean()) / max(total.std(), 1e-12)


def _sample_road_point(rng, rig: StereoRig) -> tuple[float, float]:
    """World (x, y) of a random point of the plane z = 0 seen in the middle of the
    left image."""
    left, _ = rig.centres()
    u = rng.uniform(0.2, 0.8) * rig.width
    v = rng.uniform(0.25, 0.85) * rig.height
    direction = rig.ray_directions(np.array(u), np.array(v))
    t = -left[2] / direction[2]
    return float(left[0] + t * direction[0]), float(left[1] + t * direction[1])


def _classic_pothole(rng, x: float, y: float) -> Pothole:
    """A classic pothole centred on world (x, y): size, aspect, depth, walls, outline
    and orientation drawn from ``rng``."""
    diameter = rng.uniform(0.2, 0.8)
    aspect = rng.uniform(0.6, 1.0)
    depth = rng.uniform(0.02, 0.06)
    semi_a = diameter / 2.0
    semi_b = semi_a * aspect
    # Walls at least 1.2x as wide as the pothole is deep keep slopes below ~1.3.
    wall = max(1.2 * depth, rng.uniform(0.25, 0.5) * semi_b)
    flat_fraction = max(0.0, 1.0 - wall / semi_b)
    wobble = (rng.uniform(0.0, 0.12), rng.uniform(0, 2 * math.pi),
              rng.uniform(0.0, 0.08), rng.uniform(0, 2 * math.pi))
    return Pothole(x, y, semi_a, semi_b, rng.uniform(0, math.pi), depth, flat_fraction, wobble)


def _sample_potholes(rng, rig: StereoRig, count: int, shape_rng=None) -> list[Pothole]:
    """Potholes centred on road points seen near the middle of the left image; with a
    ``shape_rng``, of the families of :mod:`.potholes` (else all classic)."""
    holes = []
    # Families cycle from a random start: every family appears about equally often.
    start = int(shape_rng.integers(0, len(FAMILIES))) if shape_rng is not None else 0
    for _ in range(count):
        x, y = _sample_road_point(rng, rig)
        holes.append(_classic_pothole(rng, x, y))
        if shape_rng is not None:
            holes[-1] = varied_pothole(holes[-1], shape_rng, FAMILIES[(start + len(holes) - 1) % len(FAMILIES)])
    return holes


def _grid_window(hole: Pothole, x0: float, y0: float, spacing: float, shape) -> tuple[slice, slice]:
    reach = 1.25 * max(hole.semi_a, hole.semi_b)
    cols = slice(max(int((hole.x - reach - x0) / spacing), 0), min(int((hole.x + reach - x0) / spacing) + 2, shape[1]))
    rows = slice(max(int((hole.y - reach - y0) / spacing), 0), min(int((hole.y + reach - y0) / spacing) + 2, shape[0]))
    return rows, cols


def _grid_coords(x0, y0, spacing, rows: slice, cols: slice):
    xs = x0 + spacing * np.arange(cols.start, cols.stop)
    ys = y0 + spacing * np.arange(rows.start, rows.stop)
    return np.meshgrid(xs, ys)


def _pothole_map(holes, x0, y0, spacing, shape) -> np.ndarray:
    """Max over potholes of their depth profile weight, float32 ``shape``."""
    weight = np.zeros(shape, np.float32)
    for hole in holes:
        rows, cols = _grid_window(hole, x0, y0, spacing, shape)
        xx, yy = _grid_coords(x0, y0, spacing, rows, cols)
        np.maximum(weight[rows, cols], _pothole_weight(hole, xx, yy), out=weight[rows, cols])
    return weight


def _lipschitz_tiles(h: np.ndarray, spacing: float, tile: int) -> np.ndarray:
    """Per-tile bound on |grad h| of the bilinear surface, dilated by one tile.

    Inside a bilinear cell dh/dx lies between the x-differences of its two rows, so
    the maximum absolute grid difference bounds the slope.
    """
    ax = np.zeros_like(h)
    ay = np.zeros_like(h)
    ax[:, :-1] = np.abs(np.diff(h, axis=1)) / spacing
    ay[:-1, :] = np.abs(np.diff(h, axis=0)) / spacing
    ny, nx = h.shape
    ty, tx = -(-ny // tile), -(-nx // tile)

    def tile_max(a):
        padded = np.zeros((ty * tile + 1, tx * tile + 1))
        padded[:ny, :nx] = a
        padded[ny:, :nx] = a[-1:, :]
        padded[:, nx:] = padded[:, nx - 1:nx]
        # Cells on a tile's far edge belong to it too (+1 overlap).
        core = padded[:-1, :-1].reshape(ty, tile, tx, tile).max(axis=(1, 3))
        edge_r = padded[:-1, tile::tile][:, :tx].reshape(ty, tile, -1).max(axis=1)
        edge_b = padded[tile::tile, :-1][:ty].reshape(-1, tx, tile).max(axis=2)
        return np.maximum(np.maximum(core, edge_r), edge_b)

    bound = np.hypot(tile_max(ax), tile_max(ay)) * 1.05 + 1e-4
    return cv2.dilate(bound, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)


@dataclass(frozen=True)
class _RoadShape:
    """Random shape parameters of one road (world metres)."""

    undulation_m: float  # std of the multi-octave noise (clipped at 5 std)
    cross_slope: float  # dz/dx
    grade: float  # dz/dy
    holes: tuple[Pothole, ...]
    bump: tuple[float, float, float, float, float] | None  # x, y, sigma_x, sigma_y, height
    flat: bool

    def height_range(self, bounds) -> tuple[float, float]:
        """Bounds (z_low, z_high) the surface cannot leave over ``bounds``."""
        if self.flat:
            return -1e-3, 1e-3
        x_min, x_max, y_min, y_max = bounds
        x_min, y_min, x_max, y_max = x_min - 0.1, y_min - 0.1, x_max + 0.1, y_max + 0.1  # grid overhang
        tilt = abs(self.cross_slope) * max(abs(x_min), abs(x_max)) + abs(self.grade) * max(abs(y_min), abs(y_max))
        wave = 5.0 * self.undulation_m
        hole = max((h.depth + h.roughness_m * 5.0 for h in self.holes), default=0.0)
        bump = self.bump[4] if self.bump is not None else 0.0
        return -(tilt + wave + hole) - 1e-3, tilt + wave + bump + 1e-3


def _sample_road(rng, rig: StereoRig, potholes: int | None, flat: bool, shapes: str = "varied") -> _RoadShape:
    """Road shape; ``shapes`` "varied" draws the pothole families of :mod:`.potholes` from a
    stream of their own (the rest of the scene is that of the seed), "classic" only the
    flat-floored potholes with raised-cosine walls of earlier versions."""
    if flat:
        return _RoadShape(0.0, 0.0, 0.0, (), None, True)
    count = int(rng.integers(0, 4)) if potholes is None else int(potholes)
    holes = tuple(_sample_potholes(rng, rig, count, rng.spawn(1)[0] if shapes == "varied" else None))
    bump = None
    if rng.uniform() < 0.35:
        bx, by = _sample_road_point(rng, rig)
        bump = (bx, by, rng.uniform(0.08, 0.25), rng.uniform(0.05, 0.2), rng.uniform(0.01, 0.025))
    return _RoadShape(rng.uniform(1.5e-3, 3.5e-3), rng.uniform(-0.015, 0.015), rng.uniform(-0.015, 0.015),
                      holes, bump, False)


def _build_height_field(rng, road: _RoadShape, bounds, spacing: float) -> _HeightField:
    x_min, x_max, y_min, y_max = bounds
    nx = int(math.ceil((x_max - x_min) / spacing)) + 2
    ny = int(math.ceil((y_max - y_min) / spacing)) + 2
    shape = (ny, nx)
    weight = _pothole_map(road.holes, x_min, y_min, spacing, shape)
    if road.flat:
        h = np.zeros(shape)
    else:
        octaves = _fractal_noise(rng, shape, spacing, (1.6, 0.8, 0.4, 0.2, 0.1, 0.05))
        xs = x_min + spacing * np.arange(nx)
        ys = y_min + spacing * np.arange(ny)
        h = road.undulation_m * np.clip(octaves, -5.0, 5.0) + road.cross_slope * xs[None, :] + road.grade * ys[:, None]
        base = h.copy()  # the road without potholes: what their depth is measured from
        # Overlapping potholes merge into one (the deepest wins), they do not add up.
        sink = np.zeros(shape)
        for hole in road.holes:
            rows, cols = _grid_window(hole, x_min, y_min, spacing, shape)
            xx, yy = _grid_coords(x_min, y_min, spacing, rows, cols)
            np.maximum(sink[rows, cols], hole.depth * _pothole_weight(hole, xx, yy), out=sink[rows, cols])
        h -= sink
        if road.holes:
            # Broken, rough floors: a few millimetres of relief where the road is gone
            # (classic potholes: 2.5 mm scale; rough ones more).
            relief = np.clip(np.abs(_fractal_noise(rng, shape, spacing, (0.06, 0.03, 0.015))), 0.0, 5.0)
            h -= _roughness_map(road.holes, x_min, y_min, spacing, shape) * relief
        if road.bump is not None:
            bx, by, sx, sy, height = road.bump
            bump = height * np.exp(-0.5 * (((xs[None, :] - bx) / sx) ** 2 + ((ys[:, None] - by) / sy) ** 2))
            h += bump
            base = base + bump
    water = _fill_water(road.holes, h, base, x_min, y_min, spacing) if not road.flat else None
    grad_y, grad_x = np.gradient(h, spacing)
    tile = 16
    return _HeightField(h, grad_x, grad_y, _lipschitz_tiles(h, spacing, tile), tile, x_min, y_min, spacing, weight,
                        sink=None if road.flat else base - h, water=water)


def _roughness_map(holes, x0, y0, spacing, shape) -> np.ndarray:
    """Floor relief scale (metres per unit of |noise|): max over potholes of their
    ``roughness_m`` times their profile weight."""
    # float32 like the weight map: classic potholes (one scale) give the relief of
    # earlier versions bit for bit.
    rough = np.zeros(shape, np.float32)
    for hole in holes:
        rows, cols = _grid_window(hole, x0, y0, spacing, shape)
        xx, yy = _grid_coords(x0, y0, spacing, rows, cols)
        w = _pothole_weight(hole, xx, yy).astype(np.float32)
        np.maximum(rough[rows, cols], hole.roughness_m * w, out=rough[rows, cols])
    return rough


def _fill_water(holes, h: np.ndarray, base: np.ndarray, x0, y0, spacing) -> np.ndarray | None:
    """Water in the potholes with ``water_fill``: ``h`` raised in place to a horizontal
    level ``water_fill * depth`` above the floor, kept 2 mm below the lowest point of the
    rim (so it never spills); returns the water mask (float64, 1 = water) or None."""
    water = None
    for hole in holes:
        if hole.water_fill <= 0:
            continue
        rows, cols = _grid_window(hole, x0, y0, spacing, h.shape)
        xx, yy = _grid_coords(x0, y0, spacing, rows, cols)
        rho = _normalised_radius(hole, xx, yy)
        sub, sub_base = h[rows, cols], base[rows, cols]
        floor = float(sub.min())
        rim = sub_base[(rho > 0.97) & (rho < 1.03)]
        level = floor + hole.water_fill * hole.depth
        if rim.size:
            level = min(level, float(rim.min()) - 2e-3)
        wet = (rho < 1.0) & (sub < level)
        sub[wet] = level
        if water is None:
            water = np.zeros(h.shape)
        water[rows, cols] = np.maximum(water[rows, cols], wet)
    return water
