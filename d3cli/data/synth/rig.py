"""The stereo rig: a rectified camera pair above the road drawn at random (height, pitch,
roll, baseline), and the patch of road its views see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


VARIANTS = ("sun", "dusk", "wet")
MATERIALS = ("asphalt", "cement")


# Camera rays must meet the road at least this steeply, so every pixel sees road
# (no horizon) and the texture map stays a bounded patch.
_MIN_DEPRESSION_DEG = 12.0


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
        ``d(u, v) = a0 + a1 (v cos(theta) - u sin(theta))`` (docs/design.md, 'Perspective transformation').
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


def sample_rig(rng: np.random.Generator, width: int, height: int) -> StereoRig:
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
