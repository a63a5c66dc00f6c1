"""The ray tracer (Numba): sphere tracing of the height field, cast shadows, mip-mapped
albedo over the ray footprint, supersampled pixels; the lighting variants and the
exposure (lens blur, sensor noise, quantisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit, prange

from .rig import StereoRig


_SURFACE_TOL_M = 1e-6  # sphere tracing stops this close above the surface
_OCCLUSION_TOL_M = 5e-4  # a right-camera hit this much before the point = occluded
_MAX_TRACE_STEPS = 400


# Optical point spread (Gaussian sigma) of both cameras.  0.7 px is typical of real
# lenses and keeps bilinear interpolation of the images within ~2 grey levels on the
# contrasty asphalt (0.5 px: ~3).
_LENS_BLUR_SIGMA_PX = 0.7


@njit(cache=True, inline="always")
def _bilinear(grid, fx, fy):
    ny, nx = grid.shape
    fx = min(max(fx, 0.0), nx - 1.0)
    fy = min(max(fy, 0.0), ny - 1.0)
    ix = min(int(fx), nx - 2)
    iy = min(int(fy), ny - 2)
    ax = fx - ix
    ay = fy - iy
    top = grid[iy, ix] * (1.0 - ax) + grid[iy, ix + 1] * ax
    bottom = grid[iy + 1, ix] * (1.0 - ax) + grid[iy + 1, ix + 1] * ax
    return top * (1.0 - ay) + bottom * ay


@njit(cache=True, inline="always")
def _lipschitz_at(lip, tile, fx, fy):
    ty = min(max(int(fy / tile), 0), lip.shape[0] - 1)
    tx = min(max(int(fx / tile), 0), lip.shape[1] - 1)
    return lip[ty, tx]


@njit(cache=True)
def _trace(ox, oy, oz, dx, dy, dz, hmap, lip, tile, x0, y0, s, h_top):
    """First hit of the ray o + t d (dz < 0) with the height field, by sphere tracing.

    The step g / (|dz| + L |d_xy|), with g the height above the surface and L the local
    slope bound, can never pass through the surface, so the first hit is found even
    behind pothole rims.  Steps are capped to one tile so the tile's bound stays valid.
    Returns t (inf when the ray does not go down).
    """
    if dz >= 0.0:
        return np.inf
    horiz = math.sqrt(dx * dx + dy * dy)
    cap = tile * s / horiz if horiz > 0.0 else np.inf
    t = max((h_top - oz) / dz, 0.0)
    for _ in range(_MAX_TRACE_STEPS):
        x = ox + t * dx
        y = oy + t * dy
        fx = (x - x0) / s
        fy = (y - y0) / s
        g = oz + t * dz - _bilinear(hmap, fx, fy)
        if g < _SURFACE_TOL_M:
            break
        step = g / (-dz + _lipschitz_at(lip, tile, fx, fy) * horiz)
        t += min(step, cap)
    return t


@njit(cache=True)
def _in_shadow(px, py, pz, lx, ly, lz, hmap, lip, tile, x0, y0, s, h_top):
    """True when the surface blocks the (unit) light direction l from point p."""
    horiz = math.sqrt(lx * lx + ly * ly)
    cap = tile * s / horiz if horiz > 0.0 else 1.0
    t = 2e-3  # start clear of the facet the point lies on
    for _ in range(_MAX_TRACE_STEPS):
        z = pz + t * lz
        if z > h_top:
            return False
        fx = (px + t * lx - x0) / s
        fy = (py + t * ly - y0) / s
        g = z - _bilinear(hmap, fx, fy)
        if g < 0.0:
            return True
        rate = _lipschitz_at(lip, tile, fx, fy) * horiz - lz
        step = cap if rate <= 1e-9 else min(max(g / rate, 5e-4), cap)
        t += step
    return False


@njit(cache=True, inline="always")
def _mip_level(flat, offsets, shapes, scales, level, fx0, fy0):
    ny = shapes[level, 0]
    nx = shapes[level, 1]
    fx = (fx0 + 0.5) * scales[level, 1] - 0.5
    fy = (fy0 + 0.5) * scales[level, 0] - 0.5
    fx = min(max(fx, 0.0), nx - 1.0)
    fy = min(max(fy, 0.0), ny - 1.0)
    ix = min(int(fx), nx - 2)
    iy = min(int(fy), ny - 2)
    ax = fx - ix
    ay = fy - iy
    base = offsets[level] + iy * nx + ix
    top = flat[base] * (1.0 - ax) + flat[base + 1] * ax
    bottom = flat[base + nx] * (1.0 - ax) + flat[base + nx + 1] * ax
    return top * (1.0 - ay) + bottom * ay


@njit(cache=True, inline="always")
def _albedo(flat, offsets, shapes, scales, fx0, fy0, lod):
    """Trilinear mip-map lookup at level-0 texel coordinates and level of detail."""
    last = offsets.shape[0] - 1
    lod = min(max(lod, 0.0), float(last))
    lo = int(lod)
    frac = lod - lo
    a = _mip_level(flat, offsets, shapes, scales, lo, fx0, fy0)
    if frac <= 0.0 or lo >= last:
        return a
    b = _mip_level(flat, offsets, shapes, scales, lo + 1, fx0, fy0)
    return a * (1.0 - frac) + b * frac


@njit(cache=True, parallel=True)
def _render_view(
    centre, rot, f, cx, cy, width, height, ss,
    hmap, grad_x, grad_y, wet, lip, tile, x0, y0, s, h_top,
    mip_flat, mip_offsets, mip_shapes, mip_scales, texel, tex_x0, tex_y0,
    light, shade, shadows,
):
    """Radiance image (float64 (H, W)) of one camera: ss x ss rays per pixel, averaged.

    shade = [ambient, diffuse, ks_dry, ks_wet, shininess_dry, shininess_wet,
             wet_darkening]; wet is a wetness grid on the height grid (or 1x1 zeros).
    """
    out = np.zeros((height, width))
    cz = centre[2]
    use_wet = wet.shape[0] > 1
    for v in prange(height):
        for u in range(width):
            acc = 0.0
            for k in range(ss * ss):
                su = u + ((k % ss) + 0.5) / ss - 0.5
                sv = v + ((k // ss) + 0.5) / ss - 0.5
                xc = (su - cx) / f
                yc = (sv - cy) / f
                dx = rot[0, 0] * xc + rot[1, 0] * yc + rot[2, 0]
                dy = rot[0, 1] * xc + rot[1, 1] * yc + rot[2, 1]
                dz = rot[0, 2] * xc + rot[1, 2] * yc + rot[2, 2]
                t = _trace(centre[0], centre[1], cz, dx, dy, dz, hmap, lip, tile, x0, y0, s, h_top)
                if not np.isfinite(t):
                    continue
                px = centre[0] + t * dx
                py = centre[1] + t * dy
                pz = cz + t * dz
                fx = (px - x0) / s
                fy = (py - y0) / s
                hx = _bilinear(grad_x, fx, fy)
                hy = _bilinear(grad_y, fx, fy)
                norm = math.sqrt(hx * hx + hy * hy + 1.0)
                nx_, ny_, nz_ = -hx / norm, -hy / norm, 1.0 / norm
                # Pixel footprint on the road: area = Z^3 / (f^2 * camera height above
                # the point) for unit-depth rays; split among the ss x ss rays.
                area = t * t * t / (f * f * max(cz - pz, 1e-3))
                lod = math.log2(max(math.sqrt(area) / ss / texel, 1e-6))
                albedo = _albedo(mip_flat, mip_offsets, mip_shapes, mip_scales,
                                 (px - tex_x0) / texel, (py - tex_y0) / texel, lod)
                wetness = _bilinear(wet, fx, fy) if use_wet else 0.0
                albedo *= 1.0 - shade[6] * wetness
                ndotl = nx_ * light[0] + ny_ * light[1] + nz_ * light[2]
                lit = 0.0
                if ndotl > 0.0:
                    lit = 1.0
                    if shadows and _in_shadow(px, py, pz, light[0], light[1], light[2],
                                              hmap, lip, tile, x0, y0, s, h_top):
                        lit = 0.0
                radiance = albedo * (shade[0] + shade[1] * max(ndotl, 0.0) * lit)
                ks = shade[2] + (shade[3] - shade[2]) * wetness
                if ks > 0.0 and lit > 0.0:
                    # Blinn-Phong highlight: depends on the direction to this camera.
                    vx, vy, vz = centre[0] - px, centre[1] - py, cz - pz
                    vn = math.sqrt(vx * vx + vy * vy + vz * vz)
                    hxv, hyv, hzv = vx / vn + light[0], vy / vn + light[1], vz / vn + light[2]
                    hn = math.sqrt(hxv * hxv + hyv * hyv + hzv * hzv)
                    ndoth = max((nx_ * hxv + ny_ * hyv + nz_ * hzv) / hn, 0.0)
                    shininess = shade[4] + (shade[5] - shade[4]) * wetness
                    radiance += ks * ndoth ** shininess
                acc += radiance
            out[v, u] = acc / (ss * ss)
    return out


@njit(cache=True, parallel=True)
def _centre_hits(centre, rot, f, cx, cy, width, height, hmap, lip, tile, x0, y0, s, h_top):
    """World point (float64 (H, W, 3), nan where none) hit by each pixel's centre ray."""
    out = np.full((height, width, 3), np.nan)
    for v in prange(height):
        for u in range(width):
            xc = (u - cx) / f
            yc = (v - cy) / f
            dx = rot[0, 0] * xc + rot[1, 0] * yc + rot[2, 0]
            dy = rot[0, 1] * xc + rot[1, 1] * yc + rot[2, 1]
            dz = rot[0, 2] * xc + rot[1, 2] * yc + rot[2, 2]
            t = _trace(centre[0], centre[1], centre[2], dx, dy, dz, hmap, lip, tile, x0, y0, s, h_top)
            if np.isfinite(t):
                out[v, u, 0] = centre[0] + t * dx
                out[v, u, 1] = centre[1] + t * dy
                out[v, u, 2] = centre[2] + t * dz
    return out


@njit(cache=True, parallel=True)
def visible_from(centre, points, hmap, lip, tile, x0, y0, s, h_top, tol):
    """True where the ray from ``centre`` to each point first meets the surface there."""
    height, width = points.shape[0], points.shape[1]
    out = np.zeros((height, width), dtype=np.bool_)
    for v in prange(height):
        for u in range(width):
            dx = points[v, u, 0] - centre[0]
            dy = points[v, u, 1] - centre[1]
            dz = points[v, u, 2] - centre[2]
            if not np.isfinite(dx):
                continue
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            t = _trace(centre[0], centre[1], centre[2], dx, dy, dz, hmap, lip, tile, x0, y0, s, h_top)
            out[v, u] = t >= 1.0 - tol / length
    return out


@dataclass(frozen=True)
class _Lighting:
    light: np.ndarray  # unit vector towards the light, world
    shade: np.ndarray  # ambient, diffuse, ks_dry, ks_wet, shininess_dry, shininess_wet, wet_darkening
    shadows: bool
    mean_electrons: float  # exposure: mean signal of the left image, electrons
    read_noise_e: float
    mean_dn: float  # mean grey level the exposure aims at
    vignetting: float  # relative fall-off at the image corners


def _direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])


def _sample_lighting(rng, variant: str, rig: StereoRig) -> _Lighting:
    if variant == "sun":
        return _Lighting(_direction(rng.uniform(35, 65), rng.uniform(0, 360)),
                         np.array([0.3, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0]), True,
                         mean_electrons=15000.0, read_noise_e=6.0, mean_dn=rng.uniform(105, 130), vignetting=0.0)
    if variant == "dusk":
        return _Lighting(_direction(rng.uniform(15, 35), rng.uniform(0, 360)),
                         np.array([0.6, 0.5, 0.0, 0.0, 1.0, 1.0, 0.0]), False,
                         mean_electrons=rng.uniform(40.0, 90.0), read_noise_e=3.0, mean_dn=rng.uniform(45, 65),
                         vignetting=0.25)
    # Wet: the sun ahead of the camera near the mirror direction of the view, so the
    # highlights land in the image.
    elevation = float(np.clip(rig.pitch_deg + rng.uniform(-12, 8), 20, 75))
    return _Lighting(_direction(elevation, rng.uniform(-15, 15)),
                     np.array([0.3, 0.8, 0.01, rng.uniform(0.3, 0.7), 8.0, rng.uniform(100, 400),
                               rng.uniform(0.3, 0.5)]),
                     True, mean_electrons=8000.0, read_noise_e=6.0, mean_dn=rng.uniform(80, 100), vignetting=0.05)


def _expose(radiance: np.ndarray, scale: float, lighting: _Lighting, rng, noise: bool, rig: StereoRig) -> np.ndarray:
    """Camera: lens blur, vignetting, shot + read noise, gain and 8-bit quantisation."""
    image = cv2.GaussianBlur(radiance, (0, 0), _LENS_BLUR_SIGMA_PX, borderType=cv2.BORDER_REFLECT)
    if lighting.vignetting > 0:
        vv, uu = np.mgrid[0:rig.height, 0:rig.width]
        r2 = ((uu - rig.cx) ** 2 + (vv - rig.cy) ** 2) / (rig.cx ** 2 + rig.cy ** 2)
        image = image * (1.0 - lighting.vignetting * r2)
    electrons = image * scale
    if noise:
        electrons = electrons + rng.standard_normal(electrons.shape) * np.sqrt(np.maximum(electrons, 0.0))
        electrons = electrons + rng.standard_normal(electrons.shape) * lighting.read_noise_e
    gain = lighting.mean_dn / lighting.mean_electrons
    return np.clip(np.rint(electrons * gain), 0, 255).astype(np.uint8)
