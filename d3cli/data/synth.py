"""Synthetic road stereo pairs with exact ground truth.

A road surface ``z = h(x, y)`` (world metres: x across the road, y along it, z up) is
built from smooth multi-octave value noise (millimetre undulations, a small cross
slope and grade), 0-3 smooth-walled elliptical potholes and an optional bump.  Its
albedo is a procedural texture map over the road plane (asphalt: stones of several
sizes in a dark binder; cement: fine noise, sand, pores and cracks) at about one texel
per pixel of the nearest image row (1-1.5 mm at 1280x720), so both views sample the
very same surface.

Each view of a rectified stereo rig is rendered by ray casting the height field
(sphere tracing with per-tile Lipschitz bounds, converged to 1 micrometre), with 2x2
rays per pixel and a mip-mapped texture filtered to the ray footprint.  The left-view
ground truth comes from the centre ray of each pixel: its hit point is projected into
the right camera and ``d = u_left - u_right``.  The non-occlusion mask re-casts the ray
from the right camera to that point.

Three illumination variants reproduce the conditions of UDTIRI-Stereo (paper, section
"Datasets"): ``sun`` (hard directional light with cast shadows, low noise), ``dusk``
(dim, high gain, strong shot and read noise) and ``wet`` (darker wet patches with
view-dependent specular highlights, so left and right differ as on real wet roads).

Public API: :func:`render_pair`, :func:`generate_dataset`, :func:`self_test`.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numba import njit, prange

from ..errors import InputError, OutputError, where_what_fix

log = logging.getLogger(__name__)

VARIANTS = ("sun", "dusk", "wet")
MATERIALS = ("asphalt", "cement")

# Camera rays must meet the road at least this steeply, so every pixel sees road
# (no horizon) and the texture map stays a bounded patch.
_MIN_DEPRESSION_DEG = 12.0
_SURFACE_TOL_M = 1e-6  # sphere tracing stops this close above the surface
_OCCLUSION_TOL_M = 5e-4  # a right-camera hit this much before the point = occluded
_MAX_TRACE_STEPS = 400
# Optical point spread (Gaussian sigma) of both cameras.  0.7 px is typical of real
# lenses and keeps bilinear interpolation of the images within ~2 grey levels on the
# contrasty asphalt (0.5 px: ~3).
_LENS_BLUR_SIGMA_PX = 0.7


# --------------------------------------------------------------------------- data


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo rig looking down at the road.

    Attributes
    ----------
    f : float
        Focal length in pixels (both cameras).
    baseline : float
        Distance between the camera centres in metres, along the camera x axis.
    cx, cy : float
        Principal point in pixels (the image centre, ``(W - 1) / 2``, ``(H - 1) / 2``).
    width, height : int
        Image size in pixels.
    height_m : float
        Height of the rig's mid-point above the mean road level (z = 0), metres.
    pitch_deg : float
        Downward tilt of the optical axes from the horizontal, degrees.
    roll_deg : float
        Roll angle theta in degrees, signed so that a planar road has the disparity
        ``d(u, v) = a0 + a1 (v cos(theta) - u sin(theta))`` (DESIGN.md section 1, PT).
    """

    f: float
    baseline: float
    cx: float
    cy: float
    width: int
    height: int
    height_m: float
    pitch_deg: float
    roll_deg: float

    def rotation(self) -> np.ndarray:
        """World-to-camera rotation, float64 (3, 3); rows are the camera x (right),
        y (down) and z (optical axis) directions in world coordinates."""
        pitch = math.radians(self.pitch_deg)
        # The camera rotates by -theta about its optical axis for the PT roll theta.
        roll = -math.radians(self.roll_deg)
        sp, cp = math.sin(pitch), math.cos(pitch)
        x0 = np.array([1.0, 0.0, 0.0])
        y0 = np.array([0.0, -sp, -cp])
        z0 = np.array([0.0, cp, -sp])
        cr, sr = math.cos(roll), math.sin(roll)
        return np.stack([cr * x0 + sr * y0, -sr * x0 + cr * y0, z0])

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        """Left and right camera centres in world metres, float64 (3,) each."""
        axis_x = self.rotation()[0]
        mid = np.array([0.0, 0.0, self.height_m])
        return mid - 0.5 * self.baseline * axis_x, mid + 0.5 * self.baseline * axis_x

    def ray_directions(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """World directions (not normalised; unit camera depth) of pixels (u, v).

        Returns float64 (..., 3): a point at depth Z along the ray is ``C + Z * dir``.
        """
        cam = np.stack([(u - self.cx) / self.f, (v - self.cy) / self.f, np.ones_like(u, dtype=float)], -1)
        return cam @ self.rotation()

    def calib(self) -> dict:
        """Calibration as a plain dict (the keys of ``calib.txt``)."""
        return {
            "f": self.f,
            "baseline": self.baseline,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
            "height_m": self.height_m,
            "pitch_deg": self.pitch_deg,
            "roll_deg": self.roll_deg,
            "doffs": 0.0,
        }


@dataclass(frozen=True)
class Pothole:
    """A smooth-walled, slightly irregular elliptical depression (world metres)."""

    x: float
    y: float
    semi_a: float  # semi-axis along the rotated x direction, metres
    semi_b: float
    angle: float  # radians
    depth: float  # metres, positive
    flat_fraction: float  # share of the normalised radius with a flat bottom
    wobble: tuple[float, float, float, float]  # 2nd/3rd harmonic amplitude and phase


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


@dataclass
class SynthPair:
    """One rendered stereo pair with exact ground truth.

    Attributes
    ----------
    left, right : ndarray, uint8, (H, W)
        Grey images of the left and right camera.
    disparity : ndarray, float32, (H, W)
        Left-view disparity in pixels, ``u_left - u_right`` of the surface point seen
        by each left pixel's centre ray; ``inf`` where invalid (no road hit).
    nocc : ndarray, bool, (H, W)
        True where that point is visible in the right view (inside the image and not
        occluded).
    calib : dict
        ``f``, ``baseline``, ``cx``, ``cy``, ``width``, ``height``, ``height_m``,
        ``pitch_deg``, ``roll_deg``, ``doffs`` and ``ndisp`` (= ceil(max gt) + 8).
    info : dict
        How the pair was made: seed, variant, material, potholes (world and left-image
        positions, depths), bump, lighting.
    pothole_ids : ndarray, uint8, (H, W) or None
        Defect id (1..N, the order of ``defects_gt``) of the surface point each left
        pixel sees where a pothole lowers the road by more than 1 mm, else 0; nested
        potholes carry their group's id (:func:`pothole_groups`).
    defects_gt : list of dict
        Per pothole: ``id``, ``depth_mm`` (below the surrounding surface), ``area_m2``
        (horizontal area deeper than 10 mm), ``volume_l`` (fill volume up to the
        surrounding surface), ``visible_px`` (pixels of the id mask), ``u``, ``v``, and
        ``members`` (ids of the nested potholes it stands for, itself included) or
        ``part_of`` (the id of the deeper pothole it is part of; no pixels, area 0).
    """

    left: np.ndarray
    right: np.ndarray
    disparity: np.ndarray
    nocc: np.ndarray
    calib: dict
    info: dict = field(default_factory=dict)
    pothole_ids: np.ndarray | None = None
    defects_gt: list = field(default_factory=list)


# ------------------------------------------------------------- numba kernels


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
def _visible_from(centre, points, hmap, lip, tile, x0, y0, s, h_top, tol):
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


# ------------------------------------------------------------- scene building


def _sample_rig(rng: np.random.Generator, width: int, height: int) -> StereoRig:
    """Random rig: height 1-1.5 m, pitch 40-70 deg, roll +-3 deg, baseline 0.1-0.26 m.

    The focal length makes the image centre row span 1.6-2.6 m of road; the baseline
    then puts the centre disparity at 6.5-10 % of the width (83-128 px at 1280), which
    keeps a whole 1280x720 pair within about 50-190 px.
    """
    height_m = rng.uniform(1.0, 1.5)
    pitch = rng.uniform(40.0, 70.0)
    roll = rng.uniform(-3.0, 3.0)
    coverage_m = rng.uniform(1.6, 2.6)
    centre_disp_share = rng.uniform(0.065, 0.10)
    depth_centre = height_m / math.sin(math.radians(pitch))
    f = width * depth_centre / coverage_m
    baseline = centre_disp_share * coverage_m  # d_centre = f b / Z = W b / coverage
    rig = StereoRig(f, baseline, (width - 1) / 2.0, (height - 1) / 2.0, width, height, height_m, pitch, roll)
    # Narrow the view until every corner ray meets the road steeply enough.
    while _min_depression_deg(rig) < _MIN_DEPRESSION_DEG:
        rig = StereoRig(rig.f * 1.1, rig.baseline, rig.cx, rig.cy, width, height, height_m, pitch, roll)
    return rig


def _texel_size(rig: StereoRig) -> float:
    """Texture resolution, metres: about one texel per pixel at the nearest (bottom)
    image row, where the pixel footprint is smallest; never below 0.7 mm."""
    steepest = min(89.0, rig.pitch_deg + math.degrees(math.atan(rig.cy / rig.f)))
    near_depth = rig.height_m / math.sin(math.radians(steepest))
    return float(np.clip(near_depth / rig.f, 7e-4, 2e-2))


def _border_pixels(rig: StereoRig, per_edge: int = 33) -> tuple[np.ndarray, np.ndarray]:
    us = np.linspace(-0.5, rig.width - 0.5, per_edge)
    vs = np.linspace(-0.5, rig.height - 0.5, per_edge)
    u = np.concatenate([us, us, np.full_like(vs, -0.5), np.full_like(vs, rig.width - 0.5)])
    v = np.concatenate([np.full_like(us, -0.5), np.full_like(us, rig.height - 0.5), vs, vs])
    return u, v


def _min_depression_deg(rig: StereoRig) -> float:
    dirs = rig.ray_directions(*_border_pixels(rig))
    sines = -dirs[:, 2] / np.linalg.norm(dirs, axis=1)
    return math.degrees(math.asin(min(1.0, float(sines.min()))))


def _road_bounds(rig: StereoRig, z_low: float, z_high: float, margin: float) -> tuple[float, float, float, float]:
    """Bounding box (x_min, x_max, y_min, y_max) of what both cameras can see of a
    surface lying between z_low and z_high, plus a margin (metres)."""
    u, v = _border_pixels(rig)
    dirs = rig.ray_directions(u, v)
    xs, ys = [], []
    for centre in rig.centres():
        for z in (z_low, z_high):
            t = (z - centre[2]) / dirs[:, 2]
            xs.append(centre[0] + t * dirs[:, 0])
            ys.append(centre[1] + t * dirs[:, 1])
    xs, ys = np.concatenate(xs), np.concatenate(ys)
    return xs.min() - margin, xs.max() + margin, ys.min() - margin, ys.max() + margin


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


def _sample_potholes(rng, rig: StereoRig, count: int) -> list[Pothole]:
    """Potholes centred on road points seen near the middle of the left image."""
    holes = []
    for _ in range(count):
        x, y = _sample_road_point(rng, rig)
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
        holes.append(Pothole(x, y, semi_a, semi_b, rng.uniform(0, math.pi), depth, flat_fraction, wobble))
    return holes


def _normalised_radius(hole: Pothole, xx, yy):
    """Radius of world points (xx, yy) in the hole's rotated, wobbled ellipse (1 = its rim);
    arrays or scalars."""
    dx, dy = xx - hole.x, yy - hole.y
    ca, sa = math.cos(hole.angle), math.sin(hole.angle)
    xr = (dx * ca + dy * sa) / hole.semi_a
    yr = (-dx * sa + dy * ca) / hole.semi_b
    theta = np.arctan2(yr, xr)
    a2, p2, a3, p3 = hole.wobble
    rim = 1.0 + a2 * np.cos(2 * theta + p2) + a3 * np.cos(3 * theta + p3)
    return np.hypot(xr, yr) / rim


def _pothole_weight(hole: Pothole, xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
    """Depth profile in [0, 1] (1 = floor) of one pothole at world points (xx, yy)."""
    rho = _normalised_radius(hole, xx, yy)
    wall = np.clip((rho - hole.flat_fraction) / (1.0 - hole.flat_fraction), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * wall))


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
        hole = max((h.depth for h in self.holes), default=0.0) + (_ROUGH_FLOOR_M * 5.0 if self.holes else 0.0)
        bump = self.bump[4] if self.bump is not None else 0.0
        return -(tilt + wave + hole) - 1e-3, tilt + wave + bump + 1e-3


_ROUGH_FLOOR_M = 2.5e-3  # relief of broken pothole floors (std of |noise| scale)


def _sample_road(rng, rig: StereoRig, potholes: int | None, flat: bool) -> _RoadShape:
    if flat:
        return _RoadShape(0.0, 0.0, 0.0, (), None, True)
    count = int(rng.integers(0, 4)) if potholes is None else int(potholes)
    holes = tuple(_sample_potholes(rng, rig, count))
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
        # Overlapping potholes merge into one (the deepest wins), they do not add up.
        sink = np.zeros(shape)
        for hole in road.holes:
            rows, cols = _grid_window(hole, x_min, y_min, spacing, shape)
            xx, yy = _grid_coords(x_min, y_min, spacing, rows, cols)
            np.maximum(sink[rows, cols], hole.depth * _pothole_weight(hole, xx, yy), out=sink[rows, cols])
        h -= sink
        if road.holes:
            # Broken, rough floors: a few millimetres of relief where the road is gone.
            relief = np.clip(np.abs(_fractal_noise(rng, shape, spacing, (0.06, 0.03, 0.015))), 0.0, 5.0)
            h -= _ROUGH_FLOOR_M * weight * relief
        if road.bump is not None:
            bx, by, sx, sy, height = road.bump
            h += height * np.exp(-0.5 * (((xs[None, :] - bx) / sx) ** 2 + ((ys[:, None] - by) / sy) ** 2))
    grad_y, grad_x = np.gradient(h, spacing)
    tile = 16
    return _HeightField(h, grad_x, grad_y, _lipschitz_tiles(h, spacing, tile), tile, x_min, y_min, spacing, weight)


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


# ---------------------------------------------------------------- lighting


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


# ---------------------------------------------------------------- rendering


def _check_choice(name: str, value: str, choices) -> None:
    if value not in choices:
        raise InputError(where_what_fix("synth", f"unknown {name} {value!r}", f"use one of {', '.join(choices)}"))


#: Image sides accepted by the generator: smaller cannot hold a road scene, larger would
#: need tens of GB while rendering (a 200000-pixel width used to end in a MemoryError).
MIN_SIDE, MAX_SIDE = 32, 8192
#: The file that marks a folder as one synthetic dataset (seed and size).
DATASET_FILE = "synth.json"


def _check_size(width: int, height: int) -> None:
    if width < MIN_SIDE or height < MIN_SIDE:
        raise InputError(where_what_fix("synth", f"image size {width}x{height} is too small",
                                        f"use a width and height of at least {MIN_SIDE} pixels"))
    if width > MAX_SIDE or height > MAX_SIDE:
        raise InputError(where_what_fix("synth", f"image size {width}x{height} is too large",
                                        f"use a width and height of at most {MAX_SIDE} pixels"))


def _claim_folder(out_dir: Path, identity: dict) -> None:
    """Refuse to mix two datasets in one folder; mark the folder as this dataset.

    A folder may be empty, or hold a dataset made with the same seed and size (a rerun,
    or more pairs of the same set: pairs are deterministic).  Anything else is refused,
    so that pairs of two seeds or sizes never end up side by side.
    """
    import json

    marker = out_dir / DATASET_FILE
    entries = [p.name for p in out_dir.iterdir()] if out_dir.is_dir() else []
    if entries:
        try:
            stored = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            stored = None
        if stored != identity:
            made_by = (f"a synthetic set with seed {stored.get('seed')} and size {stored.get('width')}x"
                       f"{stored.get('height')}" if isinstance(stored, dict) else f"{len(entries)} other entries")
            raise OutputError(where_what_fix(
                str(out_dir), f"the folder is not empty (it holds {made_by})",
                "give an empty or new folder, or the same --seed/--width/--height as before"))
    _atomic_write(marker, lambda tmp: tmp.write_text(json.dumps(identity) + "\n", encoding="utf-8"))


def render_pair(
    *,
    seed: int,
    width: int = 1280,
    height: int = 720,
    variant: str = "sun",
    material: str = "asphalt",
    noise: bool = True,
    potholes: int | None = None,
    flat: bool = False,
    supersample: int = 2,
) -> SynthPair:
    """Render one synthetic road stereo pair with exact ground truth.

    Parameters
    ----------
    seed : int
        Seed of everything random (rig, road, texture, light, noise); equal seeds give
        bit-identical pairs.
    width, height : int
        Image size in pixels (at least 32).
    variant : {"sun", "dusk", "wet"}
        Illumination (see the module docstring).
    material : {"asphalt", "cement"}
        Road surface texture.
    noise : bool
        False leaves out sensor noise (images are still blurred and quantised).
    potholes : int or None
        Number of potholes; None draws 0-3.
    flat : bool
        True makes the road the exact plane z = 0 (no undulation, slope, potholes or
        bump), so the disparity is exactly ``a0 + a1 (v cos(theta) - u sin(theta))``.
    supersample : int
        Rays per pixel along each axis (antialiasing).

    Returns
    -------
    SynthPair
        Images uint8 (H, W), disparity float32 (H, W) (inf invalid), nocc bool (H, W),
        calib and info dicts.
    """
    _check_choice("variant", variant, VARIANTS)
    _check_choice("material", material, MATERIALS)
    _check_size(width, height)
    if int(supersample) < 1:
        raise InputError(where_what_fix("synth", f"supersample is {supersample}", "use 1 or more rays per axis"))
    rng = np.random.default_rng(seed)
    rig = _sample_rig(rng, width, height)
    road = _sample_road(rng, rig, potholes, flat)
    holes = road.holes

    texel = _texel_size(rig)
    spacing = float(np.clip(1.5 * texel, 2e-3, 2e-2))
    # The visible patch depends on the height range and the tilt part of the height
    # range on the patch: two rounds from a generous start settle it.
    z_low, z_high = -0.15, 0.1
    for _ in range(2):
        bounds = _road_bounds(rig, z_low, z_high, margin=0.05)
        z_low, z_high = road.height_range(bounds)
    bounds = _road_bounds(rig, z_low, z_high, margin=0.05)
    field_ = _build_height_field(rng, road, bounds, spacing)
    h_top = float(field_.h.max()) + 1e-3
    if field_.h.max() > z_high or field_.h.min() < z_low:
        raise RuntimeError("synthetic road height left the range its visible patch was computed for")

    lighting = _sample_lighting(rng, variant, rig)
    light_pool = None
    if variant == "dusk":
        light_pool = (*_sample_road_point(rng, rig), rng.uniform(1.0, 2.5))
    albedo = _build_albedo(rng, material, bounds, texel, holes, light_pool)
    mip = _build_mipmap(albedo, texel, bounds[0], bounds[2])
    del albedo
    wet = _build_wetness(rng, field_) if variant == "wet" else np.zeros((1, 1))

    rot = rig.rotation()
    left_c, right_c = rig.centres()
    hf = (field_.h, field_.grad_x, field_.grad_y, wet, field_.lipschitz, field_.tile,
          field_.x0, field_.y0, field_.spacing, h_top)
    radiance = [
        _render_view(c, rot, rig.f, rig.cx, rig.cy, width, height, int(supersample), *hf,
                     mip.flat, mip.offsets, mip.shapes, mip.scales, mip.texel, mip.x0, mip.y0,
                     lighting.light, lighting.shade, lighting.shadows)
        for c in (left_c, right_c)
    ]
    scale = lighting.mean_electrons / max(float(radiance[0].mean()), 1e-9)
    left_img, right_img = (_expose(r, scale, lighting, rng, noise, rig) for r in radiance)

    disparity, nocc, points = _ground_truth(rig, field_, h_top)
    pothole_ids, defects_gt = pothole_truth(holes, rig, points)
    finite = disparity[np.isfinite(disparity)]
    calib = rig.calib()
    calib["ndisp"] = int(math.ceil(float(finite.max()))) + 8 if finite.size else width // 4
    info = {
        "seed": int(seed),
        "variant": variant,
        "material": material,
        "noise": bool(noise),
        "flat": bool(flat),
        "potholes": [_describe_hole(hole, rig) for hole in holes],
        "bump": None if road.bump is None else {"x": road.bump[0], "y": road.bump[1], "height_m": road.bump[4]},
        "undulation_std_m": road.undulation_m,
        "cross_slope": road.cross_slope,
        "grade": road.grade,
        "light_elevation_deg": math.degrees(math.asin(float(lighting.light[2]))),
        "texel_m": texel,
        "grid_spacing_m": spacing,
    }
    return SynthPair(left_img, right_img, disparity, nocc, calib, info, pothole_ids, defects_gt)


def _describe_hole(hole: Pothole, rig: StereoRig) -> dict:
    left_c, _ = rig.centres()
    p = rig.rotation() @ (np.array([hole.x, hole.y, -hole.depth]) - left_c)
    return {
        "x": hole.x, "y": hole.y, "depth_m": hole.depth,
        "diameter_m": 2.0 * hole.semi_a,
        "semi_axes_m": [hole.semi_a, hole.semi_b], "angle_rad": hole.angle,
        "flat_fraction": hole.flat_fraction, "wobble": list(hole.wobble),
        "u": float(rig.f * p[0] / p[2] + rig.cx), "v": float(rig.f * p[1] / p[2] + rig.cy),
    }


_OPENING_M = 0.01  # a pothole's opening: where it lowers the road by more than 10 mm


def _opening_ratio(hole: Pothole, x: float, y: float) -> float:
    """Where world point (x, y) lies in ``hole``: its normalised radius over that of the
    hole's opening (< 1: inside the part deeper than 10 mm)."""
    rho = float(_normalised_radius(hole, x, y))
    w = _OPENING_M / hole.depth
    if w >= 1.0:
        return math.inf
    # Inverse of the raised-cosine wall of _pothole_weight at weight w.
    rho_open = hole.flat_fraction + (1.0 - hole.flat_fraction) * math.acos(2.0 * w - 1.0) / math.pi
    return rho / rho_open


def pothole_groups(holes) -> list[int]:
    """Which potholes form one defect: for each hole, the 0-based index of its group's
    deepest hole.

    Overlapping potholes of the generator merge into one surface (the deepest wins).  Two
    of them are *nested* when the centre (the floor) of one lies inside the other's
    opening (the part deeper than 10 mm, ``min_depth_mm`` of a pothole): a pit inside a
    shallower pothole's outline is a deeper spot of that pothole, and a shallow hole
    centred on a deeper one's wall is a shelf of it; an inspector reports one pothole,
    as deep as its deepest point, as large as the union.  Each hole joins the nearest
    (centre distance) deeper hole it is nested with; chains join (union-find).  Potholes
    that only touch or overlap rim to rim, each floor outside the other's opening, stay
    separate defects (a saddle or a terrace between two pits).

    Parameters
    ----------
    holes : sequence of Pothole

    Returns
    -------
    list of int
        ``len(holes)`` indices into ``holes``.
    """
    parent = list(range(len(holes)))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for k, hole in enumerate(holes):
        nested = [j for j, other in enumerate(holes)
                  if other.depth > hole.depth or (other.depth == hole.depth and j < k)
                  if _opening_ratio(hole, other.x, other.y) < 1.0 or _opening_ratio(other, hole.x, hole.y) < 1.0]
        if nested:
            j = min(nested, key=lambda j: math.hypot(holes[j].x - hole.x, holes[j].y - hole.y))
            rk, rj = root(k), root(j)
            if rk != rj:
                parent[rk] = rj
    deepest = {}
    for k in range(len(holes)):
        r = root(k)
        if r not in deepest or holes[k].depth > holes[deepest[r]].depth:
            deepest[r] = k
    return [deepest[root(k)] for k in range(len(holes))]


def pothole_truth(holes, rig: StereoRig, points: np.ndarray) -> tuple[np.ndarray, list]:
    """Pothole id mask (uint8 (H, W)) and the per-pothole ground truth of defects_gt.json.

    Nested potholes (:func:`pothole_groups`) are one defect: the entry of the group's
    deepest hole describes the whole group (its depth, the area and volume of the union)
    and its id marks the group's pixels; every other member's entry says ``part_of`` that
    id and has no pixels (``visible_px`` 0).  Depth is the nominal depth below the
    surrounding surface (the floor relief of a few mm is not counted); area and volume are
    integrated on a 2 mm world grid of the group's own depth profile (where separate
    defects overlap, the deeper one owns a point, as in the rendered surface).

    Parameters
    ----------
    holes : sequence of Pothole
    rig : StereoRig
    points : ndarray, float64, (H, W, 3)
        World point each left pixel sees (inf/nan where none).
    """
    h, w = points.shape[:2]
    groups = pothole_groups(holes)
    members = {g: [k for k, gk in enumerate(groups) if gk == g] for g in set(groups)}
    ids = np.zeros((h, w), np.uint8)
    best = np.zeros((h, w))
    xs, ys = points[..., 0], points[..., 1]
    finite = np.isfinite(xs) & np.isfinite(ys)
    xs, ys = np.where(finite, xs, 1e9), np.where(finite, ys, 1e9)
    for k, hole in enumerate(holes):
        sink = hole.depth * _pothole_weight(hole, xs, ys)
        take = finite & (sink > 1e-3) & (sink > best)
        ids[take] = groups[k] + 1
        best = np.where(take, sink, best)
    spacing = 2e-3
    truth = []
    for k, hole in enumerate(holes):
        desc = _describe_hole(hole, rig)
        if groups[k] != k:
            truth.append({"id": k + 1, "depth_mm": 1e3 * hole.depth, "area_m2": 0.0, "volume_l": 0.0,
                          "visible_px": 0, "u": desc["u"], "v": desc["v"], "part_of": groups[k] + 1})
            continue
        group = [holes[j] for j in members[k]]
        reach = [1.25 * max(g.semi_a, g.semi_b) for g in group]
        gx, gy = np.meshgrid(np.arange(min(g.x - r for g, r in zip(group, reach)), max(g.x + r for g, r in zip(group, reach)), spacing),
                             np.arange(min(g.y - r for g, r in zip(group, reach)), max(g.y + r for g, r in zip(group, reach)), spacing))
        own = np.max([g.depth * _pothole_weight(g, gx, gy) for g in group], axis=0)
        for j, other in enumerate(holes):
            if groups[j] != k:
                own = np.where(other.depth * _pothole_weight(other, gx, gy) > own, 0.0, own)
        truth.append({"id": k + 1, "depth_mm": 1e3 * hole.depth,
                      "area_m2": float((own > _OPENING_M).sum() * spacing ** 2),
                      "volume_l": float(own.sum() * spacing ** 2 * 1e3),
                      "visible_px": int((ids == k + 1).sum()), "u": desc["u"], "v": desc["v"],
                      "members": [j + 1 for j in members[k]]})
    return ids, truth


def _ground_truth(rig: StereoRig, field_: _HeightField, h_top: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact left disparity (float32, inf invalid), non-occlusion mask (bool) and the
    world points (float64 (H, W, 3)) the left pixels' centre rays hit."""
    rot = rig.rotation()
    left_c, right_c = rig.centres()
    hf = (field_.h, field_.lipschitz, field_.tile, field_.x0, field_.y0, field_.spacing, h_top)
    points = _centre_hits(left_c, rot, rig.f, rig.cx, rig.cy, rig.width, rig.height, *hf)
    in_right = (points - right_c) @ rot.T
    u_right = rig.f * in_right[..., 0] / in_right[..., 2] + rig.cx
    u_left = np.arange(rig.width, dtype=np.float64)[None, :]
    disparity = u_left - u_right
    valid = np.isfinite(disparity) & (disparity > 0)
    visible = _visible_from(right_c, points, *hf, _OCCLUSION_TOL_M)
    nocc = valid & visible & (u_right >= 0.0) & (u_right <= rig.width - 1.0)
    return np.where(valid, disparity, np.inf).astype(np.float32), nocc, points


def self_test(pair: SynthPair, *, border: int = 8) -> float:
    """RMS grey-level error of the right view warped into the left by the ground truth.

    Each left pixel (u, v) is compared with the right image at (u - d, v), bilinear,
    over non-occluded pixels at least ``border`` pixels from every edge (of both
    views).  For noise-free ``sun`` pairs it measures rendering consistency (a grey
    level or two); with noise it approaches sqrt(2) x the noise level.

    Returns
    -------
    float
        RMS error on the 0-255 scale (nan when no pixel qualifies).
    """
    left = pair.left.astype(np.float64)
    right = pair.right.astype(np.float64)
    h, w = left.shape
    vv, uu = np.mgrid[0:h, 0:w]
    x = uu - pair.disparity.astype(np.float64)
    usable = pair.nocc & np.isfinite(x) & (x >= border) & (x <= w - 1 - border)
    usable &= (uu >= border) & (uu < w - border) & (vv >= border) & (vv < h - border)
    if not usable.any():
        return float("nan")
    xs = x[usable]
    rows = vv[usable]
    x0 = np.floor(xs).astype(np.int64)
    a = xs - x0
    warped = right[rows, x0] * (1.0 - a) + right[rows, np.minimum(x0 + 1, w - 1)] * a
    return float(np.sqrt(np.mean((warped - left[usable]) ** 2)))


# ---------------------------------------------------------------- writing


def _atomic_write(path: Path, write) -> None:
    """Call ``write(tmp)`` on a temporary sibling with the same suffix, then rename."""
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(where_what_fix(str(path.parent), f"cannot write {path.name} ({exc.strerror or exc})",
                                         "check that the folder is writable and the disk is not full")) from exc
    finally:
        if tmp.exists():
            tmp.unlink()


def _write_png(path: Path, image: np.ndarray) -> None:
    def write(tmp):
        if not cv2.imwrite(str(tmp), image):
            raise OSError(f"OpenCV could not encode {path.name}")

    _atomic_write(path, write)


def _write_pfm_local(path: Path, disparity: np.ndarray) -> None:
    data = np.ascontiguousarray(np.flipud(disparity).astype("<f4"))
    with open(path, "wb") as stream:
        stream.write(f"Pf\n{data.shape[1]} {data.shape[0]}\n-1.0\n".encode("ascii"))
        stream.write(data.tobytes())


def _write_pfm(path: Path, disparity: np.ndarray) -> None:
    try:
        from .io import write_pfm  # atomic itself
    except ImportError:  # d3cli.io missing: the format is simple enough to write here
        _atomic_write(path, lambda tmp: _write_pfm_local(tmp, disparity))
    else:
        write_pfm(path, disparity)


def _write_text(path: Path, lines: list[str]) -> None:
    _atomic_write(path, lambda tmp: tmp.write_text("\n".join(lines) + "\n", encoding="utf-8"))


def read_pfm(path) -> np.ndarray:
    """Read a PFM written by :func:`generate_dataset` (or any 1/3-channel PFM).

    Returns float32 (H, W) with the top row first.
    """
    with open(path, "rb") as stream:
        kind = stream.readline().strip()
        dims = stream.readline().split()
        scale = float(stream.readline())
        width, height = int(dims[0]), int(dims[1])
        channels = 3 if kind == b"PF" else 1
        data = np.frombuffer(stream.read(), dtype="<f4" if scale < 0 else ">f4")
    data = data[: width * height * channels].reshape(height, width, channels)[..., 0]
    return np.flipud(data).astype(np.float32)


def pair_name(index: int, variant: str, material: str) -> str:
    """Folder name of pair ``index``: ``synth-0000-sun-asphalt``."""
    return f"synth-{index:04d}-{variant}-{material}"


def generate_dataset(out_dir, *, n: int = 12, seed: int = 0, width: int = 1280, height: int = 720) -> list[Path]:
    """Render ``n`` pairs into pair folders under ``out_dir``.

    Variants cycle sun, dusk, wet and materials asphalt, cement, so six consecutive
    pairs cover every combination.  Each folder holds ``left.png``, ``right.png``
    (8-bit grey), ``disp_gt.pfm`` (float32, inf invalid), ``mask0nocc.png`` (255 =
    visible in the right view), ``calib.txt`` and ``SOURCE.txt`` (``gt_scale: 1``,
    ``gt_invalid: inf``, seeds and scene description); every file is written under a
    temporary name and renamed.  The same (seed, index, size) always gives the same
    pair; ``render_pair(seed=<pair_seed in SOURCE.txt>, ...)`` reproduces it.

    Returns
    -------
    list of Path
        The pair folders, in index order.
    """
    if int(n) < 1:
        raise InputError(where_what_fix("synth", f"--n is {n}", "ask for at least one pair"))
    _check_size(width, height)
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(where_what_fix(str(out_dir), f"cannot create the folder ({exc.strerror or exc})",
                                         "choose a writable output folder")) from exc
    _claim_folder(out_dir, {"generator": "d3stereo synth", "seed": int(seed), "width": int(width),
                            "height": int(height)})
    folders = []
    for index in range(int(n)):
        variant = VARIANTS[index % len(VARIANTS)]
        material = MATERIALS[index % len(MATERIALS)]
        pair_seed = int(np.random.SeedSequence([int(seed), index]).generate_state(1)[0])
        pair = render_pair(seed=pair_seed, width=width, height=height, variant=variant, material=material)
        folder = out_dir / pair_name(index, variant, material)
        folders.append(_write_pair(folder, pair, dataset_seed=int(seed), index=index))
        finite = pair.disparity[np.isfinite(pair.disparity)]
        log.info("synth: wrote %s (disparity %.1f-%.1f px)", folder.name, finite.min(), finite.max())
    return folders


def _write_pair(folder: Path, pair: SynthPair, *, dataset_seed: int, index: int) -> Path:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(where_what_fix(str(folder), f"cannot create the folder ({exc.strerror or exc})",
                                         "choose a writable output folder")) from exc
    _write_png(folder / "left.png", pair.left)
    _write_png(folder / "right.png", pair.right)
    _write_pfm(folder / "disp_gt.pfm", pair.disparity)
    _write_png(folder / "mask0nocc.png", np.where(pair.nocc, 255, 0).astype(np.uint8))
    if pair.pothole_ids is not None:
        _write_png(folder / "potholes_gt.png", pair.pothole_ids)
    gt_text = json.dumps({"definitions": "depth_mm: below the surrounding surface; area_m2: horizontal area "
                                         "deeper than 10 mm; volume_l: fill volume up to the surrounding "
                                         "surface; visible_px: pixels of potholes_gt.png with this id; nested potholes (the "
                                         "floor of one inside the other's part deeper than 10 mm) are one defect: "
                                         "the deepest one's entry lists its members and holds the union's area and "
                                         "volume, the others say part_of that id",
                          "potholes": pair.defects_gt}, indent=2) + "\n"
    _atomic_write(folder / "defects_gt.json", lambda tmp: tmp.write_text(gt_text, encoding="utf-8"))
    calib = pair.calib
    _write_text(folder / "calib.txt", [f"{key}: {_fmt(calib[key])}" for key in
                                       ("f", "baseline", "cx", "cy", "width", "height", "height_m",
                                        "pitch_deg", "roll_deg", "doffs", "ndisp")])
    info = pair.info
    finite = pair.disparity[np.isfinite(pair.disparity)]
    holes = "; ".join(f"x={h['x']:.3f} y={h['y']:.3f} depth={h['depth_m']:.3f} diameter={h['diameter_m']:.2f} "
                      f"u={h['u']:.1f} v={h['v']:.1f}" for h in info["potholes"]) or "none"
    bump = "none" if info["bump"] is None else (f"x={info['bump']['x']:.3f} y={info['bump']['y']:.3f} "
                                                 f"height={info['bump']['height_m']:.3f}")
    _write_text(folder / "SOURCE.txt", [
        "source: d3stereo synthetic road (d3cli.synth), exact ground truth by ray casting",
        "family: synth",
        "gt_scale: 1",
        "gt_invalid: inf",
        f"dataset_seed: {dataset_seed}",
        f"index: {index}",
        f"pair_seed: {info['seed']}",
        f"variant: {info['variant']}",
        f"material: {info['material']}",
        f"potholes: {holes}",
        f"bump: {bump}",
        f"max_disparity: {calib['ndisp']}",
        f"image_size: {calib['width']}x{calib['height']}",
        f"disparity_range: {finite.min():.3f} {finite.max():.3f}",
        f"nocc_share: {pair.nocc.mean():.4f}",
        f"reproduce: render_pair(seed={info['seed']}, width={calib['width']}, height={calib['height']}, "
        f"variant={info['variant']!r}, material={info['material']!r})",
    ])
    return folder


def _fmt(value) -> str:
    return str(value) if isinstance(value, int) else f"{value:.10g}"
