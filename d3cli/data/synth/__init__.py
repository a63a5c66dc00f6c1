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

A *drive* (:func:`generate_drive`, module ``drive``) renders overlapping frames with one
rig moving along a straight road, with a GPS track (``track.csv``, ``track.gpx``) and the
potholes' map positions, outlines and measurements (``drive_gt.json``): ground truth for
geolocating and merging detections across frames.

Modules: ``rig``, ``terrain``, ``texture``, ``render``, ``truth``, ``dataset``, ``drive``;
this package re-exports the public API: :func:`render_pair`, :func:`generate_dataset`,
:func:`generate_drive`, :func:`self_test`, :func:`pothole_groups`, :func:`pothole_truth`,
:func:`pothole_depth_image` and the records.

May import: :mod:`d3cli.data.formats` (its writers), :mod:`d3cli.errors` only.
"""

from __future__ import annotations

from .dataset import DATASET_FILE, MAX_SIDE, MIN_SIDE, generate_dataset, pair_name, pothole_depth_image, render_pair
from .drive import generate_drive
from .rig import MATERIALS, VARIANTS, StereoRig
from .terrain import Pothole
from .truth import SynthPair, pothole_groups, pothole_truth, self_test

__all__ = [
    "DATASET_FILE", "MATERIALS", "MAX_SIDE", "MIN_SIDE", "VARIANTS", "Pothole", "StereoRig", "SynthPair",
    "generate_dataset", "generate_drive", "pair_name", "pothole_depth_image", "pothole_groups", "pothole_truth", "render_pair", "self_test",
]
