"""Dataset layouts -> a sorted list of :class:`Pair` records.

:func:`discover` takes folders, manifest YAMLs or two image files and auto-detects each
layout.  No image is read while discovering (only small text files: ``SOURCE.txt``,
``calib.txt``, manifests), so a large dataset is listed in milliseconds; images and
ground truth are read later by :func:`load_pair_images` and :func:`load_ground_truth`.

Layouts (``layout:`` name in a manifest, then what is expected on disk):

``pair-folders``
    A folder of pair folders, the layout of ``shared/data``.  Each pair folder holds
    ``left.<ext>`` and ``right.<ext>`` (png, jpg, ppm, pgm, tif, bmp), optionally
    ``disp_gt.<pfm|png|pgm|npy>``, a non-occlusion mask (``mask0nocc.png``,
    ``disp_gt_nocc.png``, ``nonocc.png``, ``mask_nonocc.png`` or KITTI's ``disp_noc.png``), ``calib.txt`` and a
    ``SOURCE.txt`` whose machine-readable lines ``gt_scale: 256``, ``gt_invalid: 0``
    (``0``, ``inf``, ``auto`` or ``none``; the first word counts), optionally
    ``max_disparity: N``, ``family: NAME`` and ``image_size: WxH`` are used.
    The pair name is the folder name; the family is the name's prefix before the first
    ``-`` (``middlebury2014-teddy-Q`` -> ``middlebury2014``), with the road sequences
    ``karlsruhe2010-*`` and ``sid-*`` mapped to ``road``.  The max disparity is
    ``ndisp`` of ``calib.txt`` when present, rescaled by ``image width / calib width``
    when ``SOURCE.txt`` gives an ``image_size`` that differs from the calib's ``width``
    (images downsized after calibration); otherwise None.
``pair``
    One such pair folder given directly.
``middlebury2014``
    MiddEval3: a root holding ``trainingQ``/``trainingH``/``trainingF`` (and/or
    ``testQ``/...), one of those folders, or one scene folder.  A scene folder holds
    ``im0.png``, ``im1.png``, ``calib.txt`` (``ndisp`` -> max disparity) and, once the
    ``MiddEval3-GT0-*.zip`` archives are unpacked over it, ``disp0GT.pfm`` and
    ``mask0nocc.png`` (255 = non-occluded; 128 = occluded is *not* evaluated).
    Names: ``middlebury2014-<scene lower case>-<Q|H|F>``.
``kitti2012``
    ``<root>/training`` and/or ``<root>/testing`` (or a split folder itself) with
    ``colored_0``/``colored_1`` (preferred when present) or ``image_0``/``image_1``,
    ``disp_occ`` (ground truth, all pixels), ``disp_noc`` (used as the non-occlusion
    mask) and ``calib/<frame>.txt``; only the ``*_10.png`` frames are stereo pairs.
    Names: ``kitti2012-000000_10`` (``kitti2012-testing-...`` for the test split).
``kitti2015``
    The same with ``image_2``/``image_3``, ``disp_occ_0``, ``disp_noc_0`` and
    ``calib_cam_to_cam/<frame>.txt``.  Names ``kitti2015-000000_10``.
``udtiri-stereo``
    Assumed layout (UDTIRI-Stereo as released by its authors): a root, or split
    sub-folders of it (``train``/``val``/``test``...), each with ``left/``, ``right/``
    and ``disparity_noc/`` folders of files with matching stems; left/right are images,
    ground truth is ``<stem>.npy`` (float32 disparity in pixels; non-finite or <= 0 =
    invalid; a ``<stem>.pfm`` is accepted too).  Names
    ``udtiri-[<split>-]<stem>``, family ``udtiri``.
``stereo-road``
    Assumed layout (Stereo-Road, Fan et al. 2018, University of Bristol): a root, or
    split sub-folders of it, with ``left/`` and ``right/`` (or ``image_L/`` and
    ``image_R/``) folders of PNGs with matching names and no ground truth; an optional
    ``calib.txt`` beside them (or in the root) applies to every pair, and
    ``calib/<stem>.txt`` to one pair.  Names ``stereo-road-[<split>-]<stem>``, family
    ``road``.
manifest YAML
    See ``data_manifests/README.md``: ``root:`` (relative to the manifest), an optional
    ``layout:`` expanded at the root, a ``pairs:`` list of {name, left, right, gt,
    gt_scale, gt_invalid, nocc, calib, max_disparity, family}, and optional top-level
    defaults (``gt_scale``, ``gt_invalid``, ``family``, ``max_disparity``).
two image files
    ``left right``: one pair named after the left file (or its folder when the file is
    called ``left``/``im0``), without ground truth.
"""

from __future__ import annotations

import dataclasses
import errno
import logging
import math
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ..config import MAX_CONFIG_INT, parse_yaml, quote, read_bounded
from ..errors import InputError, where_what_fix
from . import io

log = logging.getLogger(__name__)

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
_MIDDLEBURY_RES = re.compile(r"^(training|test)([QHF])$", re.IGNORECASE)
_GENERIC_LEFT_STEMS = {"left", "im0", "iml", "view1", "image_l", "l", "im2"}


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
        Left-view ground-truth disparity (any format of :func:`d3cli.data.io.read_disparity`).
    gt_scale : float
        Disparity = stored value / gt_scale.
    gt_invalid : str
        Invalid-value convention passed to :func:`d3cli.data.io.read_disparity`.
    nocc : Path or None
        Non-occlusion mask (nonzero = evaluate; Middlebury 2014 ``mask0nocc``: 255).
    calib : Path or None
        Calibration file for :func:`d3cli.data.io.read_calib`.
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


# --------------------------------------------------------------------------- small helpers


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


def _missing_why(path: Path) -> tuple[str, str]:
    """(what, fix) for an input that does not exist: a symlink loop and a broken link are
    named as such (issue 12 item 15), anything else is a wrong path."""
    if path.is_symlink():
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "a symlink loop (the link leads back to itself)", "point it at the data or remove it"
        return f"a broken symlink (to {os.readlink(path)}, which does not exist)", "fix the link or the path"
    return "no such file or folder", "check the path"


def _entries(folder: Path, keep) -> list[Path]:
    """Entries of ``folder`` for which ``keep(entry)`` holds, skipping broken ones.

    An entry that cannot be examined (a symlink loop, a dangling or forbidden link) is
    skipped with a warning naming that entry: one bad link must not hide the rest of a
    dataset (nor be blamed on the root folder).
    """
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        raise InputError(where_what_fix(str(folder), f"cannot list folder ({exc.strerror})", "check permissions")) from None
    kept = []
    for entry in entries:
        try:
            if keep(entry):
                kept.append(Path(entry.path))
        except OSError as exc:
            log.warning("%s: skipped (%s); fix or remove the link", entry.path, exc.strerror or exc)
    return kept


def _files_by_lower_name(folder: Path) -> dict[str, Path]:
    return {path.name.lower(): path for path in _entries(folder, lambda entry: entry.is_file())}


def _subfolders(folder: Path) -> list[Path]:
    return sorted(_entries(folder, lambda entry: not entry.name.startswith(".") and _is_folder(entry)))


def _is_folder(entry: os.DirEntry) -> bool:
    if entry.is_symlink():
        os.stat(entry.path)  # raises ELOOP for a symlink loop (is_dir() would say False)
    return entry.is_dir()


def _find_view(files: dict[str, Path], stem: str) -> Path | None:
    """The image file named ``stem.<image extension>`` among ``files`` (lower-case keys)."""
    for ext in io.IMAGE_EXTENSIONS:
        if f"{stem}{ext}" in files:
            return files[f"{stem}{ext}"]
    return None


def _first(files: dict[str, Path], names: Iterable[str]) -> Path | None:
    for name in names:
        if name in files:
            return files[name]
    return None


def _is_image(path: Path) -> bool:
    return path.suffix.lower() in io.IMAGE_EXTENSIONS


def _subfolder_map(folder: Path) -> dict[str, Path]:
    return {sub.name.lower(): sub for sub in _subfolders(folder)}


# --------------------------------------------------------------------------- SOURCE.txt


def _source_lines(path: Path) -> dict[str, str]:
    """``key: value`` lines of a SOURCE.txt (first occurrence of each key wins).

    Keys start in column 0: indented lines continue the previous free-text value.
    """
    values: dict[str, str] = {}
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
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
    if not value > 0:
        raise InputError(where_what_fix(str(path), f"{key} must be > 0, got {word}", "fix the value"))
    return value


def _canonical_invalid(value: Any, where: str) -> str:
    text = str(value).strip().lower()
    word = _first_word(text) if text else "auto"
    aliases = {"0": "zero", "zeros": "zero", "-": "auto", "infinity": "inf", "nan": "inf"}
    word = aliases.get(word, word)
    if word not in io.INVALID_CONVENTIONS:
        raise InputError(
            where_what_fix(where, f"gt_invalid {value!r} is not understood", "use 0, inf, auto or none")
        )
    return word


def _image_size(source: dict[str, str]) -> tuple[int, int] | None:
    match = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)", source.get("image_size", ""))
    return (int(match.group(1)), int(match.group(2))) if match else None


# --------------------------------------------------------------------------- pair folders


def _has_view(folder: Path, stem: str) -> bool:
    return _find_view(_files_by_lower_name(folder), stem) is not None


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
        max_disparity = _max_disparity_from_calib(io.read_calib(calib), size[0] if size else None)
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


# --------------------------------------------------------------------------- Middlebury 2014


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
        max_disparity = _max_disparity_from_calib(io.read_calib(calib), None)
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


# --------------------------------------------------------------------------- KITTI


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
                    gt=gt if gt.is_file() else None,
                    gt_scale=256.0,
                    gt_invalid="zero",
                    nocc=nocc if nocc.is_file() else None,
                    calib=calib if calib.is_file() else None,
                    max_disparity=None,
                    family=f"kitti{year}",
                )
            )
    return pairs


# --------------------------------------------------------------------------- UDTIRI-Stereo, Stereo-Road

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
    for left in sorted(path for path in left_dir.iterdir() if path.is_file() and _is_image(path)):
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
                gt = next((gt_dir / f"{left.stem}{ext}" for ext in (".npy", ".pfm") if (gt_dir / f"{left.stem}{ext}").is_file()), None)
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
        shared_calib = split_calib if split_calib.is_file() else (root_calib if root_calib.is_file() else None)
        for left, right in _matched_views(left_dir, right_dir):
            own_calib = split / "calib" / f"{left.stem}.txt"
            calib = own_calib if own_calib.is_file() else shared_calib
            max_disparity = _max_disparity_from_calib(io.read_calib(calib), None) if calib else None
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


# --------------------------------------------------------------------------- layout detection


def detect_layout(folder: str | os.PathLike) -> str | None:
    """Name the layout of ``folder`` (one of :data:`LAYOUTS`), or None when unknown."""
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
    if layout == "auto":
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
    if not pairs:
        raise _no_pairs_error(folder)
    return pairs


# --------------------------------------------------------------------------- manifests


def _read_manifest_yaml(path: Path) -> Any:
    """The parsed manifest: a bounded regular file, safe YAML (no alias bombs, no
    duplicate keys), every problem an InputError naming the file and the line."""
    raw = read_bounded(str(path), what="manifest file", missing_fix="check the path", error=InputError)
    return parse_yaml(raw, str(path), what="manifest file", error=InputError)[0]


def _check_value(key: str, value: Any, where: str) -> Any:
    """Validate and normalise one manifest value (pair entry or top-level default)."""
    if key in ("name", "left", "right", "gt", "nocc", "calib", "family"):
        if value is None and key in ("gt", "nocc", "calib"):
            return None
        if not isinstance(value, str) or (key != "family" and not value.strip()):
            raise InputError(where_what_fix(where, f"{key} must be a string, got {value!r}", f"write {key}: <text>"))
        if key == "name" and not _SAFE_NAME.match(value):
            raise InputError(
                where_what_fix(
                    where, f"name {value!r} is not filesystem-safe", "use letters, digits, '.', '_' and '-' only"
                )
            )
        return value
    if key == "gt_scale":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise InputError(where_what_fix(where, f"gt_scale must be a number > 0, got {value!r}", "e.g. gt_scale: 256"))
        return float(value)
    if key == "gt_invalid":
        return _canonical_invalid(value, where)
    if key == "bit_depth":
        if value is None:
            return None
        number = _whole_number(value)
        if number is None or not 1 <= number <= 16:
            raise InputError(
                where_what_fix(where, f"bit_depth must be an integer in [1, 16], got {quote(value)}", "e.g. bit_depth: 12")
            )
        return number
    if key == "max_disparity":
        if value is None:
            return None
        number = _whole_number(value)
        if number is None or not 1 <= number <= MAX_CONFIG_INT:
            raise InputError(where_what_fix(
                where, f"max_disparity must be a positive integer of at most {MAX_CONFIG_INT}, got {quote(value)}",
                "e.g. max_disparity: 64"))
        return number
    raise KeyError(key)  # pragma: no cover - callers check the key first


def _whole_number(value) -> int | None:
    """``value`` as an int when it is a whole number (``64``, ``64.0``, ``1e2`` as YAML 1.2
    reads it), else None; as the config reads integer keys (issue 12 item 14)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return int(value)
    return None


def _manifest_path(root: Path, value: str, key: str, where: str) -> Path:
    path = _abs(root / os.path.expanduser(value))
    if not path.is_file():
        raise InputError(
            where_what_fix(where, f"{key} file not found: {path}", f"fix the path (relative to root {root})")
        )
    return path


def _manifest_pair(entry: Any, index: int, root: Path, defaults: dict, manifest: Path) -> Pair:
    where = f"{manifest} pairs[{index}]"
    if not isinstance(entry, dict):
        raise InputError(where_what_fix(where, f"expected a mapping, got {type(entry).__name__}", "write - name: ..."))
    if isinstance(entry.get("name"), str):
        where += f" ({entry['name']})"
    unknown = sorted(set(map(str, entry)) - set(PAIR_KEYS))
    if unknown:
        raise InputError(
            where_what_fix(where, f"unknown key {unknown[0]!r}", f"valid keys are {', '.join(PAIR_KEYS)}")
        )
    for key in ("name", "left", "right"):
        if key not in entry:
            raise InputError(where_what_fix(where, f"missing key {key!r}", "every pair needs name, left and right"))
    values = {**defaults, **{key: _check_value(key, value, where) for key, value in entry.items()}}
    fields = {key: values[key] for key in ("name", "gt_scale", "gt_invalid", "max_disparity", "family", "bit_depth")
              if key in values}
    for key in ("left", "right", "gt", "nocc", "calib"):
        if values.get(key) is not None:
            fields[key] = _manifest_path(root, values[key], key, where)
    if "family" not in fields:
        fields["family"] = family_from_name(fields["name"])
    return Pair(**fields)


def load_manifest(path: str | os.PathLike) -> list[Pair]:
    """Read a manifest YAML (format in ``data_manifests/README.md``) into pairs.

    Raises
    ------
    InputError
        Missing file, invalid YAML, unknown or missing keys, files that do not exist,
        duplicate names; messages name the manifest and the pair index.
    """
    path = _abs(path)
    doc = _read_manifest_yaml(path)
    if not isinstance(doc, dict):
        raise InputError(
            where_what_fix(str(path), "a manifest must be a mapping with root: and pairs: (or layout:)", "see data_manifests/README.md")
        )
    unknown = sorted(set(map(str, doc)) - set(MANIFEST_KEYS))
    if unknown:
        raise InputError(
            where_what_fix(str(path), f"unknown key {unknown[0]!r}", f"valid top-level keys are {', '.join(MANIFEST_KEYS)}")
        )
    if "pairs" not in doc and "layout" not in doc:
        raise InputError(where_what_fix(str(path), "missing key 'pairs' (and no 'layout')", "list the pairs or name a layout"))
    root_value = doc.get("root", ".")
    if not isinstance(root_value, str):
        raise InputError(where_what_fix(str(path), f"root must be a path string, got {root_value!r}", "write root: <folder>"))
    root = _abs(path.parent / os.path.expanduser(root_value))
    if not root.is_dir():
        raise InputError(
            where_what_fix(
                str(path), f"root folder not found: {root}", "root: is relative to the manifest file; download the data there or fix root:"
            )
        )
    defaults = {key: _check_value(key, doc[key], str(path)) for key in DEFAULT_KEYS if key in doc}
    pairs: list[Pair] = []
    if doc.get("layout") is not None:
        layout = doc["layout"]
        if layout != "auto" and layout not in LAYOUTS:
            raise InputError(
                where_what_fix(str(path), f"unknown layout {layout!r}", f"use one of auto, {', '.join(LAYOUTS)}")
            )
        pairs += [dataclasses.replace(pair, **defaults) for pair in expand_layout(root, layout)]
    entries = doc.get("pairs") or []
    if not isinstance(entries, list):
        raise InputError(where_what_fix(str(path), "pairs must be a list", "write pairs: then '- name: ...' entries"))
    pairs += [_manifest_pair(entry, index, root, defaults, path) for index, entry in enumerate(entries)]
    if not pairs:
        raise InputError(where_what_fix(str(path), "the manifest lists no pairs", "add entries under pairs:"))
    return pairs


# --------------------------------------------------------------------------- discover


def _pair_from_two_files(left: Path, right: Path) -> Pair:
    stem = left.stem.lower()
    base = left.parent.name if stem in _GENERIC_LEFT_STEMS and left.parent.name else left.stem
    name = safe_name(base)
    return Pair(name=name, left=left, right=right, family=family_from_name(name))


def _unique(pairs: list[Pair]) -> list[Pair]:
    by_name: dict[str, Pair] = {}
    for pair in pairs:
        seen = by_name.get(pair.name)
        if seen is not None and seen != pair:
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"two different pairs share this name ({seen.left} and {pair.left})",
                    "give the inputs in separate runs or name the pairs in a manifest",
                )
            )
        by_name[pair.name] = pair
    return sorted(by_name.values(), key=lambda pair: pair.name)


def discover(inputs: Sequence[str | os.PathLike] | str | os.PathLike) -> list[Pair]:
    """Find the stereo pairs of every input, auto-detecting each layout.

    Parameters
    ----------
    inputs : sequence of str or path-like (a single path is accepted too)
        Folders (any layout of the module docstring), manifest YAMLs, or exactly two
        image files (left, right).

    Returns
    -------
    list of Pair
        Sorted by name; the same pair reached twice is listed once.

    Raises
    ------
    InputError
        Missing paths, an unknown layout, a folder without pairs, an incomplete pair, a
        bad manifest, or a number of image files other than two.
    """
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    inputs = [_abs(item) for item in inputs]
    if not inputs:
        raise InputError(where_what_fix("discover", "no inputs given", f"give {_EXPECTED}"))
    pairs: list[Pair] = []
    images: list[Path] = []
    for item in inputs:
        if item.is_dir():
            pairs += expand_layout(item)
        elif item.is_file() and item.suffix.lower() in MANIFEST_EXTENSIONS:
            pairs += load_manifest(item)
        elif item.is_file() and _is_image(item):
            images.append(item)
        elif item.exists():
            raise InputError(
                where_what_fix(str(item), f"not a folder, manifest or image ({item.suffix or 'no extension'})", f"give {_EXPECTED}")
            )
        else:
            raise InputError(where_what_fix(str(item), *_missing_why(item)))
    if images:
        if len(images) != 2:
            raise InputError(
                where_what_fix(
                    ", ".join(str(image) for image in images),
                    f"got {len(images)} image files",
                    "give exactly two image files (left, right), or a folder",
                )
            )
        pairs.append(_pair_from_two_files(*images))
    return _unique(pairs)


# --------------------------------------------------------------------------- loading


def _hw(shape) -> str:
    return f"{shape[0]}x{shape[1]}"


def _as_grey_like(image: np.ndarray) -> np.ndarray:
    """Colour -> grey of the same dtype (used only when one view is grey, the other colour)."""
    grey = io.to_grey(image)
    if image.dtype == np.uint16:
        grey = grey * 257.0
    if image.dtype.kind == "f":
        return grey
    return np.round(grey).astype(image.dtype)


def normalise_bit_depth(left: np.ndarray, right: np.ndarray, *, bits: int | None = None,
                        where: str = "pair") -> tuple[np.ndarray, np.ndarray, int]:
    """Bring the samples of a pair to the full range of their type, with one factor.

    10- and 12-bit camera data stored in 16-bit PNGs would otherwise be read as 0-4 or
    0-16 grey levels (16-bit values are mapped to 0-255 by /257).  Both views get the same
    factor, so that matching and photometric scores see the same scale.

    Parameters
    ----------
    left, right : ndarray
        uint8, uint16 or float32 images of one pair (same dtype).
    bits : int, optional, keyword-only
        Bits per sample declared by the dataset; None: the smallest bit count (>= 8) that
        holds the pair's largest value.  Float images: values <= 1 are taken as 0-1,
        values <= 255 as 0-255, larger ones as ``bits``-bit integers.
    where : str
        Names the pair in errors.

    Returns
    -------
    left, right : ndarray
        uint16 scaled by ``2^(16 - bits)`` (exact), uint8 unchanged, float32 on 0-255.
    bits : int
        The bit depth used.

    Raises
    ------
    InputError
        Values beyond the declared bit depth, or negative float samples.
    """
    top = float(max(left.max(initial=0), right.max(initial=0)))
    if left.dtype == np.uint8:
        return left, right, 8
    if left.dtype == np.uint16:
        used = bits if bits is not None else max(8, int(top).bit_length())
        if top >= 2 ** used:
            raise InputError(where_what_fix(where, f"samples up to {int(top)} do not fit bit_depth {used}",
                                            f"fix bit_depth (at least {int(top).bit_length()}) or remove it"))
        if used >= 16:
            return left, right, 16
        shift = 16 - used
        return (left.astype(np.uint16) << shift), (right.astype(np.uint16) << shift), used
    low = float(min(left.min(initial=0), right.min(initial=0)))
    if low < 0:
        raise InputError(where_what_fix(where, f"negative intensities (down to {low:g}) in a float image",
                                        "give intensities >= 0 (0-1, 0-255 or integer counts)"))
    if bits is None and top <= 1.0:
        scale, used = 255.0, 0
    elif bits is None and top <= 255.0:
        scale, used = 1.0, 8
    else:
        used = bits if bits is not None else max(8, math.ceil(math.log2(top + 1)))
        scale = 255.0 / (2 ** used - 1)
    return (left * np.float32(scale)).astype(np.float32), (right * np.float32(scale)).astype(np.float32), used


def pair_image_size(pair: Pair, *, both: bool = False):
    """The pair's image size from the file headers, without decoding.

    Returns
    -------
    (height, width), or with ``both`` ((w_left, h_left), (w_right, h_right)); None when a
    header cannot be read without decoding.  Lets a batch check memory before it decodes.
    """
    if pair.error is not None:
        raise InputError(pair.error)
    left, right = io.image_size(pair.left), io.image_size(pair.right)
    if left is None or right is None:
        return None
    return (left, right) if both else (left[1], left[0])


def load_pair_images(pair: Pair) -> tuple[np.ndarray, np.ndarray]:
    """Read the two views of a pair.

    Returns
    -------
    left, right : ndarray
        uint8, uint16 or float32 (0-255), ``(H, W)`` or ``(H, W, 3)`` RGB, same shape and
        dtype.  When one view is grey and the other colour, the colour one is converted
        to grey.  16-bit and float data are scaled to their type's full range with the
        pair's bit depth (:func:`normalise_bit_depth`).

    Raises
    ------
    InputError
        Unreadable image, different sizes, or different bit depths.
    """
    if pair.error is not None:
        raise InputError(pair.error)
    sizes = pair_image_size(pair, both=True)
    if sizes is not None and sizes[0] != sizes[1]:  # refused before decoding either view
        (wl, hl), (wr, hr) = sizes
        raise InputError(where_what_fix(pair.name, f"left is {hl}x{wl} but right is {hr}x{wr}",
                                        "a stereo pair needs equal sizes"))
    left = io.read_image(pair.left)
    right = io.read_image(pair.right)
    if left.shape[:2] != right.shape[:2]:
        raise InputError(
            where_what_fix(
                pair.name,
                f"left is {_hw(left.shape)} but right is {_hw(right.shape)}",
                "a stereo pair needs equal sizes",
            )
        )
    if left.dtype != right.dtype:
        raise InputError(
            where_what_fix(
                pair.name,
                f"left is {left.dtype.itemsize * 8}-bit but right is {right.dtype.itemsize * 8}-bit",
                "give both views with the same bit depth",
            )
        )
    left, right, bits = normalise_bit_depth(left, right, bits=pair.bit_depth, where=pair.name)
    if bits not in (8, 16):
        log.debug("%s: %d-bit samples scaled to the full range", pair.name, bits)
    if left.ndim != right.ndim:
        log.warning("%s: one view is grey, the other colour; using grey for both", pair.name)
        left = _as_grey_like(left) if left.ndim == 3 else left
        right = _as_grey_like(right) if right.ndim == 3 else right
    return left, right


def _nocc_min_value(path: Path) -> int:
    # Middlebury 2014 mask0nocc.png: 255 = non-occluded, 128 = occluded, 0 = no GT.
    return 255 if path.name.lower().startswith("mask0nocc") else 1


def load_ground_truth(pair: Pair, shape: Sequence[int]) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Read a pair's ground truth and non-occlusion mask.

    Parameters
    ----------
    pair : Pair
    shape : sequence of int
        ``(H, W, ...)`` of the left image; the ground truth must match ``(H, W)``.

    Returns
    -------
    gt : ndarray float32 (H, W) with inf where invalid, or None without ground truth
    mask : ndarray bool (H, W) (True = evaluate), or None without a mask

    Raises
    ------
    InputError
        Unreadable file, or ground truth / mask of another size than the images.
    """
    if pair.gt is None:
        return None, None
    height, width = int(shape[0]), int(shape[1])
    gt = io.read_disparity(pair.gt, scale=pair.gt_scale, invalid=pair.gt_invalid)
    if gt.shape != (height, width):
        raise InputError(
            where_what_fix(
                pair.name,
                f"ground truth {Path(pair.gt).name} is {_hw(gt.shape)} but the images are {height}x{width}",
                "give ground truth of the left image's size",
            )
        )
    mask = None
    if pair.nocc is not None:
        mask = io.read_mask(pair.nocc, min_value=_nocc_min_value(Path(pair.nocc)))
        if mask.shape != (height, width):
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"mask {Path(pair.nocc).name} is {_hw(mask.shape)} but the images are {height}x{width}",
                    "give a mask of the left image's size",
                )
            )
    return gt, mask


def _max_disparity_from_gt(pair: Pair) -> int | None:
    gt = io.read_disparity(pair.gt, scale=pair.gt_scale, invalid=pair.gt_invalid)
    finite = gt[np.isfinite(gt) & (gt > 0)]
    if finite.size == 0:
        return None
    # A small margin above the largest true disparity, rounded up to a multiple of 16
    # (what SGBM needs and a comfortable search range for ours).
    return int(16 * math.ceil((math.ceil(float(finite.max())) + 4) / 16))


def resolve_max_disparity(pair: Pair, width: int, override: int | None = None) -> int:
    """Pick the disparity search range of a pair.

    Order: ``override`` (``--max-disparity``), ``pair.max_disparity`` (dataset), a margin
    above the largest ground-truth disparity rounded up to a multiple of 16 (capped at
    ``width - 1``), else ``width // 4``.

    Parameters
    ----------
    pair : Pair
    width : int
        Image width in pixels.
    override : int or None
        User value; wins when given.

    Returns
    -------
    int
        In ``[1, width - 1]``.

    Raises
    ------
    InputError
        A user or dataset value outside ``[1, width - 1]``.
    """
    if override is not None:
        if isinstance(override, bool) or not isinstance(override, (int, np.integer)) or not 0 < override < width:
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"--max-disparity {override} must be in [1, {width - 1}] (image width {width})",
                    "give a smaller positive value",
                )
            )
        return int(override)
    if pair.max_disparity is not None:
        if not 0 < pair.max_disparity < width:
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"max disparity {pair.max_disparity} from the dataset must be in [1, {width - 1}] (image width {width})",
                    "fix max_disparity in the manifest/calib or pass --max-disparity",
                )
            )
        return int(pair.max_disparity)
    derived = _max_disparity_from_gt(pair) if pair.gt is not None else None
    if derived is None:
        derived = width // 4
    derived = min(derived, width - 1)
    if derived < 1:
        raise InputError(
            where_what_fix(
                pair.name,
                f"image width {width} leaves no disparity range (--max-disparity must be in [1, width-1])",
                "give wider images",
            )
        )
    return derived
