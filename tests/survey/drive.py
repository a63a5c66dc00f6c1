"""A drive with exactly known poses, without rendering: a camera on a car along a track,
potholes at known places on the road, and each frame's defects.json as the road report
would write it (the outlines and centroids projected through the frame's camera onto its
road plane)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from pyproj import Geod

GEOD = Geod(ellps="WGS84")
F, CX, CY, W, H, BASELINE = 800.0, 639.5, 359.5, 1280, 720, 0.12


@dataclass
class Pose:
    """A frame's camera above the road: height (m), pitch (down +, degrees), roll (degrees)."""

    height: float = 1.5
    pitch: float = 12.0
    roll: float = 0.0

    def axes(self):
        """(up, forward, right) of the road in the left camera frame, and the plane offset."""
        p, r = math.radians(self.pitch), math.radians(self.roll)
        up = np.array([0.0, -math.cos(p), -math.sin(p)])  # pitched down: the axis dips below the horizon
        # Roll about the optical axis (z).
        rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
        up = rz @ up
        z = np.array([0.0, 0.0, 1.0])
        fwd = z - (z @ up) * up
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, up)
        return up, fwd, right, self.height


def camera_points(road_xy, pose: Pose) -> np.ndarray:
    """Camera-frame points (N, 3) of road points (forward, right) from the point below the rig's mid-point."""
    up, fwd, right, h = pose.axes()
    mid = np.array([BASELINE / 2, 0.0, 0.0])
    origin = mid - (up @ mid + h) * up
    xy = np.atleast_2d(np.asarray(road_xy, float))
    return origin + xy[:, :1] * fwd + xy[:, 1:2] * right


def project(points: np.ndarray) -> np.ndarray:
    return np.stack([F * points[:, 0] / points[:, 2] + CX, F * points[:, 1] / points[:, 2] + CY], axis=1)


def plane_info(pose: Pose) -> dict:
    up, _, _, h = pose.axes()
    return {"normal": up.tolist(), "offset_m": h, "inlier_share": 0.9}


def road_of(lon, lat, fix, heading) -> tuple[float, float]:
    """(forward, right) metres of a point from a fix along a heading (exact geodesics)."""
    az, _, dist = GEOD.inv(fix[0], fix[1], lon, lat)
    a = math.radians(az - heading)
    return dist * math.cos(a), dist * math.sin(a)


def straight_track(n: int, spacing: float, *, lat0=48.1, lon0=11.5, heading=30.0, curve_deg_per_m=0.0):
    """n fixes ``spacing`` metres apart, starting at (lat0, lon0) with ``heading``; with a
    curvature, the heading turns by ``curve_deg_per_m`` per metre (a circular arc)."""
    lons, lats, heads = [lon0], [lat0], [heading]
    for _ in range(n - 1):
        mid = heads[-1] + curve_deg_per_m * spacing / 2  # the chord of the arc
        lo, la, _ = GEOD.fwd(lons[-1], lats[-1], mid, spacing)
        lons.append(lo)
        lats.append(la)
        heads.append(heads[-1] + curve_deg_per_m * spacing)
    return lons, lats, heads


def pothole(lon, lat, radius, depth_mm, n=24):
    return {"lon": lon, "lat": lat, "radius": radius, "depth_mm": depth_mm, "n": n}


def frame_defects(frame_fix, heading, potholes, pose: Pose, *, max_range=14.0, decided=0.9) -> list[dict]:
    """defects.json items of the potholes a frame sees (inside the image, within max_range)."""
    items = []
    for k, p in enumerate(potholes):
        cx, cy = road_of(p["lon"], p["lat"], frame_fix, heading)
        if not 1.0 < cx < max_range:
            continue
        angles = np.linspace(0, 2 * math.pi, p["n"], endpoint=False)
        ring = np.stack([cx + p["radius"] * np.cos(angles), cy + p["radius"] * np.sin(angles)], axis=1)
        pts = camera_points(ring, pose)
        if (pts[:, 2] <= 0.1).any():
            continue
        uv = project(pts)
        if uv[:, 0].min() < 0 or uv[:, 0].max() > W - 1 or uv[:, 1].min() < 0 or uv[:, 1].max() > H - 1:
            continue
        centre_cam = camera_points([[cx, cy]], pose)
        centre_uv = project(centre_cam)[0]
        area = math.pi * p["radius"] ** 2
        items.append({"id": len(items) + 1, "kind": p.get("kind", "pothole"),
                      "centroid_px": centre_uv.tolist(), "centroid_m": centre_cam[0].tolist(),
                      "bbox_px": [int(uv[:, 0].min()), int(uv[:, 1].min()), int(uv[:, 0].max()), int(uv[:, 1].max())],
                      "outline_px": [uv.tolist()], "area_m2": area, "max_depth_mm": p["depth_mm"] * (1 + 0.01 * cx),
                      "mean_depth_mm": p["depth_mm"] / 2, "volume_l": area * p["depth_mm"] / 2,
                      "decided_share": decided, "low_confidence": False, "confidence": "ok", "flags": [],
                      "reasons": "", "severity": "medium", "diameter_mm": 2000 * p["radius"],
                      "equivalent_potholes": 1.0, "truth": k})
    return items


def write_drive(root: Path, lons, lats, heads, potholes, *, pose: Pose | None = None, track=True,
                heading_in_track=False, unplaced=()) -> tuple[Path, Path, list]:
    """Input folder (pair folders with calib.txt and a track.csv) and output folder (per pair
    result.json and defects.json, road_survey.json) of a drive; returns (in, out, pairs)."""
    pose = pose or Pose()
    inp, out = Path(root) / "in", Path(root) / "out"
    pairs = []
    rows = ["frame,latitude,longitude" + (",heading_deg" if heading_in_track else "")]
    for i, (lo, la, hd) in enumerate(zip(lons, lats, heads)):
        name = f"f{i:04d}"
        (inp / name).mkdir(parents=True, exist_ok=True)
        (inp / name / "calib.txt").write_text(f"f: {F}\nbaseline: {BASELINE}\ncx: {CX}\ncy: {CY}\nwidth: {W}\n")
        (out / name).mkdir(parents=True, exist_ok=True)
        (out / name / "result.json").write_text(json.dumps({"shape": [H, W]}))
        defects = frame_defects((lo, la), hd, potholes, pose)
        (out / name / "defects.json").write_text(json.dumps({"plane": plane_info(pose), "road_like": True,
                                                              "defects": defects, "warnings": []}))
        if name not in unplaced:
            rows.append(f"{name},{la:.9f},{lo:.9f}" + (f",{hd % 360:.6f}" if heading_in_track else ""))
        pairs.append(SimpleNamespace(name=name, left=inp / name / "left.png", calib=inp / name / "calib.txt"))
    if track:
        (inp / "track.csv").write_text("\n".join(rows) + "\n")
    (out / "road_survey.json").write_text(json.dumps({"frames": len(pairs), "potholes": 0}))
    (out / "defects.csv").write_text("pair,id\n")
    return inp, out, pairs
