"""Benchmark submission layouts written from a run's output folder (``d3stereo export``).

* ``kitti``: ``SUBMISSION/disp_0/<name>_10.png``, uint16 PNG of disparity * 256, 0 =
  invalid (the KITTI 2012/2015 stereo devkit reads ``png / 256``, invalid where 0).
  ``<name>_10`` is the left image's own name when it is a KITTI frame (``000000_10``),
  else ``<pair>_10``.
* ``middeval3``: ``SUBMISSION/<Split>/<Scene>/disp0<ALG>.pfm`` (float32 PFM, scale -1 =
  little-endian, rows bottom to top, ``inf`` = invalid) and ``time<ALG>.txt`` (the
  method's seconds for the pair, from ``result.json``).  Split and scene come from the
  left image's path (``.../trainingQ/Adirondack/im0.png``); pairs from other layouts
  take the split given and their pair name as the scene.

Only complete pairs are exported (``result.json`` is written last, so its presence says
the pair's files are whole); every file is written atomically, and OUT is only read.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data.formats import atomic_write, read_pfm, write_kitti_png, write_pfm
from ..errors import InputError, OutputError, where_what_fix
from .outputs import RESULT_FILE

#: The submission formats.
FORMATS = ("kitti", "middeval3")
#: KITTI's folder of left-view disparity maps of the first frame.
KITTI_FOLDER = "disp_0"
#: A KITTI frame name (left image stem): 6 digits, ``_10`` for the first frame of the pair.
KITTI_FRAME = re.compile(r"^\d{6}_10$")
#: A MiddEval3 split folder: training or test, full (F), half (H) or quarter (Q) size.
MIDDEVAL3_SPLIT = re.compile(r"^(training|test)[QHF]$")
#: Algorithm names MiddEval3 accepts in its file names.
ALGORITHM_NAME = re.compile(r"^[A-Za-z0-9_-]{1,40}$")
#: The disparity map of a pair in OUT.
DISPARITY_FILE = "disp.pfm"


@dataclass
class Exported:
    """What :func:`export_submission` wrote.

    Attributes
    ----------
    files : list of Path
        Every file written, in pair order.
    pairs : list of str
        The pairs exported.
    incomplete : list of str
        Pair folders of OUT without a complete result (failed or not yet computed).
    """

    files: list[Path] = field(default_factory=list)
    pairs: list[str] = field(default_factory=list)
    incomplete: list[str] = field(default_factory=list)


def export_submission(out: str | os.PathLike, submission: str | os.PathLike, fmt: str, *,
                      algorithm: str = "D3Stereo", split: str | None = None) -> Exported:
    """Write the submission layout ``fmt`` of every complete pair of the run folder ``out``.

    Parameters
    ----------
    out : path-like
        The output folder of ``d3stereo run`` (``<pair>/disp.pfm`` and ``<pair>/result.json``).
    submission : path-like
        Folder to write the layout into (created; files of the same names are replaced).
    fmt : {"kitti", "middeval3"}
        The benchmark layout.
    algorithm : str
        MiddEval3's algorithm name, in ``disp0<ALG>.pfm`` and ``time<ALG>.txt``.
    split : str, optional
        MiddEval3 split (``trainingQ``, ``testF``, ...) for pairs whose input path names none.

    Returns
    -------
    Exported
        The files written, the pairs exported and the incomplete pair folders skipped.

    Raises
    ------
    InputError
        OUT is not a run folder or holds no complete pair, a bad format, algorithm name or
        split, a pair whose MiddEval3 split is unknown, two pairs with one submission name.
    OutputError
        SUBMISSION is OUT or inside it, or cannot be written.
    """
    out, submission = Path(out), Path(submission)
    _check_arguments(out, submission, fmt, algorithm, split)
    complete, incomplete = _pairs_of(out)
    exported = Exported(incomplete=incomplete)
    targets: dict[Path, str] = {}
    for pair_dir in complete:
        result = json.loads((pair_dir / RESULT_FILE).read_text(encoding="utf-8"))
        if fmt == "kitti":
            files = {submission / KITTI_FOLDER / f"{kitti_name(pair_dir.name, result)}.png": "disp"}
        else:
            folder = submission / Path(*middeval3_place(pair_dir.name, result, split))
            files = {folder / f"disp0{algorithm}.pfm": "disp", folder / f"time{algorithm}.txt": "time"}
        for target in files:
            if target in targets:
                raise InputError(where_what_fix(str(out), f"pairs {targets[target]} and {pair_dir.name} both "
                                                f"give {target.relative_to(submission)}",
                                                "export runs of one dataset, one pair folder each"))
            targets[target] = pair_dir.name
        disparity = read_pfm(pair_dir / DISPARITY_FILE)
        for target, what in files.items():
            target.parent.mkdir(parents=True, exist_ok=True)
            if what == "time":
                text = f"{pair_seconds(pair_dir, result):.3f}\n"
                atomic_write(target, lambda tmp, text=text: Path(tmp).write_text(text, encoding="ascii"))
            elif fmt == "kitti":
                write_kitti_png(target, disparity)
            else:
                write_pfm(target, np.where(np.isfinite(disparity), disparity, np.float32(np.inf)))
            exported.files.append(target)
        exported.pairs.append(pair_dir.name)
    return exported


def _check_arguments(out: Path, submission: Path, fmt: str, algorithm: str, split: str | None) -> None:
    """Refuse a bad format, algorithm name, split, OUT, or a SUBMISSION inside OUT."""
    if fmt not in FORMATS:
        raise InputError(f"{fmt}: unknown submission format; give one of {', '.join(FORMATS)}")
    if not ALGORITHM_NAME.match(algorithm):
        raise InputError(where_what_fix(algorithm, "not a usable algorithm name",
                                        "give 1-40 letters, digits, '_' or '-' (it goes into file names)"))
    if split is not None and not MIDDEVAL3_SPLIT.match(split):
        raise InputError(where_what_fix(split, "not a MiddEval3 split",
                                        "give training or test followed by Q, H or F (e.g. trainingQ)"))
    if not out.is_dir():
        raise InputError(where_what_fix(str(out), "no such folder", "give the output folder of d3stereo run"))
    inside = Path(os.path.abspath(submission))
    if inside == Path(os.path.abspath(out)) or Path(os.path.abspath(out)) in inside.parents:
        raise OutputError(where_what_fix(str(submission), f"is inside the run folder {out}",
                                         "write the submission to a folder outside it"))


def _pairs_of(out: Path) -> tuple[list[Path], list[str]]:
    """(complete pair folders, names of incomplete ones) of OUT, sorted by name."""
    complete, incomplete = [], []
    for entry in sorted(out.iterdir()):
        if not entry.is_dir() or entry.name.startswith("."):
            continue
        if (entry / RESULT_FILE).is_file() and (entry / DISPARITY_FILE).is_file():
            complete.append(entry)
        else:
            incomplete.append(entry.name)
    if not complete:
        raise InputError(where_what_fix(str(out), f"no complete pair (no <pair>/{RESULT_FILE} with "
                                        f"{DISPARITY_FILE})", "give the output folder of d3stereo run"))
    return complete, incomplete


def kitti_name(pair: str, result: dict) -> str:
    """``000000_10`` for a KITTI frame (the left image's own name), else ``<pair>_10``."""
    stem = Path(str((result.get("inputs") or {}).get("left") or "")).stem
    return stem if KITTI_FRAME.match(stem) else f"{pair}_10"


def middeval3_place(pair: str, result: dict, split: str | None) -> tuple[str, str]:
    """``(Split, Scene)`` of a pair: from ``.../<Split>/<Scene>/im0.png``, else (split, pair).

    Raises
    ------
    InputError
        The split is neither in the path nor given.
    """
    left = Path(str((result.get("inputs") or {}).get("left") or ""))
    if left.name.lower() == "im0.png" and MIDDEVAL3_SPLIT.match(left.parent.parent.name):
        return left.parent.parent.name, left.parent.name
    scene = left.parent.name if left.name.lower() == "im0.png" and left.parent.name else pair
    if split is None:
        raise InputError(where_what_fix(pair, f"the MiddEval3 split is not in the path of its left image {left}",
                                        "pass --split (e.g. --split trainingQ)"))
    return split, scene


def pair_seconds(pair_dir: Path, result: dict) -> float:
    """The method's seconds for the pair (``timings.total``; ``wall`` where that is missing)."""
    timings = result.get("timings") or {}
    seconds = timings.get("total", timings.get("wall"))
    if not isinstance(seconds, (int, float)) or not np.isfinite(seconds) or seconds < 0:
        raise InputError(where_what_fix(str(pair_dir / RESULT_FILE), "no timings.total (seconds) to write",
                                        "compute the pair again with d3stereo run --overwrite"))
    return float(seconds)
