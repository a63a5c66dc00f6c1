"""Layout detection of a folder and its expansion into pairs."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from ...errors import InputError, where_what_fix
from .files import _files_by_lower_name, _find_view, _is_image, _subfolder_map, _subfolders
from .folders import _pair_folders, read_pair_folder
from .kitti import _kitti_pairs, _kitti_splits, _kitti_views
from .middlebury import _MIDDLEBURY_RES, _middlebury_pairs
from .pair import LAYOUTS, Pair, _EXPECTED, _LAYOUT_FIX, _abs
from .road import _road_splits, _stereo_road_pairs, _udtiri_pairs

log = logging.getLogger(__name__)


def detect_layout(folder: str | os.PathLike) -> str | None:
    """Name the layout of ``folder`` (one of :data:`LAYOUTS`), or None when unknown.

    Parameters
    ----------
    folder : str or os.PathLike
        The dataset folder (or a pair folder).
    """
    folder = _abs(folder)
    files = _files_by_lower_name(folder)
    if _find_view(files, "left") is not None or _find_view(files, "right") is not None:
        return "pair"
    if "im0.png" in files:
        return "middlebury2014"
    subs = _subfolders(folder)
    if any(_MIDDLEBURY_RES.match(sub.name) for sub in subs):
        return "middlebury2014"
    splits = [split for split, _ in _kitti_splits(folder)]
    if any(_kitti_views(split, 2015) for split in splits):
        return "kitti2015"
    if any(_kitti_views(split, 2012) for split in splits):
        return "kitti2012"
    road_splits = [split for split, _ in _road_splits(folder)]
    if any("disparity_noc" in _subfolder_map(split) for split in road_splits):
        return "udtiri-stereo"
    if road_splits:
        return "stereo-road"
    for sub in subs:
        sub_files = _files_by_lower_name(sub)
        if _find_view(sub_files, "left") is not None or _find_view(sub_files, "right") is not None:
            return "pair-folders"
    if any((sub / "im0.png").is_file() for sub in subs):
        return "middlebury2014"
    return None


_EXPANDERS = {
    "pair-folders": _pair_folders,
    "pair": lambda folder: [read_pair_folder(folder)],
    "middlebury2014": _middlebury_pairs,
    "kitti2012": lambda folder: _kitti_pairs(folder, 2012),
    "kitti2015": lambda folder: _kitti_pairs(folder, 2015),
    "udtiri-stereo": _udtiri_pairs,
    "stereo-road": _stereo_road_pairs,
}


def _count_images(folder: Path) -> int:
    count = sum(1 for path in _files_by_lower_name(folder).values() if _is_image(path))
    for sub in _subfolders(folder):
        count += sum(1 for path in _files_by_lower_name(sub).values() if _is_image(path))
    return count


def _no_pairs_error(folder: Path) -> InputError:
    return InputError(where_what_fix(str(folder), f"no stereo pairs found ({_EXPECTED})", _LAYOUT_FIX))


def expand_layout(folder: str | os.PathLike, layout: str = "auto") -> list[Pair]:
    """List the pairs of ``folder`` in the given (or detected) layout.

    Raises
    ------
    InputError
        Unknown layout, no pairs, or an incomplete pair.
    """
    folder = _abs(folder)
    auto = layout == "auto"
    if auto:
        detected = detect_layout(folder)
        if detected is None:
            n_images = _count_images(folder)
            if n_images == 0:
                raise _no_pairs_error(folder)
            raise InputError(
                where_what_fix(
                    str(folder),
                    f"unknown dataset layout (found {n_images} image files but no left/right views; {_EXPECTED})",
                    "name the views left.png and right.png, pass the two image files, "
                    "or list the pairs in a manifest YAML (see data_manifests/README.md)",
                )
            )
        layout = detected
    if layout not in _EXPANDERS:
        raise InputError(
            where_what_fix(str(folder), f"unknown layout {layout!r}", f"use one of auto, {', '.join(LAYOUTS)}")
        )
    pairs = _EXPANDERS[layout](folder)
    if auto and layout not in ("pair", "pair-folders"):
        pairs += _pair_folders_beside(folder, layout)
    if not pairs:
        raise _no_pairs_error(folder)
    return pairs


def _pair_folders_beside(folder: Path, layout: str) -> list[Pair]:
    """Pair folders (``p/left.png``...) next to a dataset of another layout: run too, with
    a warning, rather than dropped without a word (a Stereo-Road ``left/`` + ``right/``
    pair hid them)."""
    pairs = _pair_folders(folder)
    if pairs:
        log.warning("%s: holds a %s dataset and pair folders (%s); running both", folder, layout,
                    ", ".join(pair.name for pair in pairs))
    return pairs
