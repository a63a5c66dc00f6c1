"""The :class:`Pair` record every layout produces, the layout and file-name constants,
and pair and family names.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path



LAYOUTS = ("pair-folders", "pair", "middlebury2014", "kitti2012", "kitti2015", "udtiri-stereo", "stereo-road")
MANIFEST_EXTENSIONS = (".yaml", ".yml")
GT_NAMES = ("disp_gt.pfm", "disp_gt.png", "disp_gt.pgm", "disp_gt.npy", "disp_gt.tif", "disp_gt.tiff")


# disp_noc.png: KITTI-style non-occluded ground truth, used as the mask (value > 0 = non-occluded).
NOCC_NAMES = ("mask0nocc.png", "disp_gt_nocc.png", "nonocc.png", "mask_nonocc.png", "disp_noc.png")


# Family of pair folders whose name prefix is a road sequence without ground truth.
ROAD_PREFIXES = ("karlsruhe", "sid", "stereo-road", "road")


PAIR_KEYS = ("name", "left", "right", "gt", "gt_scale", "gt_invalid", "nocc", "calib", "max_disparity", "family",
             "bit_depth")


DEFAULT_KEYS = ("gt_scale", "gt_invalid", "family", "max_disparity", "bit_depth")
MANIFEST_KEYS = ("root", "layout", "pairs", "description", *DEFAULT_KEYS)


_EXPECTED = (
    "expected pair folders with left.png and right.png, a Middlebury 2014, KITTI 2012/2015, "
    "UDTIRI-Stereo or Stereo-Road root, a manifest YAML, or two image files"
)


_LAYOUT_FIX = "check the path, or list the pairs in a manifest YAML (see data_manifests/README.md)"
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class Pair:
    """One rectified stereo pair and what belongs to it.

    Attributes
    ----------
    name : str
        Unique, filesystem-safe; the output sub-folder name.
    left, right : Path
        The two views (left is the reference).
    gt : Path or None
        Left-view ground-truth disparity (any format of :func:`d3cli.data.formats.read_disparity`).
    gt_scale : float
        Disparity = stored value / gt_scale.
    gt_invalid : str
        Invalid-value convention passed to :func:`d3cli.data.formats.read_disparity`.
    nocc : Path or None
        Non-occlusion mask (nonzero = evaluate; Middlebury 2014 ``mask0nocc``: 255).
    calib : Path or None
        Calibration file for :func:`d3cli.data.formats.read_calib`.
    max_disparity : int or None
        Search range from the dataset (e.g. Middlebury ``ndisp``), None if unknown.
    family : str
        Dataset family for per-family tables, e.g. ``"middlebury2014"``, ``"kitti2012"``,
        ``"road"``.
    bit_depth : int or None
        Bits per sample actually used in the image files (e.g. 10 or 12 for camera data
        stored in 16-bit PNGs); None: detected from the pair's largest value
        (:func:`normalise_bit_depth`).  From ``bit_depth:`` in SOURCE.txt or a manifest.
    error : str or None
        Why this pair folder cannot be used (e.g. a left image without a right one).  A
        broken folder inside a dataset is listed with its error instead of stopping the
        discovery of the others; loading it raises that error, so a batch records the
        pair as failed and runs the rest.
    """

    name: str
    left: Path
    right: Path
    gt: Path | None = None
    gt_scale: float = 1.0
    gt_invalid: str = "auto"
    nocc: Path | None = None
    calib: Path | None = None
    max_disparity: int | None = None
    family: str = ""
    bit_depth: int | None = None
    error: str | None = None


def _abs(path: str | os.PathLike) -> Path:
    # abspath, not resolve(): normalise "..", keep symlinks as the user named them.
    return Path(os.path.abspath(os.fspath(path)))


def safe_name(text: str) -> str:
    """Turn ``text`` into a filesystem-safe pair name (letters, digits, ``.``, ``_``, ``-``)."""
    name = re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("._-")
    return name or "pair"


def family_from_name(name: str) -> str:
    """Dataset family from a pair name: the prefix before the first ``-``.

    ``middlebury2014-teddy-Q`` -> ``middlebury2014``; road sequences without ground
    truth (``karlsruhe2010-*``, ``sid-*``) -> ``road``; a name without ``-`` -> ``""``.
    """
    lowered = name.lower()
    if any(lowered.startswith(prefix + "-") or re.match(rf"{prefix}\d{{4}}-", lowered) for prefix in ROAD_PREFIXES):
        return "road"
    return lowered.split("-", 1)[0] if "-" in lowered else ""
