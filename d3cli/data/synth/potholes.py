"""Pothole shapes of the synthetic road: the families real potholes come in, their depth
profiles and how they are drawn.

A pothole is an elliptical region of the road (semi-axes ``semi_a``, ``semi_b``, rotated
by ``angle``, outline perturbed by harmonics) lowered by ``depth * weight(rho)``, where
``rho`` is the normalised radius (1 at the rim) and ``weight`` in [0, 1] the family's
profile:

============  ==========================================================================
family        profile
============  ==========================================================================
classic       flat floor, raised-cosine walls (every pothole of ``shapes="classic"``)
bowl          ``1 - rho^p``, p in [1.6, 4] (paraboloid p = 2; larger p: flatter bottom)
flat-steep    flat floor, raised-cosine walls as narrow as the slope limit allows
flat-gentle   flat floor, raised-cosine walls over half the radius or more
cone          ``1 - rho`` (a point at the bottom)
multilevel    a shelf at 40-65 % of the depth with a deeper flat core off centre
rough         a bowl or flat floor with 5-9 mm of floor relief (broken base course)
elongated     a bowl or flat floor with an aspect ratio of 0.25-0.5
ragged        a bowl or flat floor with a ragged outline (harmonics 4-7)
water         a bowl or flat floor holding water up to 30-70 % of its depth: the water
              is a flat, dark, reflective surface at that level
============  ==========================================================================

Every family's surface is exactly what the ground truth (:mod:`.truth`) integrates: the
relief and the water are part of the height field, so depth, area and volume are those of
the surface the cameras see (a water surface counts as the pothole's visible floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Families drawn by ``shapes="varied"`` (the default), in order.
FAMILIES = ("bowl", "flat-steep", "flat-gentle", "cone", "multilevel", "rough", "elongated", "ragged", "water")

_CLASSIC_ROUGH_M = 2.5e-3  # relief of broken pothole floors (std of |noise| scale)
_MAX_SLOPE = 1.3  # steepest wall drawn: keeps the surface a height field the cameras see


@dataclass(frozen=True)
class Pothole:
    """A depression of the road (world metres); ``shape`` names its family (module docstring).

    ``profile``: the bowl exponent p; ``core``: (dx, dy, radius, shelf) of a multilevel
    pothole's deeper core (offset and radius as fractions of the semi-axes, shelf depth as
    a fraction of ``depth``); ``roughness_m``: floor relief scale; ``ragged``: extra outline
    harmonics (order, amplitude, phase)...; ``water_fill``: share of the depth filled.
    """

    x: float
    y: float
    semi_a: float  # semi-axis along the rotated x direction, metres
    semi_b: float
    angle: float  # radians
    depth: float  # metres, positive
    flat_fraction: float  # share of the normalised radius with a flat bottom
    wobble: tuple[float, float, float, float]  # 2nd/3rd harmonic amplitude and phase
    shape: str = "classic"
    profile: float = 2.0
    core: tuple = ()
    roughness_m: float = _CLASSIC_ROUGH_M
    ragged: tuple = ()
    water_fill: float = 0.0


def normalised_radius(hole: Pothole, xx, yy):
    """Radius of world points (xx, yy) in the hole's rotated, perturbed ellipse (1 = its rim)."""
    dx, dy = xx - hole.x, yy - hole.y
    ca, sa = math.cos(hole.angle), math.sin(hole.angle)
    xr = (dx * ca + dy * sa) / hole.semi_a
    yr = (-dx * sa + dy * ca) / hole.semi_b
    theta = np.arctan2(yr, xr)
    a2, p2, a3, p3 = hole.wobble
    rim = 1.0 + a2 * np.cos(2 * theta + p2) + a3 * np.cos(3 * theta + p3)
    for order, amp, phase in hole.ragged:
        rim = rim + amp * np.cos(order * theta + phase)
    return np.hypot(xr, yr) / rim


def _flat(rho, flat_fraction: float):
    wall = np.clip((rho - flat_fraction) / (1.0 - flat_fraction), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * wall))


def radial_weight(hole: Pothole, rho):
    """The profile along the normalised radius, without a multilevel pothole's core."""
    if hole.shape == "cone":
        return np.clip(1.0 - rho, 0.0, 1.0)
    if hole.flat_fraction < 0.0:  # bowl-profiled members of the mixed families
        return np.clip(1.0 - np.minimum(rho, 1.0) ** hole.profile, 0.0, 1.0)
    return _flat(rho, hole.flat_fraction) * (hole.core[3] if hole.core else 1.0)


def pothole_weight(hole: Pothole, xx, yy):
    """Depth profile in [0, 1] (1 = deepest) of one pothole at world points (xx, yy)."""
    rho = normalised_radius(hole, xx, yy)
    weight = radial_weight(hole, rho)
    if hole.core:
        dx, dy, radius, shelf = hole.core
        inner = Pothole(hole.x + dx * hole.semi_a * math.cos(hole.angle) - dy * hole.semi_b * math.sin(hole.angle),
                        hole.y + dx * hole.semi_a * math.sin(hole.angle) + dy * hole.semi_b * math.cos(hole.angle),
                        radius * hole.semi_a, radius * hole.semi_b, hole.angle, hole.depth, 0.5, (0.0, 0.0, 0.0, 0.0))
        weight = np.maximum(weight, _flat(normalised_radius(inner, xx, yy), 0.5) * (rho < 1.0))
    return weight


def _flat_fraction(rng, depth: float, semi_b: float, wall_share: tuple[float, float]) -> float:
    # A raised-cosine wall of width w is at most pi D / (2 w) steep.
    wall = max(math.pi / 2 * depth / _MAX_SLOPE, rng.uniform(*wall_share) * semi_b)
    return max(0.0, 1.0 - wall / semi_b)


def varied_pothole(classic: Pothole, shape_rng, shape: str) -> Pothole:
    """``classic`` (the seed's pothole as ``shapes="classic"`` draws it: position, size, depth,
    outline) reshaped into family ``shape`` with ``shape_rng`` (a stream of its own, so the
    rest of the scene stays that of the seed)."""
    depth = float(np.clip(classic.depth * shape_rng.uniform(0.8, 1.4), 0.018, 0.075))
    semi_a, semi_b = classic.semi_a, classic.semi_b
    if shape == "elongated":
        semi_a = max(semi_a, 0.2)
        semi_b = semi_a * shape_rng.uniform(0.25, 0.5)
    if shape == "multilevel":
        semi_a, semi_b = max(semi_a, 0.2), max(semi_b, 0.16)
    # Floors are smoother than the classic ones except in the rough family, whose relief
    # is what sets it apart.
    kw = dict(shape=shape, roughness_m=1e-3)
    bowlish = shape in ("bowl", "cone") or (shape in ("rough", "elongated", "ragged", "water")
                                            and shape_rng.uniform() < 0.5)
    if bowlish:
        # The wall slope at the rim is p depth / semi_b: p is limited to keep it drawable.
        kw["profile"] = float(max(1.0, min(shape_rng.uniform(1.6, 4.0), _MAX_SLOPE * semi_b / depth)))
        flat_fraction = -1.0
        if shape == "cone":
            depth = min(depth, _MAX_SLOPE * semi_b)
    elif shape == "flat-steep":
        flat_fraction = _flat_fraction(shape_rng, depth, semi_b, (0.05, 0.15))
    elif shape == "flat-gentle":
        flat_fraction = _flat_fraction(shape_rng, depth, semi_b, (0.55, 0.9))
    else:
        flat_fraction = _flat_fraction(shape_rng, depth, semi_b, (0.25, 0.5))
    if shape == "multilevel":
        kw["core"] = (shape_rng.uniform(-0.2, 0.2), shape_rng.uniform(-0.2, 0.2), shape_rng.uniform(0.35, 0.5),
                      shape_rng.uniform(0.4, 0.65))
    if shape == "rough":
        kw["roughness_m"] = shape_rng.uniform(3e-3, 5e-3)  # |noise| averages ~0.8: 2.5-4 mm of relief
    if shape == "ragged":
        kw["ragged"] = tuple((int(k), shape_rng.uniform(0.04, 0.09), shape_rng.uniform(0, 2 * math.pi))
                             for k in shape_rng.choice([4, 5, 6, 7], size=2, replace=False))
    if shape == "water":
        kw["water_fill"] = shape_rng.uniform(0.3, 0.7)
    return Pothole(classic.x, classic.y, semi_a, semi_b, classic.angle, depth, flat_fraction, classic.wobble, **kw)
