"""The road layouts: UDTIRI-Stereo (``left/``, ``right/``, ``disparity_noc/``) and
Stereo-Road (``left/``/``right/`` or ``image_L/``/``image_R/``, no ground truth).
"""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError, where_what_fix
from .. import formats
from .files import _files_by_lower_name, _find_view, _is_image, _present, _subfolder_map, _subfolders
from .folders import _max_disparity_from_calib
from .pair import Pair, safe_name


_ROAD_VIEW_FOLDERS = (("left", "right"), ("image_l", "image_r"))


def _road_view_folders(folder: Path) -> tuple[Path, Path] | None:
    subs = _subfolder_map(folder)
    for left, right in _ROAD_VIEW_FOLDERS:
        if left in subs and right in subs:
            return subs[left], subs[right]
    return None


def _road_splits(root: Path) -> list[tuple[Path, str]]:
    """(folder, split name) for the root and each sub-folder holding left/right views."""
    splits = [(root, "")] if _road_view_folders(root) else []
    for sub in _subfolders(root):
        if _road_view_folders(sub):
            splits.append((sub, safe_name(sub.name)))
    return splits


def _matched_views(left_dir: Path, right_dir: Path) -> list[tuple[Path, Path]]:
    right_files = _files_by_lower_name(right_dir)
    matched = []
    for left in sorted(path for path in _files_by_lower_name(left_dir).values() if _is_image(path)):
        right = _find_view(right_files, left.stem.lower())
        if right is None:
            raise InputError(
                where_what_fix(
                    str(right_dir),
                    f"no right image for {left}",
                    "every left image needs a right image with the same name (stem)",
                )
            )
        matched.append((left, right))
    return matched


def _udtiri_pairs(root: Path) -> list[Pair]:
    pairs = []
    for split, split_name in _road_splits(root):
        left_dir, right_dir = _road_view_folders(split)
        gt_dir = _subfolder_map(split).get("disparity_noc")
        for left, right in _matched_views(left_dir, right_dir):
            gt = None
            if gt_dir is not None:
                gt = next((gt_dir / f"{left.stem}{ext}" for ext in (".npy", ".pfm") if _present(gt_dir / f"{left.stem}{ext}")), None)
            parts = ["udtiri", split_name, left.stem]
            pairs.append(
                Pair(
                    name=safe_name("-".join(part for part in parts if part)),
                    left=left,
                    right=right,
                    gt=gt,
                    gt_scale=1.0,
                    gt_invalid="auto",
                    family="udtiri",
                )
            )
    return pairs


def _stereo_road_pairs(root: Path) -> list[Pair]:
    pairs = []
    root_calib = root / "calib.txt"
    for split, split_name in _road_splits(root):
        left_dir, right_dir = _road_view_folders(split)
        split_calib = split / "calib.txt"
        shared_calib = split_calib if _present(split_calib) else (root_calib if _present(root_calib) else None)
        for left, right in _matched_views(left_dir, right_dir):
            own_calib = split / "calib" / f"{left.stem}.txt"
            calib = own_calib if _present(own_calib) else shared_calib
            max_disparity = _max_disparity_from_calib(formats.read_calib(calib, camera=False), None) if calib else None
            parts = ["stereo-road", split_name, left.stem]
            pairs.append(
                Pair(
                    name=safe_name("-".join(part for part in parts if part)),
                    left=left,
                    right=right,
                    calib=calib,
                    max_disparity=max_disparity,
                    family="road",
                )
            )
    return pairs
