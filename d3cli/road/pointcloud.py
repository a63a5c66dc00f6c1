"""Point clouds from disparity maps (``--pointcloud``): camera, back-projection, PLY.

A left pixel (u, v) with disparity d of a rectified rig (focal length f in pixels,
baseline B in metres, principal point (cx, cy), disparity offset doffs between the two
principal points, Middlebury 2014's ``doffs``) sees the point

    Z = f B / (d + doffs),   X = (u - cx) Z / f,   Y = (v - cy) Z / f

in the left camera frame (x right, y down, z forward), in metres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, where_what_fix
from ..data.formats import atomic_write

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Camera:
    """Rectified stereo camera at the resolution of the images.

    Attributes
    ----------
    f : float
        Focal length, pixels.
    baseline : float
        Distance of the camera centres, metres.
    cx, cy : float
        Principal point of the left camera, pixels.
    doffs : float
        x difference of the principal points (right - left), pixels; 0 for most rigs.
    """

    f: float
    baseline: float
    cx: float
    cy: float
    doffs: float = 0.0


def camera_from(calib: dict | None, cfg, shape: tuple[int, int]) -> Camera | None:
    """The camera of a pair from its calibration, completed from the config.

    Parameters
    ----------
    calib : dict or None
        :func:`d3cli.data.formats.read_calib` of the pair's calib.txt (Middlebury, KITTI, synth,
        Stereo-Road layouts), or None.  When it gives a ``width`` different from the
        image width (images downsized after calibration), f, cx, cy and doffs are
        scaled by image width / calib width.
    cfg : Config
        Its ``camera`` section (f, baseline, cx, cy) fills what the calibration lacks.
    shape : (int, int)
        Image (H, W); the principal point defaults to the image centre.

    Returns
    -------
    Camera or None
        None when the focal length or the baseline is unknown.
    """
    calib = dict(calib or {})
    h, w = int(shape[0]), int(shape[1])
    scale = 1.0
    if calib.get("width") and int(calib["width"]) != w:
        scale = w / float(calib["width"])
    cam = cfg.camera

    def pick(key, default=None):
        if calib.get(key) is not None:
            value = float(calib[key])
            if key == "baseline":
                return value
            # Pixel coordinates follow the resize: centres map as (x + 0.5) s - 0.5.
            return (value + 0.5) * scale - 0.5 if key in ("cx", "cy") else value * scale
        value = getattr(cam, key, None)
        return float(value) if value is not None else default

    f = pick("f")
    baseline = pick("baseline")
    if f is None or baseline is None or not (f > 0 and baseline > 0):
        return None
    cx = pick("cx", (w - 1) / 2.0)
    cy = pick("cy", (h - 1) / 2.0)
    doffs = float(calib.get("doffs") or 0.0) * scale
    return Camera(f=f, baseline=baseline, cx=cx, cy=cy, doffs=doffs)


def disparity_to_points(
    disparity: np.ndarray,
    valid: np.ndarray,
    camera: Camera,
    *,
    doffs: float | None = None,
    depth_range: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Back-project valid pixels of a left-view disparity map to 3-D points.

    Parameters
    ----------
    disparity : ndarray, float, (H, W)
        Disparity in pixels.
    valid : ndarray, bool, (H, W)
        Pixels to keep; non-finite disparities and ``d + doffs <= 0`` are dropped too.
    camera : Camera
    doffs : float, optional, keyword-only
        Overrides ``camera.doffs``.
    depth_range : (float, float), optional, keyword-only
        ``(min, max)`` depth Z in metres; points outside ``min <= Z <= max`` are dropped
        (near-zero disparities give points at absurd depths, e.g. 1e33 m); None keeps all.

    Returns
    -------
    points : ndarray, float32, (N, 3)
        X, Y, Z in metres, left camera frame (x right, y down, z forward).
    index : ndarray, int64, (N, 2)
        (v, u) of each point, e.g. to take colours from the left image.
    """
    disp = np.asarray(disparity, dtype=np.float64)
    valid = np.asarray(valid, dtype=bool)
    if disp.ndim != 2 or valid.shape != disp.shape:
        raise InputError(where_what_fix(
            "point cloud", f"disparity {disp.shape} and mask {valid.shape} differ", "pass equal (H, W) arrays"))
    off = camera.doffs if doffs is None else float(doffs)
    with np.errstate(invalid="ignore"):
        keep = valid & np.isfinite(disp) & (disp + off > 0)
    v, u = np.nonzero(keep)
    z = camera.f * camera.baseline / (disp[v, u] + off)
    if depth_range is not None:
        near, far = (float(x) for x in depth_range)
        inside = (z >= near) & (z <= far)
        v, u, z = v[inside], u[inside], z[inside]
    x = (u - camera.cx) * z / camera.f
    y = (v - camera.cy) * z / camera.f
    return np.stack([x, y, z], axis=1).astype(np.float32), np.stack([v, u], axis=1)


def point_colours(image: np.ndarray, index: np.ndarray) -> np.ndarray:
    """uint8 (N, 3) RGB colours of the pixels ``index`` (v, u) of a grey or RGB image."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        if img.dtype.kind in "ui" and img.max(initial=0) > 255:
            img = img / 257.0
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    rgb = img[index[:, 0], index[:, 1], :3]
    return np.ascontiguousarray(rgb, dtype=np.uint8)


def write_ply(path, points: np.ndarray, colours: np.ndarray | None = None) -> Path:
    """Write a binary little-endian PLY point cloud, atomically.

    Parameters
    ----------
    path : path-like
        ``.ply`` file; its folder must exist.
    points : ndarray, float, (N, 3)
        x, y, z (metres), written as float32.
    colours : ndarray, uint8, (N, 3), optional
        red, green, blue per point.

    Returns
    -------
    Path
    """
    pts = np.ascontiguousarray(points, dtype="<f4").reshape(-1, 3)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if colours is not None:
        cols = np.asarray(colours, dtype=np.uint8).reshape(-1, 3)
        if cols.shape[0] != pts.shape[0]:
            raise InputError(where_what_fix(
                str(path), f"{pts.shape[0]} points but {cols.shape[0]} colours", "pass one colour per point"))
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    rec = np.empty(pts.shape[0], dtype=fields)
    rec["x"], rec["y"], rec["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    if colours is not None:
        rec["red"], rec["green"], rec["blue"] = cols[:, 0], cols[:, 1], cols[:, 2]
    types = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment d3stereo point cloud, metres, left camera frame",
              f"element vertex {pts.shape[0]}"]
    header += [f"property {types[t]} {name}" for name, t in fields]
    header += ["end_header"]
    blob = ("\n".join(header) + "\n").encode("ascii") + rec.tobytes()

    def write(tmp: Path) -> None:
        tmp.write_bytes(blob)

    return atomic_write(path, write)


def read_ply(path) -> tuple[np.ndarray, np.ndarray | None]:
    """Read a PLY written by :func:`write_ply`: float32 (N, 3) points, uint8 (N, 3) colours or None.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.ply`` file.
    """
    data = Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").splitlines()
    n = next(int(line.split()[-1]) for line in lines if line.startswith("element vertex"))
    names = [line.split()[-1] for line in lines if line.startswith("property")]
    fields = [(name, "<f4" if name in "xyz" else "u1") for name in names]
    rec = np.frombuffer(data[end:], dtype=fields, count=n)
    pts = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
    cols = np.stack([rec["red"], rec["green"], rec["blue"]], axis=1) if "red" in names else None
    return pts, cols


def save_pair_cloud(path, disparity: np.ndarray, valid: np.ndarray, left: np.ndarray, camera: Camera, *,
                    depth_range: tuple[float, float] | None = None) -> int:
    """Back-project, colour from the left image and write ``path``; returns the point count.

    ``depth_range``: ``(min, max)`` metres of the points kept (``camera.min_depth_m``,
    ``camera.max_depth_m`` in a batch); see :func:`disparity_to_points`.
    """
    points, index = disparity_to_points(disparity, valid, camera, depth_range=depth_range)
    write_ply(path, points, point_colours(left, index))
    return int(points.shape[0])
