"""Calibration files: Middlebury ``calib.txt``, KITTI projection matrices, ``key: value``
lines -> one dict of focal length, baseline, principal point and disparity range.
"""

from __future__ import annotations

import os
import re

import numpy as np

from ...errors import InputError, where_what_fix
from .images import _read_bytes, regular_file


# Keys read_calib may return, with the numeric type of each.
CALIB_KEYS = {
    "f": float,
    "baseline": float,
    "cx": float,
    "cy": float,
    "doffs": float,
    "ndisp": int,
    "width": int,
    "height": int,
    "height_m": float,
    "pitch_deg": float,
    "roll_deg": float,
    "vmin": float,
    "vmax": float,
}


_CALIB_ALIASES = {"focal": "f", "fx": "f", "focal_px": "f", "baseline_m": "baseline"}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_MIDDLEBURY_CAM = re.compile(r"^cam0\s*=\s*\[(.*)\]\s*$")
_KEY_VALUE = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*[:=]\s*(.*?)\s*$")


# Left/right projection-matrix pairs, first match wins: KITTI 2012 grey (P0, P1),
# KITTI 2015 calib_cam_to_cam (P_rect_02, P_rect_03), KITTI colour (P2, P3),
# Karlsruhe sequences (P1 = left, P2 = right).
_PROJECTION_PAIRS = (("P0", "P1"), ("P_rect_02", "P_rect_03"), ("P2", "P3"), ("P1", "P2"))


#: Karlsruhe-style files give the projections of the cropped images (``roi:``) too.
_ROI_PAIR = ("P1_roi", "P2_roi")


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(_NUMBER, text)]


def _calib_from_projections(matrices: dict[str, np.ndarray], pairs=_PROJECTION_PAIRS) -> tuple[dict, str]:
    """(f, cx, cy, baseline) from the first left/right matrices present, and their names
    (``"P0 and P1"``); ({}, "") when none are."""
    for left_key, right_key in pairs:
        if left_key in matrices and right_key in matrices:
            left, right = matrices[left_key], matrices[right_key]
            f = float(left[0, 0])
            if f <= 0:
                continue
            return {
                "f": f,
                "cx": float(left[0, 2]),
                "cy": float(left[1, 2]),
                # P[0, 3] = -f * (camera x offset), so the baseline is the difference.
                "baseline": float(left[0, 3] - right[0, 3]) / f,
            }, f"{left_key} and {right_key}"
    return {}, ""


def _check_camera(path, calib: dict, matrices: str, baseline_unit: float = 1.0) -> None:
    """Refuse a focal length or baseline the file gives as 0 or less.

    Without this, a point cloud or road report of the pair says "focal length or baseline
    unknown; add calib.txt" to a user whose calib.txt is there, with a value of 0.
    ``matrices`` names the projection matrices the baseline came from ("" when a line of
    the file gave it); ``baseline_unit`` turns the baseline back into the file's unit
    (1000 for Middlebury's millimetres), so the message quotes what the file says.
    """
    for key in ("f", "baseline"):
        value = calib.get(key)
        if value is None or value > 0:
            continue
        if key == "baseline":
            value *= baseline_unit
        if key == "baseline" and matrices:
            left, right = matrices.split(" and ")
            raise InputError(where_what_fix(
                str(path), f"the baseline from {matrices} is {value:g}, must be > 0",
                f"{left} must be the left camera's matrix and {right} the right one's"))
        raise InputError(where_what_fix(
            str(path), f"{key} {value:g} must be > 0",
            "write the camera's value there, or remove the line and set it in the camera section of the config"))


def _roi_size(numbers: list[float]) -> tuple[int, int] | None:
    """(width, height) of a Karlsruhe ``roi: x0 x1 y0 y1`` line (inclusive pixel bounds)."""
    if len(numbers) != 4:
        return None
    x0, x1, y0, y1 = numbers
    return int(round(x1 - x0)) + 1, int(round(y1 - y0)) + 1


def read_calib(path: str | os.PathLike, *, image_size: tuple[int, int] | None = None, camera: bool = True) -> dict:
    """Read a stereo calibration file.

    Understands Middlebury 2014 ``calib.txt`` (``cam0=[f 0 cx; 0 f cy; 0 0 1]``,
    ``baseline=`` in mm, ``doffs=``, ``ndisp=``, ``width=``, ``height=``), KITTI /
    Karlsruhe projection matrices (``P0:`` ... ``P3:``, ``P_rect_02:``; 3x4 row-major)
    and plain ``key: value`` / ``key=value`` lines (as written by :mod:`d3cli.data.synth`;
    there the baseline is in metres).  Unknown lines are ignored.

    Karlsruhe files also give ``roi: x0 x1 y0 y1`` and the projections ``P1_roi``/``P2_roi``
    of the images cropped to it, which is how those images are distributed: their
    principal point is used unless ``image_size`` shows uncropped images.

    Parameters
    ----------
    path : str or path-like
    image_size : (width, height), optional, keyword-only
        Size of the images the calibration is for: picks the projections (full or
        ``roi``) that match it.
    camera : bool, keyword-only
        Check the camera values (a focal length or baseline of 0 or less is an error
        naming the file).  False when only the disparity range is read (``ndisp``): a
        pair whose calib.txt has no usable camera still gets its map.

    Returns
    -------
    dict
        Whatever of ``f`` (px), ``baseline`` (m), ``cx``, ``cy`` (px), ``doffs`` (px),
        ``ndisp``, ``width``, ``height`` (px), ``height_m`` (m), ``pitch_deg``,
        ``roll_deg``, ``vmin``, ``vmax`` the file defines.

    Raises
    ------
    InputError
        The file is missing or unreadable; with ``camera``, a focal length or baseline
        of 0 or less (or a baseline from swapped projection matrices).
    """
    path = regular_file(path, "calibration file")
    text = _read_bytes(path).decode("utf-8", errors="replace")
    calib: dict = {}
    matrices: dict[str, np.ndarray] = {}
    middlebury = False
    roi = None
    for line in text.splitlines():
        line = line.strip()
        cam = _MIDDLEBURY_CAM.match(line)
        if cam:
            values = _numbers(cam.group(1))
            if len(values) == 9:
                middlebury = True
                calib.update(f=values[0], cx=values[2], cy=values[5])
            continue
        match = _KEY_VALUE.match(line)
        if not match:
            continue
        key, value = match.group(1), match.group(2)
        numbers = _numbers(value)
        if re.fullmatch(r"P\d|P_rect_\d\d|P\d_roi", key) and len(numbers) == 12:
            matrices[key] = np.array(numbers, dtype=np.float64).reshape(3, 4)
            continue
        if key == "roi":
            roi = _roi_size(numbers)
            continue
        key = _CALIB_ALIASES.get(key.lower(), key.lower())
        if key in CALIB_KEYS and len(numbers) == 1:
            kind = CALIB_KEYS[key]
            calib[key] = int(round(numbers[0])) if kind is int else float(numbers[0])
    if middlebury and "baseline" in calib:
        calib["baseline"] = calib["baseline"] / 1000.0  # Middlebury gives millimetres
    pairs = _PROJECTION_PAIRS
    if all(key in matrices for key in _ROI_PAIR) and (image_size is None or tuple(image_size) == roi):
        pairs = (_ROI_PAIR,)
    projected, names = _calib_from_projections(matrices, pairs)
    given_baseline = "baseline" in calib
    for key, value in projected.items():
        calib.setdefault(key, value)
    if camera:
        _check_camera(path, calib, "" if given_baseline else names, 1000.0 if middlebury else 1.0)
    return calib
