"""The files of an output folder and how they are written, read back and removed.

Layout of an output folder ``OUT``::

    OUT/run.json                 resolved config, versions, backend, per-pair status
    OUT/<pair>/disp.pfm          float32 disparity, inf = invalid
    OUT/<pair>/disp.png          KITTI uint16 (disparity * 256, 0 = invalid)
    OUT/<pair>/disp_color.png    TURBO over the 1st-99th percentile of the estimate (or
                                 --color-range), colour bar stating the range
    OUT/<pair>/valid.png         255 where the method decided the disparity itself (mask,
                                 read back for point clouds)
    OUT/<pair>/valid_overlay.png the left image, filled pixels red, no disparity blue
    OUT/<pair>/error.png         KITTI log-colour error map with legend (--eval and gt)
    OUT/<pair>/panel.png         left | disparity | error | validity, titled with metrics
    OUT/<pair>/cloud.ply         point cloud (only with --pointcloud)
    OUT/<pair>/height.pfm, height_color.png, defects.json, defects.png   (only with --road-report)
    OUT/<pair>/result.json       timings, metrics, info; written LAST
    OUT/metrics.csv, summary.json, summary.md   (only with --eval)
    OUT/defects.csv              every defect of every pair (only with --road-report)

Every file is written atomically, and ``result.json`` last: its presence means the pair
is complete.  A pair is written into a staging folder ``OUT/.<pair>.partial-XXXX`` that
replaces ``OUT/<pair>`` in one rename once complete (:mod:`d3cli.batch.staging`), and
``result.json`` records the size and SHA-256 of every file of the pair (``"files"``),
checked before a rerun skips it.
"""

from __future__ import annotations

import json
import logging
import os
import re
from pathlib import Path

import numpy as np

from ..data.formats import atomic_write, read_image, write_image, write_kitti_png, write_pfm
from ..evaluation import pictures
from ..evaluation.html import REPORT_FILE
from ..errors import InputError, OutputError, where_what_fix
from ..evaluation.report import jsonable
from .staging import file_records
from ..road.outputs import CSV_FIELDS as DEFECTS_CSV_FIELDS
from ..road.outputs import DEFECTS_CSV, DEFECTS_JSON, DEFECTS_PNG, HEIGHT_COLOR_FILE, HEIGHT_FILE, SURVEY_JSON
from ..survey.outputs import DEFECTS_GEOJSON, TRACK_GEOJSON

log = logging.getLogger(__name__)

#: The per-pair files of a complete result with every output (``run.outputs: all``), besides result.json.
OUTPUT_FILES = ("disp.pfm", "disp.png", "disp_color.png", "valid.png")
#: The per-pair files every run writes, whatever ``run.outputs`` leaves out: what a rerun
#: (road report, clouds, evaluation, more outputs), ``d3stereo eval`` and ``export`` read.
REQUIRED_FILES = ("disp.pfm", "valid.png")
RESULT_FILE = "result.json"
ERROR_MAP = "error.png"
PANEL_FILE = "panel.png"
OVERLAY_FILE = "valid_overlay.png"
CLOUD_FILE = "cloud.ply"  # only with --pointcloud
RUN_FILE = "run.json"
#: Largest disparity disp.png can hold: KITTI's uint16 stores round(d * 256) <= 65535.
KITTI_PNG_MAX_DISPARITY = 65535 / 256.0
#: Batch-level report files of ``--eval`` (d3cli.evaluation.report.write_summary).
SUMMARY_FILES = ("metrics.csv", "summary.json", "summary.md")
#: Road inspection outputs of a pair (--road-report), made from its disparity map: stale
#: once the map is computed again.
ROAD_FILES = (HEIGHT_FILE, HEIGHT_COLOR_FILE, DEFECTS_JSON, DEFECTS_PNG)
#: The files of each optional group of ``run.outputs`` (:data:`d3cli.config.OUTPUT_GROUPS`).
GROUP_FILES = {"kitti": ("disp.png",),
               "pictures": ("disp_color.png", OVERLAY_FILE, ERROR_MAP, PANEL_FILE, HEIGHT_COLOR_FILE, DEFECTS_PNG),
               "height": (HEIGHT_FILE,)}
#: Every file d3stereo writes into a pair's folder (anything else there is the user's).
PAIR_FILES = (RESULT_FILE, *OUTPUT_FILES, ERROR_MAP, CLOUD_FILE, PANEL_FILE, OVERLAY_FILE, *ROAD_FILES)
#: Files of a whole batch (or eval report) in OUT, beside the pairs' folders.
BATCH_FILES = (RUN_FILE, REPORT_FILE, *SUMMARY_FILES, DEFECTS_CSV, SURVEY_JSON, DEFECTS_GEOJSON, TRACK_GEOJSON)
#: A shard's run record, ``run-I-of-N.json``.
_SHARD_RECORD = re.compile(r"run-\d+-of-\d+\.json")
#: Prefix of d3stereo's hidden files in OUT (lock files, the writability probe).
_HIDDEN_PREFIX = ".d3stereo"


def reserved_name(name: str) -> str | None:
    """The file of OUT that a pair folder named ``name`` would collide with, or None.

    Compared without case: OUT may lie on a file system that ignores it (macOS, SMB).
    """
    folded = name.casefold()
    for batch_file in BATCH_FILES:
        if folded == batch_file.casefold():
            return batch_file
    if _SHARD_RECORD.fullmatch(folded):
        return folded
    if folded.startswith(_HIDDEN_PREFIX):
        return name
    return None


def check_pair_name(name: str, out: Path) -> None:
    """Refuse a pair whose folder ``out/<name>`` would take the name of a file the batch
    writes there (the batch would stop on writing that file, after the pairs).

    Raises
    ------
    InputError
        ``NAME: the pair's name is taken by a file d3stereo writes into the output folder
        (OUT/run.json); rename the pair (its folder, or its name in the manifest) and rerun``.
    """
    taken = reserved_name(name)
    if taken is not None:
        raise InputError(where_what_fix(
            name, f"the pair's name is taken by a file d3stereo writes into the output folder ({Path(out) / taken})",
            "rename the pair (its folder, or its name in the manifest) and rerun"))


def check_batch_files(out: Path) -> None:
    """Refuse an output folder where the name of a batch file (run.json, report.html, the
    summary files, a shard's record) is a folder: the batch could not be recorded (a pair
    folder of that name, written by an earlier d3stereo).

    Raises
    ------
    OutputError
        ``OUT/run.json: is a folder, where d3stereo writes a file of the batch; move it away
        (a pair's folder: rename the pair) or choose another -o folder``.
    """
    try:
        names = [name for name in os.listdir(out) if _SHARD_RECORD.fullmatch(name)]
    except OSError:
        names = []  # a new folder; one that cannot be read is named by ensure_writable
    for name in (*BATCH_FILES, *names):
        entry = Path(out) / name
        if entry.is_dir() and not entry.is_symlink():
            raise OutputError(where_what_fix(str(entry), "is a folder, where d3stereo writes a file of the batch",
                                             "move it away (a pair's folder: rename the pair) or choose another "
                                             "-o folder"))


def check_output_folder(out: Path, pairs) -> None:
    """Refuse an output folder whose writing could touch an input file (a ground truth
    named ``disp.png`` in the input folder would be replaced by the prediction and then
    scored; a link ``OUT/p1`` into the input pair would have the user's files overwritten).

    Compared by real path, so links and ``..`` hide nothing:

    * no input file of any pair may lie inside OUT (nor be OUT itself);
    * ``OUT/<pair>`` must not be a symbolic link leading outside OUT (it is replaced when
      the pair is written, never written through, but a link into the inputs says the
      folder was chosen wrongly);
    * OUT may be a new folder inside the inputs' folder (``d3stereo run L.png R.png -o
      out`` in the images' own folder): nothing is written next to the inputs;
    * no batch file's name may be a folder (:func:`check_batch_files`).

    A pair named like a batch file is left to fail alone (:func:`check_pair_name`).

    Raises
    ------
    OutputError
        Naming the folder, the pair and input concerned, and the fix.
    """
    check_batch_files(Path(out))
    root = Path(os.path.realpath(out))
    for pair in pairs:
        entry = Path(out) / pair.name
        target = Path(os.path.realpath(entry))
        if entry.is_symlink() and root not in target.parents:
            raise OutputError(where_what_fix(
                str(entry), f"is a symbolic link leading outside the output folder (to {target})",
                "remove the link (what it points to is left alone) or choose another -o folder"))
        # A reserved name is never written (the pair fails alone): OUT/run.json is the batch's.
        if not entry.is_symlink() and entry.exists() and not entry.is_dir() and reserved_name(pair.name) is None:
            raise OutputError(where_what_fix(str(entry), f"is a file, where pair {pair.name} writes its folder",
                                             "move it away or choose another -o folder"))
        for key in ("left", "right", "gt", "nocc", "calib"):
            given = getattr(pair, key, None)
            if given is None:
                continue
            real = Path(os.path.realpath(given))
            if real == root or root in real.parents:
                raise OutputError(where_what_fix(
                    str(out), f"the output folder holds input files of pair {pair.name} ({real})",
                    "choose an output folder outside the input data with -o (a new folder beside the inputs is fine)"))


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON (NaN/inf as null), atomically."""
    text = json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n"
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


def write_result(folder: Path, stored: dict) -> dict:
    """Write ``folder/result.json`` from ``stored`` with the size and SHA-256 of every file
    of the pair now in ``folder`` (``"files"``, checked before a rerun skips the pair);
    returns what was written."""
    stored = {**stored, "files": file_records(folder, [n for n in PAIR_FILES if n != RESULT_FILE])}
    write_json(folder / RESULT_FILE, stored)
    return stored


def read_result(pair_dir: Path) -> dict | None:
    """The stored result of a complete pair folder, or None when incomplete."""
    result_path = pair_dir / RESULT_FILE
    if not result_path.is_file() or not all((pair_dir / f).is_file() for f in REQUIRED_FILES):
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
    names = PAIR_FILES  # result.json first: never a "complete" pair missing a file
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


def write_disparity_outputs(
    folder: str | os.PathLike,
    disp: np.ndarray,
    valid: np.ndarray,
    *,
    vmax: float | None = None,
    left: np.ndarray | None = None,
    color_range: tuple[float, float] | None = None,
    groups: frozenset | None = None,
) -> dict:
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
        Unused (accepted for callers that pass a fixed [0, max disparity] range).
    left : ndarray, optional
        Left image; with it ``valid_overlay.png`` is written.
    color_range : (float, float), optional
        Fixed ``(vmin, vmax)`` of ``disp_color.png`` (``--color-range``); default the
        1st-99th percentile of the finite estimate (:func:`pictures.robust_range`).
    groups : frozenset, optional
        The optional groups of ``run.outputs`` to write (:data:`GROUP_FILES`): without
        ``kitti`` no disp.png, without ``pictures`` no disp_color.png or
        valid_overlay.png; None: all.  disp.pfm and valid.png are always written.

    Returns
    -------
    dict
        File name -> Path for every file written, and ``"color_range"``:
        ``{"min": vmin, "max": vmax, "how": "1-99th percentile" | "fixed"}``.
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
    with np.errstate(invalid="ignore"):
        if (disp < 0).any():  # disparities are >= 0 by contract: a method bug, never written
            raise ValueError(f"{folder.name}: the method returned negative disparities (down to "
                             f"{float(np.nanmin(disp)):.3f}); please report this")
    if color_range is None:
        vmin, vmax_ = pictures.robust_range(disp)
        how = "%g-%gth percentile" % pictures.ROBUST_PERCENTILES
    else:
        vmin, vmax_ = (float(v) for v in color_range)
        how = "fixed range"
    groups = frozenset(GROUP_FILES) if groups is None else groups
    written = {"disp.pfm": write_pfm(folder / "disp.pfm", disp)}
    if "kitti" in groups:
        written["disp.png"] = write_kitti_png(folder / "disp.png", disp)
    if "pictures" in groups:
        written["disp_color.png"] = write_image(folder / "disp_color.png",
                                                pictures.disparity_picture(disp, vmin, vmax_, how=how))
    written["valid.png"] = write_image(folder / "valid.png", valid.astype(np.uint8) * 255)
    if left is not None and "pictures" in groups:
        written[OVERLAY_FILE] = write_image(folder / OVERLAY_FILE, pictures.validity_overlay(left, valid, disp))
    written["color_range"] = {"min": vmin, "max": vmax_, "how": how}
    written["png_clipped"] = kitti_clipped(disp)
    return written


def kitti_clipped(disp: np.ndarray) -> int:
    """Number of finite disparities that disp.png cannot hold (>= 65535.5 / 256 px: clipped).

    KITTI's format stores ``round(d * 256)`` in uint16, so it ends at 255.996 px; such
    pixels are written as 255.996 in disp.png, exactly in disp.pfm (the reference).
    """
    with np.errstate(invalid="ignore"):
        return int(np.count_nonzero(np.isfinite(disp) & (disp * 256.0 >= 65535.5)))


def clipped_warning(n_clipped: int) -> str:
    """The result.json warning for :func:`kitti_clipped` pixels."""
    return (f"disp.png: {n_clipped} pixels have a disparity >= 256 px and are clipped to "
            f"{KITTI_PNG_MAX_DISPARITY:.3f} px (KITTI uint16 format); disp.pfm holds the exact values")


def is_our_summary(path: Path) -> bool:
    """True when ``path`` is a summary file as :func:`d3cli.evaluation.report.write_summary`
    writes it (so a later run may remove it; never a file of the user's)."""
    try:
        with open(path, encoding="utf-8") as fh:
            head = fh.read(4096)
    except (OSError, UnicodeDecodeError):
        return False
    if path.name == "metrics.csv":
        return head.startswith("pair,family,status")
    if path.name == "summary.md":
        return head.startswith("# Evaluation:")
    if path.name == DEFECTS_CSV:
        return head.startswith(",".join(DEFECTS_CSV_FIELDS) + "\n")
    if path.name == "summary.json":
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        return isinstance(data, dict) and {"method", "counts", "overall", "extra"} <= set(data)
    return False


def remove_ours(path: Path) -> bool:
    """Remove ``path`` when it is a report file d3stereo wrote (:func:`is_our_summary`)."""
    if not (path.is_file() and is_our_summary(path)):
        return False
    try:
        path.unlink()
    except OSError as exc:
        log.warning("%s: could not remove the report of an earlier run (%s)", path, exc)
        return False
    return True


def remove_stale_summaries(out: Path) -> list[str]:
    """Remove the ``--eval`` summary files of an earlier run from ``out``; returns their names.

    A run without ``--eval`` does not write them, so left in place they would describe
    another run (another method, other maps).  Only files recognised as written by
    d3stereo (:func:`is_our_summary`) are removed.
    """
    return [name for name in SUMMARY_FILES if remove_ours(out / name)]


def panel_title(name: str, scores: dict | None) -> str:
    """``pair   EPE 1.23 px   D1 4.50%   bad2noc 7.80%   A90noc 2.10 px   PSNR 30.00 dB`` (the
    figures that exist; every one with its unit)."""
    parts = [name]
    for key, label, unit in (("epe", "EPE", " px"), ("d1_all", "D1", "%"), ("bad_2_noc", "bad2noc", "%"),
                             ("a90_noc", "A90noc", " px"), ("psnr", "PSNR", " dB")):
        value = (scores or {}).get(key)
        if isinstance(value, (int, float)) and np.isfinite(value):
            parts.append(f"{label} {value:.2f}{unit}")
    return "   ".join(parts)


def write_panel(folder: str | os.PathLike, name: str, left: np.ndarray, scores: dict | None) -> Path:
    """``panel.png``: left | disparity | error (when error.png exists) | validity, titled.

    Built from the pictures already in ``folder`` so it shows exactly what they show.
    """
    folder = Path(folder)
    tiles = [("left", np.asarray(left)), ("disparity", read_image(folder / "disp_color.png"))]
    if (folder / ERROR_MAP).is_file():
        tiles.append(("error (KITTI log colours)", read_image(folder / ERROR_MAP)))
    overlay = folder / OVERLAY_FILE
    tiles.append(("validity (red filled, blue none)", read_image(overlay) if overlay.is_file()
                  else read_image(folder / "valid.png")))
    return write_image(folder / PANEL_FILE, pictures.panel(panel_title(name, scores), tiles))


def add_missing_outputs(pair_dir: Path, name: str, stored: dict, groups: frozenset, *, left: np.ndarray,
                        disparity: np.ndarray, valid: np.ndarray) -> list[str]:
    """Write the map files of ``groups`` that a complete pair folder lacks (it was written
    with fewer outputs): disp.png, disp_color.png (with the stored colour range),
    valid_overlay.png and panel.png, from its disp.pfm and valid.png; returns their names.
    The error map is the evaluation's (:func:`d3cli.batch.scoring.evaluate_pair`)."""
    folder = Path(pair_dir)
    made = []
    if "kitti" in groups and not (folder / "disp.png").is_file():
        write_kitti_png(folder / "disp.png", disparity)
        made.append("disp.png")
    if "pictures" in groups:
        if not (folder / "disp_color.png").is_file():
            colours = stored.get("color_range") or {}
            vmin, vmax = colours.get("min"), colours.get("max")
            if vmin is None or vmax is None:
                vmin, vmax = pictures.robust_range(disparity)
            how = colours.get("how") or "%g-%gth percentile" % pictures.ROBUST_PERCENTILES
            write_image(folder / "disp_color.png", pictures.disparity_picture(disparity, vmin, vmax, how=how))
            made.append("disp_color.png")
        if not (folder / OVERLAY_FILE).is_file():
            write_image(folder / OVERLAY_FILE, pictures.validity_overlay(left, valid, disparity))
            made.append(OVERLAY_FILE)
        if made or not (folder / PANEL_FILE).is_file():
            write_panel(folder, name, left, stored.get("metrics"))
            made.append(PANEL_FILE)
    return made
