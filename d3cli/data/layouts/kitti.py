"""The KITTI 2012 and 2015 layouts: training/testing splits, ``*_10.png`` frames."""

from __future__ import annotations

from pathlib import Path

from ...errors import InputError, where_what_fix
from .files import _files_by_lower_name, _present, _subfolder_map
from .pair import Pair, safe_name


def _kitti_splits(root: Path) -> list[tuple[Path, str]]:
    subs = _subfolder_map(root)
    splits = [(subs[name], name) for name in ("training", "testing") if name in subs]
    if splits:
        return splits
    return [(root, "testing" if root.name.lower() == "testing" else "training")]


def _kitti_views(split: Path, year: int) -> tuple[Path, Path] | None:
    subs = _subfolder_map(split)
    candidates = [("image_2", "image_3")] if year == 2015 else [("colored_0", "colored_1"), ("image_0", "image_1")]
    for left, right in candidates:
        if left in subs and right in subs:
            return subs[left], subs[right]
    return None


def _kitti_pairs(root: Path, year: int) -> list[Pair]:
    gt_dir, noc_dir, calib_dir = (
        ("disp_occ_0", "disp_noc_0", "calib_cam_to_cam") if year == 2015 else ("disp_occ", "disp_noc", "calib")
    )
    pairs = []
    for split, split_name in _kitti_splits(root):
        views = _kitti_views(split, year)
        if views is None:
            continue
        left_dir, right_dir = views
        right_files = _files_by_lower_name(right_dir)
        for left in sorted(left_dir.glob("*_10.png")):
            right = right_files.get(left.name.lower())
            if right is None:
                raise InputError(
                    where_what_fix(
                        str(right_dir),
                        f"no right image {left.name} for {left}",
                        "every left frame needs its right frame; re-unpack the KITTI archive",
                    )
                )
            frame = left.name.split("_")[0]
            gt = split / gt_dir / left.name
            nocc = split / noc_dir / left.name
            calib = split / calib_dir / f"{frame}.txt"
            prefix = f"kitti{year}-" + ("testing-" if split_name == "testing" else "")
            pairs.append(
                Pair(
                    name=safe_name(prefix + left.stem),
                    left=left,
                    right=right,
                    gt=gt if _present(gt) else None,
                    gt_scale=256.0,
                    gt_invalid="zero",
                    nocc=nocc if _present(nocc) else None,
                    calib=calib if _present(calib) else None,
                    max_disparity=None,
                    family=f"kitti{year}",
                )
            )
    return pairs
