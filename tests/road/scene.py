"""An analytic road scene for the road tests: a plane with a paraboloid pothole.

World frame: X right, Y forward, Z up, road at Z = 0; the pothole's surface is
``Z = -D (1 - r^2 / R^2)`` for ``r < R`` around (xc, yc) (further potholes may have a flat
floor, :func:`flat_profile`).  Its volume is ``pi R^2 D / 2``
and the area deeper than t is ``pi R^2 (1 - t / D)``.  The disparity of every pixel is
computed exactly by intersecting its ray with the surface (bisection).
"""

from __future__ import annotations

import math

import numpy as np

from d3cli.road.pointcloud import Camera


def rotation(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """Columns: the camera's x (right), y (down), z (forward) axes in the world frame."""
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    x = np.array([1.0, 0.0, 0.0])
    y = np.array([0.0, -math.sin(p), -math.cos(p)])
    z = np.array([0.0, math.cos(p), -math.sin(p)])
    xr = math.cos(r) * x + math.sin(r) * y
    yr = -math.sin(r) * x + math.cos(r) * y
    return np.stack([xr, yr, z], axis=1)


def pothole_scene(*, width=320, height=240, f=300.0, baseline=0.12, cam_height=1.5, pitch_deg=45.0,
                  roll_deg=8.0, depth=0.08, radius=0.3, centre=(0.1, 1.5), bump=None, more=(), cone=False):
    """-> (disparity float32 (H, W), camera, rotation).  ``cone``: the first pothole is a cone
    ``D (1 - r / R)`` instead of a paraboloid; ``bump``: optional (x, y, R, H) dome;
    ``more``: further potholes (x, y, R, D) paraboloids or (x, y, R, D, flat[, aspect])
    flat-floored (:func:`flat_profile`), elliptical with semi-axes R along X and R aspect
    along Y; where they overlap the deepest wins."""
    cam = Camera(f=f, baseline=baseline, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0)
    rot = rotation(pitch_deg, roll_deg)
    v, u = np.mgrid[0:height, 0:width].astype(np.float64)
    rays_c = np.stack([(u - cam.cx) / f, (v - cam.cy) / f, np.ones_like(u)], axis=-1)
    rays_w = rays_c @ rot.T
    o = np.array([0.0, 0.0, cam_height])

    def surface(x, y):
        sink = np.zeros_like(x)
        for k, (hx, hy, hr, hd, *flat) in enumerate(((centre[0], centre[1], radius, depth), *more)):
            aspect = flat[1] if len(flat) > 1 else 1.0
            r = np.sqrt(((x - hx) / hr) ** 2 + ((y - hy) / (hr * aspect)) ** 2)
            profile = np.clip(1.0 - (r if cone and k == 0 else r ** 2), 0.0, None)
            sink = np.maximum(sink, hd * (flat_profile(r, flat[0]) if flat else profile))
        z = -sink
        if bump is not None:
            bx, by, br, bh = bump
            b2 = ((x - bx) ** 2 + (y - by) ** 2) / br ** 2
            z = z + bh * np.clip(1.0 - b2, 0.0, None)
        return z

    lo = np.zeros(rays_w.shape[:2])
    hi = (cam_height + depth + 1.0) / np.maximum(-rays_w[..., 2], 1e-9)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        p = o + rays_w * mid[..., None]
        above = p[..., 2] > surface(p[..., 0], p[..., 1])
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
    t = 0.5 * (lo + hi)
    z_cam = t * rays_c[..., 2]  # rays_c has z = 1, so the camera depth is t
    disp = (f * baseline / z_cam).astype(np.float32)
    return disp, cam, rot


def flat_profile(r, flat: float):
    """Depth profile in [0, 1] of a flat-floored pothole at normalised radius ``r``: 1 on the
    floor (r < flat), a raised-cosine wall out to r = 1 (the profile of d3cli.data.synth)."""
    wall = np.clip((r - flat) / (1.0 - flat), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * wall))


def cone_truth(depth: float, radius: float, threshold: float) -> dict:
    """Depth, area deeper than ``threshold`` and volume of a cone pothole."""
    return {"max_depth_mm": depth * 1e3, "area_m2": math.pi * (radius * (1 - threshold / depth)) ** 2,
            "volume_l": math.pi * radius ** 2 * depth / 3 * 1e3}


def paraboloid_truth(depth: float, radius: float, threshold: float) -> dict:
    return {"max_depth_mm": depth * 1e3, "area_m2": math.pi * radius ** 2 * (1 - threshold / depth),
            "volume_l": math.pi * radius ** 2 * depth / 2 * 1e3}
