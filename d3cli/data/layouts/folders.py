"""Pair folders (the ``pair-folders`` and ``pair`` layouts): one folder per pair with
``left``/``right`` images, optional ground truth, ``calib.txt`` and ``SOURCE.txt``.
"""

from __future__ import annotations

import logging
import math
import os
import re
from pathlib import Path
from typing import Any

from ...errors import InputError, where_what_fix
from .. import formats
from .files import _files_by_lower_name, _find_view, _first, _subfolders
from .pair import GT_NAMES, NOCC_NAMES, Pair, _EXPECTED, _LAYOUT_FIX, _abs, family_from_name, safe_name

log = logging.getLogger(__name__)


def _source_lines(path: Path) -> dict[str, str]:
    """``key: value`` lines of a SOURCE.txt (first occurrence of each key wins).

    Keys start in column 0: indented lines continue the previous free-text value.
    """
    values: dict[str, str] = {}
    text = formats.regular_file(path, "SOURCE.txt").read_bytes().decode("utf-8", errors="replace")
    for line in text.splitlines():
        match = re.match(r"^([A-Za-z_]\w*)\s*:\s*(.*?)\s*$", line)
        if match:
            values.setdefault(match.group(1).lower(), match.group(2))
    return values


def _first_word(text: str) -> str:
    return text.split()[0] if text.split() else ""


def _source_number(source: dict[str, str], key: str, path: Path, kind=float):
    word = _first_word(source.get(key, ""))
    if word in ("", "-", "none", "n/a"):
        return None
    try:
        value = kind(word)
    except ValueError:
        raise InputError(
            where_what_fix(str(path), f"{key}: {word!r} is not a number", f"write e.g. '{key}: 256' or '{key}: -'")
        ) from None
    if not (value > 0 and math.isfinite(value)):  # inf would reach the reader, named as the ground truth's fault
        raise InputError(where_what_fix(str(path), f"{key} must be a finite number > 0, got {word}", "fix the value"))
    return value


def _canonical_invalid(value: Any, where: str) -> str:
    text = str(value).strip().lower()
    word = _first_word(text) if text else "auto"
    aliases = {"0": "zero", "zeros": "zero", "-": "auto", "infinity": "inf", "nan": "inf"}
    word = aliases.get(word, word)
    if word not in formats.INVALID_CONVENTIONS:
        raise InputError(
            where_what_fix(where, f"gt_invalid {value!r} is not understood", "use 0, inf, auto or none")
        )
    return word


def _image_size(source: dict[str, str]) -> tuple[int, int] | None:
    match = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)", source.get("image_size", ""))
    return (int(match.group(1)), int(match.group(2))) if match else None


def _max_disparity_from_calib(calib: dict, image_width: int | None) -> int | None:
    ndisp = calib.get("ndisp")
    if not ndisp or ndisp <= 0:
        return None
    calib_width = calib.get("width")
    if image_width and calib_width and image_width != calib_width:
        # Images were downsized after calibration: the disparity range shrinks with them.
        return max(1, math.ceil(ndisp * image_width / calib_width))
    return int(ndisp)


def read_pair_folder(folder: str | os.PathLike) -> Pair:
    """Read one pair folder (``left.*``, ``right.*`` and optional extras, see module doc).

    Raises
    ------
    InputError
        No left image, or a left image without a right one.
    """
    folder = _abs(folder)
    files = _files_by_lower_name(folder)
    left = _find_view(files, "left")
    right = _find_view(files, "right")
    if left is None:
        raise InputError(where_what_fix(str(folder), f"no left image ({_EXPECTED})", _LAYOUT_FIX))
    if right is None:
        raise InputError(
            where_what_fix(
                str(folder),
                f"found {left.name} but no right image",
                "add the right view as right.png (same size as the left) or remove the folder",
            )
        )
    source_path = files.get("source.txt")
    source = _source_lines(source_path) if source_path else {}
    gt = _first(files, GT_NAMES)
    calib = files.get("calib.txt")
    max_disparity = _source_number(source, "max_disparity", source_path, int) if source_path else None
    if max_disparity is None and calib is not None:
        size = _image_size(source)
        max_disparity = _max_disparity_from_calib(formats.read_calib(calib, camera=False), size[0] if size else None)
    name = safe_name(folder.name)
    family = _first_word(source.get("family", "")) or family_from_name(name)
    gt_scale = _source_number(source, "gt_scale", source_path) if source_path else None
    bit_depth = _source_number(source, "bit_depth", source_path, int) if source_path else None
    if bit_depth is not None and not 1 <= bit_depth <= 16:
        raise InputError(where_what_fix(str(source_path), f"bit_depth must be in [1, 16], got {bit_depth}",
                                        "write the bits per sample of the images, e.g. bit_depth: 12"))
    return Pair(
        name=name,
        left=left,
        right=right,
        gt=gt,
        gt_scale=float(gt_scale) if gt_scale else 1.0,
        gt_invalid=_canonical_invalid(source.get("gt_invalid", "auto"), str(source_path or folder)),
        nocc=_first(files, NOCC_NAMES),
        calib=calib,
        max_disparity=max_disparity,
        family=family,
        bit_depth=bit_depth,
    )


def _pair_folders(root: Path) -> list[Pair]:
    pairs = []
    for sub in _subfolders(root):
        files = _files_by_lower_name(sub)
        try:
            if _find_view(files, "left") is not None:
                pairs.append(read_pair_folder(sub))
            elif _find_view(files, "right") is not None:
                raise InputError(
                    where_what_fix(str(sub), "found a right image but no left image", "add left.png or remove the folder")
                )
            else:
                log.debug("skipping %s: no left/right images", sub)
        except InputError as exc:
            # one broken folder must not stop the batch: list it with its error
            log.warning("%s", exc)
            pairs.append(_broken_pair(sub, str(exc)))
    return pairs


def _broken_pair(folder: Path, error: str) -> Pair:
    name = safe_name(folder.name)
    return Pair(name=name, left=folder, right=folder, family=family_from_name(name), error=error)
