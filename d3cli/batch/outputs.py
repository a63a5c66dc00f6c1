"""The files of an output folder and how they are written, read back and removed.

Layout of an output folder ``OUT``::

    OUT/run.json                 resolved config, versions, backend, per-pair status
    OUT/<pair>/disp.pfm          float32 disparity, inf = invalid
    OUT/<pair>/disp.png          KITTI uint16 (disparity * 256, 0 = invalid)
    OUT/<pair>/disp_color.png    colour coded over [0, max disparity]
    OUT/<pair>/valid.png         255 where the method decided the disparity itself
    OUT/<pair>/error.png         error map (only with --eval and ground truth)
    OUT/<pair>/cloud.ply         point cloud (only with --pointcloud)
    OUT/<pair>/height.pfm, height_color.png, defects.json, defects.png   (only with --road-report)
    OUT/<pair>/result.json       timings, metrics, info; written LAST
    OUT/metrics.csv, summary.json, summary.md   (only with --eval)
    OUT/defects.csv              every defect of every pair (only with --road-report)

Every file is written atomically, and ``result.json`` last: its presence means the pair
is complete.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

from ..data.io import atomic_write, colorize_disparity, write_image, write_kitti_png, write_pfm
from ..errors import OutputError, where_what_fix
from ..evaluation.report import jsonable

log = logging.getLogger(__name__)

#: The per-pair files of a complete result, besides result.json.
OUTPUT_FILES = ("disp.pfm", "disp.png", "disp_color.png", "valid.png")
RESULT_FILE = "result.json"
ERROR_MAP = "error.png"
CLOUD_FILE = "cloud.ply"  # only with --pointcloud
RUN_FILE = "run.json"


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON (NaN/inf as null), atomically."""
    text = json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n"
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def read_result(pair_dir: Path) -> dict | None:
    """The stored result of a complete pair folder, or None when incomplete."""
    result_path = pair_dir / RESULT_FILE
    if not result_path.is_file() or not all((pair_dir / f).is_file() for f in OUTPUT_FILES):
        return None
    try:
        return json.loads(result_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        log.warning("%s: unreadable, computing the pair again", result_path)
        return None


def remove_pair_files(pair_dir: Path, *, remove_folder: bool = False) -> None:
    """Delete a pair's outputs, result.json, error map and leftover temporary files.

    Used before a pair is written (stale files of an earlier run, temporary files of a
    killed one) and when writing it failed or was interrupted.  Other files stay.
    """
    if not pair_dir.is_dir():
        return
    names = (*OUTPUT_FILES, RESULT_FILE, ERROR_MAP, CLOUD_FILE)
    leftovers = [p for p in pair_dir.iterdir() if p.name.startswith(".") and ".tmp-" in p.name]
    for path in [pair_dir / name for name in names] + leftovers:
        try:
            path.unlink(missing_ok=True)
        except OSError as exc:
            log.warning("%s: could not remove (%s)", path, exc)
    if remove_folder:
        try:
            pair_dir.rmdir()  # only when empty: the user's own files stay
        except OSError:
            pass


def write_disparity_outputs(folder: str | os.PathLike, disp: np.ndarray, valid: np.ndarray, *, vmax: float) -> dict:
    """Write the standard per-pair outputs, each atomically.

    Parameters
    ----------
    folder : str or path-like
        Output folder (created with its parents if needed).
    disp : ndarray, float32, (H, W)
        Disparity in pixels, inf = invalid.
    valid : ndarray, bool, (H, W)
        Pixels the method decided itself.
    vmax : float, keyword-only
        Top of the colour range of ``disp_color.png`` (usually the max disparity).

    Returns
    -------
    dict of str to Path
        ``{"disp.pfm": ..., "disp.png": ..., "disp_color.png": ..., "valid.png": ...}``.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        error = OutputError(
            where_what_fix(str(folder), f"cannot create output folder ({exc.strerror or exc})", "choose another -o folder")
        )
        error.errno = exc.errno
        raise error from None
    disp = np.asarray(disp, dtype=np.float32)
    valid = np.asarray(valid, dtype=bool)
    if valid.shape != disp.shape:
        raise ValueError(f"valid mask shape {valid.shape} differs from disparity shape {disp.shape}")
    return {
        "disp.pfm": write_pfm(folder / "disp.pfm", disp),
        "disp.png": write_kitti_png(folder / "disp.png", disp),
        "disp_color.png": write_image(folder / "disp_color.png", colorize_disparity(disp, 0.0, max(float(vmax), 1e-6))),
        "valid.png": write_image(folder / "valid.png", valid.astype(np.uint8) * 255),
    }

# Road inspection outputs (only with --road-report): height.pfm, height_color.png,
# defects.json, defects.png per pair and OUT/defects.csv; named where they are written.
from ..road.report import (  # noqa: E402,F401
    DEFECTS_CSV, DEFECTS_JSON, DEFECTS_PNG, HEIGHT_COLOR_FILE, HEIGHT_FILE)
