"""Where a defect lies on the earth: its pixels onto the frame's road plane, then from the
frame's fix along its heading.

1. **Pixels onto the road.**  A left-image pixel (u, v) is the ray
   ``((u - cx) / f, (v - cy) / f, 1)`` from the left camera centre (camera frame: x right,
   y down, z forward, metres; :mod:`d3cli.road.pointcloud`).  It meets the pair's fitted
   road plane ``n.P + c = 0`` (``defects.json``'s ``plane``: unit normal toward the
   camera, c the left camera's height) at ``P = -c d / (n.d)``; a ray that does not meet
   the plane ahead of the camera (at or above the horizon) gives no point.
2. **Road coordinates.**  Up is the plane's normal, forward the camera's optical axis
   projected onto the plane, right = forward x up; so the camera's pitch and roll come
   from the plane fit, and the camera looks straight ahead.  The origin is the point of
   the plane below the rig's mid-point (half a baseline right of the left camera).  A
   point's forward and lateral (right +) distances are its offsets from that origin.
3. **On the earth.**  The fix of a frame is that origin (``road.antenna_forward_m`` and
   ``road.antenna_right_m`` say where the GPS antenna is instead, metres ahead of and to
   the right of the rig's mid-point).  The camera's forward axis points along the frame's
   heading turned by ``road.camera_yaw_deg`` (clockwise; 0: straight ahead).  A point
   ``(forward, right)`` is one geodesic step from the fix (WGS84,
   :meth:`pyproj.Geod.fwd`) of length ``hypot(forward, right)`` at azimuth
   ``heading + atan2(right, forward)``.

Error budget (docs/survey.md, measured in tests/survey/test_geolocate.py): the geometry
is exact (an analytic camera and plane come back to within 1 mm at 2-12 m); what moves
a point is its inputs.  A pixel error e_px moves a road point at range Z, camera height
h, by ``Z e_px / f`` across and ``Z^2 e_px / (f h)`` along the road; a pitch error
``dtheta`` of the plane fit moves it by ``Z^2 dtheta / h`` along; a camera height error
``dh`` by ``Z dh / h`` along; a heading error ``dpsi`` by ``Z dpsi`` across.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..road.pointcloud import Camera
from .gis import geod


@dataclass(frozen=True)
class RoadAxes:
    """The road coordinates of one frame, in its left camera frame (metres).

    Attributes
    ----------
    origin : ndarray, (3,)
        The point of the road plane below the rig's mid-point.
    forward, right, up : ndarray, (3,)
        Unit vectors: the optical axis projected onto the plane, forward x up, the normal.
    normal : ndarray, (3,)
    offset : float
        The plane ``normal . P + offset = 0``.
    """

    origin: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    normal: np.ndarray
    offset: float


def road_axes(normal, offset: float, baseline: float) -> RoadAxes | None:
    """The road coordinates of a frame from its fitted plane.

    Parameters
    ----------
    normal : sequence of 3 float
        The plane's normal in the left camera frame (defects.json ``plane.normal``).
    offset : float
        The plane's offset c of ``normal . P + c = 0`` (``plane.offset_m``).
    baseline : float
        The rig's baseline, metres (the origin is half of it right of the left camera).

    Returns
    -------
    RoadAxes or None
        None for a plane the camera looks along (no forward direction) or through.
    """
    n = np.asarray(normal, np.float64)
    norm = float(np.linalg.norm(n))
    if not (norm > 0 and math.isfinite(offset)):
        return None
    n, c = n / norm, float(offset) / norm
    if c < 0:  # the normal toward the camera: up
        n, c = -n, -c
    if c == 0:
        return None
    z = np.array([0.0, 0.0, 1.0])
    fwd = z - (z @ n) * n
    if np.linalg.norm(fwd) < 1e-6:
        return None
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, n)
    mid = np.array([baseline / 2.0, 0.0, 0.0])
    origin = mid - (n @ mid + c) * n
    return RoadAxes(origin=origin, forward=fwd, right=right, up=n, normal=n, offset=c)


def pixels_to_road(uv, camera: Camera, axes: RoadAxes) -> np.ndarray:
    """Road coordinates of the points that left-image pixels see.

    Parameters
    ----------
    uv : array_like, (N, 2)
        Pixel columns and rows of the left image.
    camera : Camera
        Its focal length and principal point.
    axes : RoadAxes
        The frame's road coordinates (:func:`road_axes`).

    Returns
    -------
    ndarray, (N, 2)
        Forward and right distances, metres, from the point below the rig's mid-point;
        NaN where the ray does not meet the plane ahead of the camera.
    """
    uv = np.atleast_2d(np.asarray(uv, np.float64))
    d = np.stack([(uv[:, 0] - camera.cx) / camera.f, (uv[:, 1] - camera.cy) / camera.f, np.ones(len(uv))], axis=1)
    denom = d @ axes.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -axes.offset / denom
    ok = np.isfinite(t) & (t > 0)
    p = d * np.where(ok, t, np.nan)[:, None] - axes.origin
    return np.stack([p @ axes.forward, p @ axes.right], axis=1)


def road_to_lonlat(road_xy, lon: float, lat: float, heading_deg: float, *, antenna_forward_m: float = 0.0,
                   antenna_right_m: float = 0.0, camera_yaw_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Road points of a frame on the earth (module docstring, step 3).

    Parameters
    ----------
    road_xy : array_like, (N, 2)
        Forward and right distances, metres, from the point below the rig's mid-point (NaN
        stays NaN).
    lon, lat : float
        The frame's fix, WGS84 degrees.
    heading_deg : float
        The frame's heading, degrees clockwise from north.
    antenna_forward_m, antenna_right_m : float, keyword-only
        Where the fix is, metres ahead of and right of the rig's mid-point.
    camera_yaw_deg : float, keyword-only
        The camera's forward axis, degrees clockwise of the heading.

    Returns
    -------
    lon, lat : ndarray
        Degrees.
    """
    xy = np.atleast_2d(np.asarray(road_xy, np.float64))
    yaw = math.radians(camera_yaw_deg)
    fwd = xy[:, 0] * math.cos(yaw) - xy[:, 1] * math.sin(yaw) - antenna_forward_m
    right = xy[:, 0] * math.sin(yaw) + xy[:, 1] * math.cos(yaw) - antenna_right_m
    dist = np.hypot(fwd, right)
    az = (heading_deg + np.degrees(np.arctan2(right, fwd))) % 360.0
    ok = np.isfinite(dist)
    out_lon, out_lat = np.full(len(xy), np.nan), np.full(len(xy), np.nan)
    if ok.any():
        n = int(ok.sum())
        lo, la, _ = geod().fwd(np.full(n, lon), np.full(n, lat), az[ok], dist[ok])
        out_lon[ok], out_lat[ok] = lo, la
    return out_lon, out_lat


def locate_defect(defect: dict, camera: Camera, axes: RoadAxes, lon: float, lat: float, heading_deg: float,
                  **offsets) -> dict | None:
    """A defect of defects.json on the earth, or None when its centroid's ray misses the road.

    Returns
    -------
    dict
        ``centroid`` (lon, lat), ``outline`` (list of rings of (lon, lat); a ring keeps its
        points that meet the road and is dropped with fewer than 3), ``road_centroid``
        (forward, right metres) and ``range_m`` (the centroid's distance from the left
        camera along its optical axis, from defects.json's ``centroid_m``, else the road point).
    """
    centre = pixels_to_road([defect["centroid_px"]], camera, axes)
    if not np.isfinite(centre).all():
        return None
    c_lon, c_lat = road_to_lonlat(centre, lon, lat, heading_deg, **offsets)
    rings = []
    for poly in defect.get("outline_px") or []:
        pts = np.asarray(poly, np.float64).reshape(-1, 2)
        road = pixels_to_road(pts, camera, axes)
        road = road[np.isfinite(road).all(axis=1)]
        if len(road) >= 3:
            r_lon, r_lat = road_to_lonlat(road, lon, lat, heading_deg, **offsets)
            rings.append(list(zip(r_lon.tolist(), r_lat.tolist())))
    z = (defect.get("centroid_m") or [None, None, None])[2]
    if z is None or not math.isfinite(float(z)):
        z = float(centre[0, 0] + axes.origin @ axes.forward)
    return {"centroid": (float(c_lon[0]), float(c_lat[0])), "outline": rings,
            "road_centroid": (float(centre[0, 0]), float(centre[0, 1])), "range_m": float(z)}
