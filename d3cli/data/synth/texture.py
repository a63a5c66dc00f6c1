"""The road's albedo map (asphalt stones in binder; cement noise, sand, pores and
cracks), its mip map, and the wet patches of the ``wet`` variant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from .terrain import _HeightField, _fractal_noise, _pothole_map


@dataclass(frozen=True)
class _MipMap:
    """A texture pyramid packed into one array so numba kernels can take it."""

    flat: np.ndarray  # float32 (n,)
    offsets: np.ndarray  # int64 (levels,)
    shapes: np.ndarray  # int64 (levels, 2): (ny, nx)
    scales: np.ndarray  # float64 (levels, 2): level texels per level-0 texel (y, x)
    texel: float  # level-0 texel size, metres
    x0: float
    y0: float


@njit(cache=True)
def _splat_stones(tex, cx, cy, radius, aspect, angle, grey, wobble):
    """Paint irregular elliptical stones (texel units) into ``tex`` in order.

    wobble (n, 4): amplitudes and phases of the 2nd and 3rd radial harmonics.  Each
    stone is a little brighter on one side and darker at its rim (rounded relief baked
    into the albedo); edges are anti-aliased over one texel.
    """
    ny, nx = tex.shape
    for k in range(cx.shape[0]):
        r = radius[k]
        reach = r * 1.35 + 1.0
        ca, sa = math.cos(angle[k]), math.sin(angle[k])
        a2, p2, a3, p3 = wobble[k, 0], wobble[k, 1], wobble[k, 2], wobble[k, 3]
        c2, s2, c3, s3 = math.cos(p2), math.sin(p2), math.cos(p3), math.sin(p3)
        for iy in range(max(int(cy[k] - reach), 0), min(int(cy[k] + reach) + 2, ny)):
            for ix in range(max(int(cx[k] - reach), 0), min(int(cx[k] + reach) + 2, nx)):
                ddx = ix - cx[k]
                ddy = iy - cy[k]
                xr = ddx * ca + ddy * sa
                yr = (-ddx * sa + ddy * ca) / aspect[k]
                rho2 = xr * xr + yr * yr
                rho = math.sqrt(rho2)
                if rho > 0.0:
                    # cos(n theta + p) from polynomials of (xr, yr): no trig per texel.
                    cos2 = (xr * xr - yr * yr) / rho2
                    sin2 = 2.0 * xr * yr / rho2
                    cos3 = (xr * xr * xr - 3.0 * xr * yr * yr) / (rho2 * rho)
                    sin3 = (3.0 * xr * xr * yr - yr * yr * yr) / (rho2 * rho)
                    edge = r * (1.0 + a2 * (cos2 * c2 - sin2 * s2) + a3 * (cos3 * c3 - sin3 * s3))
                else:
                    edge = r
                cover = min(max(edge + 0.5 - rho, 0.0), 1.0)
                if cover <= 0.0:
                    continue
                q = min(rho / max(edge, 1e-6), 1.0)
                value = grey[k] * (1.0 - 0.35 * q * q) * (1.0 + 0.12 * (xr - yr) / (r + 1.0))
                tex[iy, ix] = tex[iy, ix] * (1.0 - cover) + value * cover


def _texture_shape(bounds, texel):
    x_min, x_max, y_min, y_max = bounds
    return int(math.ceil((y_max - y_min) / texel)) + 2, int(math.ceil((x_max - x_min) / texel)) + 2


def _stones(rng, tex: np.ndarray, texel: float, *, coverage: float, r_min_m: float, r_max_m: float,
            grey_mean: float, grey_spread: float) -> None:
    """Scatter stones with log-uniform radii in [r_min, r_max] metres over ``tex``.

    Stones smaller than ~0.7 texel cannot be drawn; their share of the surface is
    blended into the background tone instead (the texture's own prefilter).
    """
    r_lo = max(r_min_m, 0.7 * texel)
    if r_lo >= r_max_m:
        tex[:] = tex * (1.0 - coverage) + grey_mean * coverage
        return
    log_span = math.log(r_max_m / r_min_m)
    drawable = math.log(r_max_m / r_lo) / log_span  # share of stones (by log size) drawn
    mean_r2 = (r_max_m ** 2 - r_lo ** 2) / (2.0 * math.log(r_max_m / r_lo))
    area = tex.size * texel * texel
    count = int(coverage * drawable * area / (math.pi * mean_r2 * 0.8))
    if drawable < 1.0:
        hidden = coverage * (1.0 - drawable) * 0.5  # small stones cover little area
        tex[:] = tex * (1.0 - hidden) + grey_mean * hidden
    ny, nx = tex.shape
    radius = np.exp(rng.uniform(math.log(r_lo), math.log(r_max_m), count)) / texel
    order = np.argsort(-radius)  # large stones first, small ones fill the gaps on top
    _splat_stones(
        tex,
        rng.uniform(0, nx, count),
        rng.uniform(0, ny, count),
        radius[order],
        rng.uniform(0.6, 1.0, count),
        rng.uniform(0, math.pi, count),
        np.clip(rng.normal(grey_mean, grey_spread, count), 0.03, 0.95),
        np.column_stack([rng.uniform(0, 0.15, count), rng.uniform(0, 2 * math.pi, count),
                         rng.uniform(0, 0.1, count), rng.uniform(0, 2 * math.pi, count)]),
    )


def _cracks(rng, tex: np.ndarray, texel: float, count: int) -> None:
    """Dark jagged cracks 1-3 mm wide, drawn anti-aliased into ``tex``.

    Each crack is a random walk of 5 mm steps around a slowly drifting main direction,
    with an occasional short branch.
    """
    ny, nx = tex.shape
    mask = np.zeros(tex.shape, np.uint8)
    shift = 4  # cv2 sub-texel precision: coordinates in 1/16 texel
    step = 5e-3 / texel
    walks = [(rng.uniform(0.1, 0.9) * nx, rng.uniform(0.1, 0.9) * ny, rng.uniform(0, 2 * math.pi),
              rng.uniform(0.3, 1.5), rng.uniform(1e-3, 3e-3)) for _ in range(count)]
    while walks:
        x, y, course, length_m, width_m = walks.pop()
        points = [(x, y)]
        for _ in range(int(length_m / 5e-3)):
            course += rng.normal(0.0, 0.05)
            heading = course + rng.normal(0.0, 0.6)
            x += math.cos(heading) * step
            y += math.sin(heading) * step
            points.append((x, y))
            if width_m > 1.2e-3 and rng.uniform() < 0.01:
                walks.append((x, y, course + rng.choice([-1.0, 1.0]) * rng.uniform(0.4, 1.2),
                              rng.uniform(0.05, 0.3), 0.6 * width_m))
        width_tex = max(1, int(round(width_m / texel)))
        polyline = (np.array(points) * (1 << shift)).astype(np.int32)
        cv2.polylines(mask, [polyline], False, 255, width_tex, cv2.LINE_AA, shift)
    tex *= 1.0 - 0.75 * (mask.astype(np.float32) / 255.0)


def _build_albedo(rng, material: str, bounds, texel: float, holes, light_pool) -> np.ndarray:
    """Albedo map, float32 (ny, nx), over ``bounds`` at ``texel`` metres per texel."""
    shape = _texture_shape(bounds, texel)
    if material == "asphalt":
        binder = rng.uniform(0.06, 0.11)
        tex = (binder * (1.0 + 0.25 * _fractal_noise(rng, shape, texel, (0.004, 0.002)))).astype(np.float32)
        _stones(rng, tex, texel, coverage=rng.uniform(0.55, 0.75), r_min_m=1e-3, r_max_m=rng.uniform(6e-3, 10e-3),
                grey_mean=rng.uniform(0.22, 0.4), grey_spread=0.08)
        stains = (0.4, 0.15, 0.06)
    else:
        base = rng.uniform(0.42, 0.58)
        fine = _fractal_noise(rng, shape, texel, (0.008, 0.003, 0.0015), exponent=0.3)
        # Broom finish: striations across the road, long in x and short in y.
        lattice = (max(2, int(shape[0] * texel / 0.003)), max(2, int(shape[1] * texel / 0.06)))
        broom = cv2.resize(rng.standard_normal(lattice), (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
        tex = (base * (1.0 + 0.07 * fine + 0.04 * broom)).astype(np.float32)
        _stones(rng, tex, texel, coverage=0.15, r_min_m=3e-4, r_max_m=1.5e-3, grey_mean=base * 1.1, grey_spread=0.08)
        _stones(rng, tex, texel, coverage=0.03, r_min_m=3e-4, r_max_m=1.2e-3, grey_mean=0.15, grey_spread=0.03)
        _cracks(rng, tex, texel, int(rng.integers(1, 5)))
        stains = (0.5, 0.2, 0.08)
    tex *= (1.0 + 0.12 * _fractal_noise(rng, shape, texel, stains)).astype(np.float32)
    x_min, _, y_min, _ = bounds
    if holes:
        # Exposed, broken base course inside potholes: darker, blotchier.
        weight = _pothole_map(holes, x_min, y_min, texel, shape)
        rough = _fractal_noise(rng, shape, texel, (0.03, 0.012))
        tex *= (1.0 - weight * (0.25 + 0.12 * rough)).astype(np.float32)
    if light_pool is not None:
        # A street lamp's pool of light is view-independent diffuse lighting, so it can
        # be folded into the albedo.
        px, py, sigma = light_pool
        xs = x_min + texel * np.arange(shape[1])
        ys = y_min + texel * np.arange(shape[0])
        pool = np.exp(-0.5 * ((xs[None, :] - px) ** 2 + (ys[:, None] - py) ** 2) / sigma ** 2)
        tex *= (0.35 + 0.65 * pool).astype(np.float32)
    return np.clip(tex, 0.01, 1.0)


def _build_mipmap(tex: np.ndarray, texel: float, x0: float, y0: float) -> _MipMap:
    levels = [tex.astype(np.float32)]
    while min(levels[-1].shape) >= 16 and len(levels) < 12:
        ny, nx = levels[-1].shape
        levels.append(cv2.resize(levels[-1], ((nx + 1) // 2, (ny + 1) // 2), interpolation=cv2.INTER_AREA))
    shapes = np.array([lvl.shape for lvl in levels], np.int64)
    offsets = np.concatenate([[0], np.cumsum(shapes[:, 0] * shapes[:, 1])[:-1]]).astype(np.int64)
    scales = shapes / shapes[0].astype(np.float64)
    flat = np.concatenate([lvl.ravel() for lvl in levels])
    return _MipMap(flat, offsets, shapes, scales, texel, x0, y0)


def _build_wetness(rng, field_: _HeightField) -> np.ndarray:
    """Wetness in [0, 1] on the height grid: puddle-like patches plus pothole floors."""
    noise = _fractal_noise(rng, field_.h.shape, field_.spacing, (0.8, 0.4, 0.15))
    threshold = rng.uniform(-0.3, 0.5)
    patches = np.clip((noise - threshold) / 0.4, 0.0, 1.0)
    patches = patches * patches * (3.0 - 2.0 * patches)  # smoothstep edges
    return np.maximum(patches, field_.pothole_weight).astype(np.float64)
