"""The Middlebury 2014 (MiddEval3) layout: resolution folders of scene folders."""

from __future__ import annotations

import re
from pathlib import Path

from ...errors import InputError, where_what_fix
from .. import formats
from .files import _files_by_lower_name, _subfolders
from .folders import _max_disparity_from_calib
from .pair import Pair, safe_name


_MIDDLEBURY_RES = re.compile(r"^(training|test)([QHF])$", re.IGNORECASE)


def _middlebury_scene(scene: Path, resolution: str | None) -> Pair:
    files = _files_by_lower_name(scene)
    right = files.get("im1.png")
    if right is None:
        raise InputError(
            where_what_fix(str(scene), "found im0.png but no right image im1.png", "unpack the complete MiddEval3 scene")
        )
    calib = files.get("calib.txt")
    max_disparity = None
    if calib is not None:
        max_disparity = _max_disparity_from_calib(formats.read_calib(calib, camera=False), None)
    name = f"middlebury2014-{scene.name.lower()}" + (f"-{resolution.upper()}" if resolution else "")
    return Pair(
        name=safe_name(name),
        left=files["im0.png"],
        right=right,
        gt=files.get("disp0gt.pfm"),
        gt_scale=1.0,
        gt_invalid="inf",
        nocc=files.get("mask0nocc.png"),
        calib=calib,
        max_disparity=max_disparity,
        family="middlebury2014",
    )


def _middlebury_pairs(root: Path) -> list[Pair]:
    def resolution_of(folder: Path) -> str | None:
        match = _MIDDLEBURY_RES.match(folder.name)
        return match.group(2) if match else None

    if (root / "im0.png").is_file():
        return [_middlebury_scene(root, resolution_of(root.parent))]
    subs = _subfolders(root)
    resolution_dirs = [sub for sub in subs if resolution_of(sub)]
    scene_parents = resolution_dirs or [root]
    pairs = []
    for parent in scene_parents:
        for scene in _subfolders(parent):
            if (scene / "im0.png").is_file():
                pairs.append(_middlebury_scene(scene, resolution_of(parent)))
    return pairs
