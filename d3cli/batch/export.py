"""Benchmark submission layouts written from a run's output folder (``d3stereo export``).

* ``kitti``: ``SUBMISSION/disp_0/<frame>.png``, uint16 PNG of disparity * 256, 0 =
  invalid (the KITTI 2012/2015 stereo devkit reads ``png / 256``, invalid where 0).
  ``<frame>`` (``000000_10``) is the left image's own name when it is a KITTI frame, else
  the frame id that ends the pair name (``kitti2015-000000_10``, the pair-folder layout);
  a pair with neither is written as ``<pair>_10.png`` with a warning, since the devkit
  looks its files up by frame id only.  Disparities the PNG cannot hold (>= 256 px) are
  written as 255.996 px with a warning naming the pair and the count.
* ``middeval3``: ``SUBMISSION/<Split>/<Scene>/disp0<ALG>.pfm`` (float32 PFM, scale -1 =
  little-endian, rows bottom to top, ``inf`` = invalid) and ``time<ALG>.txt`` (the
  method's seconds for the pair, from ``result.json``).  Split and scene come from the
  left image's path (``.../trainingQ/Adirondack/im0.png``), else from a pair name
  ``middlebury2014-<scene>-<Q|H|F>`` (the MiddEval3 layout's names, kept by the
  pair-folder layout), else the split given and the pair name as the scene.  A folder
  that is not a MiddEval3 scene of its split is written with a warning: the SDK reads
  only its own scene list.

Only complete pairs are exported (``result.json`` is written last, so its presence says
the pair's files are whole).  Every file read from OUT is checked: ``result.json`` must
be the JSON object d3stereo writes, and ``disp.pfm`` must have the size and SHA-256 that
``result.json`` records, so a map replaced or edited after the run is never shipped.  A
pair that fails a check is left out and reported (``Exported.failed``), the others are
exported.  Every file is written atomically, nothing is written inside OUT (compared by
real path, so links hide nothing), and OUT is only read.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..data.formats import atomic_write, read_pfm, write_kitti_png, write_pfm
from ..errors import InputError, OutputError, where_what_fix
from .outputs import KITTI_PNG_MAX_DISPARITY, RESULT_FILE, kitti_clipped

log = logging.getLogger(__name__)

#: The submission formats.
FORMATS = ("kitti", "middeval3")
#: KITTI's folder of left-view disparity maps of the first frame.
KITTI_FOLDER = "disp_0"
#: A KITTI frame name (left image stem): 6 digits, ``_10`` for the first frame of the pair.
KITTI_FRAME = re.compile(r"^\d{6}_10$")
#: A pair name ending in a KITTI frame id (``kitti2015-000000_10``, ``kitti2012-testing-000007_10``).
KITTI_FRAME_IN_NAME = re.compile(r"(?:^|-)(\d{6}_10)$")
#: A MiddEval3 split folder: training or test, full (F), half (H) or quarter (Q) size.
MIDDEVAL3_SPLIT = re.compile(r"^(training|test)[QHF]$")
#: The scenes the MiddEval3 SDK evaluates, by split kind (its own scene lists).
MIDDEVAL3_SCENES = {
    "training": ("Adirondack", "ArtL", "Jadeplant", "Motorcycle", "MotorcycleE", "Piano", "PianoL", "Pipes",
                 "Playroom", "Playtable", "PlaytableP", "Recycle", "Shelves", "Teddy", "Vintage"),
    "test": ("Australia", "AustraliaP", "Bicycle2", "Classroom2", "Classroom2E", "Computer", "Crusade", "CrusadeP",
             "Djembe", "DjembeL", "Hoops", "Livingroom", "Newkuba", "Plants", "Staircase"),
}
#: A pair name of the MiddEval3 layout: ``middlebury2014-<scene in lower case>[-<Q|H|F>]``.
MIDDLEBURY_PAIR = re.compile(r"^middlebury2014-(?P<scene>[A-Za-z0-9]+)(?:-(?P<size>[QHF]))?$")
#: Algorithm names MiddEval3 accepts in its file names.
ALGORITHM_NAME = re.compile(r"^[A-Za-z0-9_-]{1,40}$")
#: The disparity map of a pair in OUT.
DISPARITY_FILE = "disp.pfm"
#: Larger than any result.json d3stereo writes (a few kB): such a file is not read.
MAX_RESULT_BYTES = 16 * 2**20
#: Names listed in one warning line; the rest are counted.
MAX_LISTED = 10
#: The fix of a damaged result.json: without it the pair is incomplete, and the run computes it.
RERUN_RESULT = "delete it and rerun the same d3stereo run command (that computes the pair again)"
#: The fix of a disp.pfm that is not the one the run wrote: the run's resume check finds it.
RERUN_MAP = "rerun the same d3stereo run command (that computes the pair again)"


class DamagedPair(InputError):
    """A file of one pair of OUT is not as the run wrote it: that pair is not exported."""


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
    failed : list of (str, str)
        Pairs left out because a file of theirs is damaged or changed: (pair, message
        naming the file, what is wrong and the fix).
    warnings : list of str
        What was written but will not be read as the user may expect (names the
        benchmark's code does not look up, clipped disparities); also logged.
    """

    files: list[Path] = field(default_factory=list)
    pairs: list[str] = field(default_factory=list)
    incomplete: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


@dataclass
class _Planned:
    """A pair whose result.json passed its checks, and the files it becomes."""

    pair_dir: Path
    result: dict
    targets: dict[Path, str]  # file -> "disp" or "time"
    seconds: float | None = None


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
        MiddEval3 split (``trainingQ``, ``testF``, ...) for pairs whose input path and name
        give none.

    Returns
    -------
    Exported
        The files written, the pairs exported, the incomplete pair folders skipped, the
        pairs left out as damaged (with why) and the warnings.

    Raises
    ------
    InputError
        OUT is not a run folder or holds no complete pair, a bad format, algorithm name or
        split, a pair whose MiddEval3 split is unknown, two pairs with one submission name.
        Raised before anything is written.
    OutputError
        SUBMISSION (or a folder of its layout) is OUT, inside it or leads into it, is a
        file, or cannot be created or written.
    """
    out, submission = Path(out), Path(submission)
    _check_arguments(out, submission, fmt, algorithm, split)
    candidates, incomplete = _pairs_of(out)
    exported = Exported(incomplete=incomplete)
    planned = _plan(out, candidates, submission, fmt, algorithm, split, exported)
    if planned:
        _check_folders(out, submission, planned)
        _make_folder(submission)
    for plan in planned:
        pair = plan.pair_dir.name
        try:
            disparity = verified_disparity(plan.pair_dir, plan.result)
        except DamagedPair as exc:
            exported.failed.append((pair, str(exc)))
            continue
        for target, what in plan.targets.items():
            _make_folder(target.parent)
            if what == "time":
                text = f"{plan.seconds:.3f}\n"
                atomic_write(target, lambda tmp, text=text: Path(tmp).write_text(text, encoding="ascii"))
            elif fmt == "kitti":
                clipped = kitti_clipped(disparity)
                if clipped:
                    counted = f"{clipped} pixels have" if clipped != 1 else "1 pixel has"
                    _warn(exported, f"{pair}: {counted} a disparity >= 256 px, written as "
                                    f"{KITTI_PNG_MAX_DISPARITY:.3f} px in {target.relative_to(submission)} "
                                    "(the most a KITTI PNG holds)")
                write_kitti_png(target, disparity)
            else:
                write_pfm(target, np.where(np.isfinite(disparity), disparity, np.float32(np.inf)))
            exported.files.append(target)
        exported.pairs.append(pair)
    exported.failed.sort()
    return exported


def _plan(out: Path, candidates: list[Path], submission: Path, fmt: str, algorithm: str, split: str | None,
          exported: Exported) -> list[_Planned]:
    """Read and check every pair's result.json and give each its files: damaged pairs go
    to ``exported.failed``; a missing split or a name clash refuses the export (nothing
    written yet)."""
    planned: list[_Planned] = []
    unread: list[str] = []  # files or folders the benchmark's code will not look up
    for pair_dir in candidates:
        try:
            result = read_run_result(pair_dir)
            left_image(pair_dir, result)  # inputs of the wrong type: damaged
            seconds = pair_seconds(pair_dir, result) if fmt == "middeval3" else None
        except DamagedPair as exc:
            exported.failed.append((pair_dir.name, str(exc)))
            continue
        if fmt == "kitti":
            name = kitti_name(pair_dir.name, result)
            if not KITTI_FRAME.match(name):
                unread.append(f"{KITTI_FOLDER}/{name}.png")
            targets = {submission / KITTI_FOLDER / f"{name}.png": "disp"}
        else:
            place = middeval3_place(pair_dir.name, result, split)
            if place[1] not in MIDDEVAL3_SCENES[MIDDEVAL3_SPLIT.match(place[0]).group(1)]:
                unread.append("/".join(place))
            folder = submission / Path(*place)
            targets = {folder / f"disp0{algorithm}.pfm": "disp", folder / f"time{algorithm}.txt": "time"}
        planned.append(_Planned(pair_dir, result, targets, seconds))
    owner: dict[Path, str] = {}
    for plan in planned:
        for target in plan.targets:
            if target in owner:
                raise InputError(where_what_fix(str(out), f"pairs {owner[target]} and {plan.pair_dir.name} both "
                                                f"give {target.relative_to(submission)}",
                                                "export runs of one dataset, one pair folder each"))
            owner[target] = plan.pair_dir.name
    if unread:
        listed = ", ".join(unread[:MAX_LISTED]) + (f", and {len(unread) - MAX_LISTED} more"
                                                   if len(unread) > MAX_LISTED else "")
        if fmt == "kitti":
            _warn(exported, "files the KITTI devkit does not read (no frame id like 000000_10 in the pair's "
                            f"name or its left image's name): {listed}")
        else:
            _warn(exported, "folders the MiddEval3 SDK does not read (not a MiddEval3 scene of their split): "
                            f"{listed}")
    return planned


def _warn(exported: Exported, message: str) -> None:
    exported.warnings.append(message)
    log.warning("%s", message)


def _check_arguments(out: Path, submission: Path, fmt: str, algorithm: str, split: str | None) -> None:
    """Refuse a bad format, algorithm name, split, OUT, or a SUBMISSION in OUT."""
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
    _refuse_inside(out, submission)


def _refuse_inside(out: Path, folder: Path) -> None:
    """Refuse ``folder`` when it is OUT or lies inside it, by real path (a symbolic link
    anywhere on the way, or ``..``, would otherwise write into the run folder)."""
    root = Path(os.path.realpath(out))
    real = Path(os.path.realpath(folder))
    if real != root and root not in real.parents:
        return
    fix = "write the submission to a folder outside it"
    plain = Path(os.path.abspath(folder))
    if plain == Path(os.path.abspath(out)):
        raise OutputError(where_what_fix(str(folder), f"is the run folder {out}", fix))
    if Path(os.path.abspath(out)) in plain.parents:
        raise OutputError(where_what_fix(str(folder), f"is inside the run folder {out}", fix))
    raise OutputError(where_what_fix(str(folder), f"leads into the run folder {out} (to {real})", fix))


def _check_folders(out: Path, submission: Path, planned: list[_Planned]) -> None:
    """Refuse, before anything is written, a folder of the layout that is OUT or leads
    into it (OUT may lie inside SUBMISSION, just not where the layout writes)."""
    for folder in sorted({target.parent for plan in planned for target in plan.targets}):
        _refuse_inside(out, folder)


def _make_folder(folder: Path) -> None:
    """``mkdir -p folder``, or one OutputError saying why it cannot be a folder."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return
    except FileExistsError:  # exist_ok: the path is there and not a folder
        raise OutputError(where_what_fix(str(folder), "is a file, not a folder",
                                         "move it away or choose another -o folder")) from None
    except OSError as exc:
        error = exc
    for above in [folder, *folder.parents]:
        if os.path.lexists(above):
            if not above.is_dir():
                raise OutputError(where_what_fix(str(folder), f"{above} is a file, not a folder",
                                                 "choose another -o folder"))
            break
    raise OutputError(where_what_fix(str(folder), f"cannot create the folder ({error.strerror or error})",
                                     "choose another -o folder"))


def _pairs_of(out: Path) -> tuple[list[Path], list[str]]:
    """(pair folders holding a result.json, names of the other pair folders) of OUT, by name.

    A folder with a result.json counts as complete here; its files are checked when read.
    """
    try:
        entries = sorted(out.iterdir())
    except OSError as exc:
        raise InputError(where_what_fix(str(out), f"cannot list the folder ({exc.strerror or exc})",
                                        "check its permissions")) from None
    complete, incomplete = [], []
    for entry in entries:
        if entry.name.startswith(".") or not entry.is_dir():
            continue
        if os.path.lexists(entry / RESULT_FILE):
            complete.append(entry)
        else:
            incomplete.append(entry.name)
    if not complete:
        raise InputError(where_what_fix(str(out), f"no complete pair (no <pair>/{RESULT_FILE} with "
                                        f"{DISPARITY_FILE})", "give the output folder of d3stereo run"))
    return complete, incomplete


def _json_kind(value) -> str:
    """What a JSON value is, in JSON's own words."""
    if isinstance(value, bool):
        return "a JSON boolean"
    if value is None:
        return "JSON null"
    if isinstance(value, (int, float)):
        return "a JSON number"
    if isinstance(value, str):
        return "a JSON string"
    if isinstance(value, list):
        return "a JSON array"
    return "a JSON object"


def _regular_size(path: Path, fix: str) -> int:
    """Size of ``path`` when it is a regular file (a link to one included), else DamagedPair."""
    try:
        info = path.stat()
    except FileNotFoundError:
        raise DamagedPair(where_what_fix(str(path), "missing, though result.json says the pair is complete",
                                         fix)) from None
    except OSError as exc:
        raise DamagedPair(where_what_fix(str(path), f"cannot read ({exc.strerror or exc})", fix)) from None
    if stat.S_ISDIR(info.st_mode):
        raise DamagedPair(where_what_fix(str(path), "is a folder, not a file", fix))
    if not stat.S_ISREG(info.st_mode):
        raise DamagedPair(where_what_fix(str(path), "not a regular file", fix))
    return info.st_size


def _read(path: Path, fix: str) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise DamagedPair(where_what_fix(str(path), f"cannot read ({exc.strerror or exc})", fix)) from None


def _sha256(path: Path, fix: str) -> str:
    digest = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        raise DamagedPair(where_what_fix(str(path), f"cannot read ({exc.strerror or exc})", fix)) from None
    return digest.hexdigest()


def read_run_result(pair_dir: Path) -> dict:
    """The result.json of a pair folder of OUT, checked to be the JSON object d3stereo writes.

    Raises
    ------
    DamagedPair
        Naming the file, what is wrong with it and the fix (compute the pair again).
    """
    path = pair_dir / RESULT_FILE
    size = _regular_size(path, RERUN_RESULT)
    if size > MAX_RESULT_BYTES:
        raise DamagedPair(where_what_fix(str(path), f"is {size} bytes, not a result.json of d3stereo", RERUN_RESULT))
    data = _read(path, RERUN_RESULT)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise DamagedPair(where_what_fix(str(path), f"not UTF-8 text (byte 0x{data[exc.start]:02x} at offset "
                                                    f"{exc.start})", RERUN_RESULT)) from None
    try:
        result = json.loads(text)
    except RecursionError:
        raise DamagedPair(where_what_fix(str(path), "not JSON (nested too deeply)", RERUN_RESULT)) from None
    except ValueError as exc:
        raise DamagedPair(where_what_fix(str(path), f"not JSON ({exc})", RERUN_RESULT)) from None
    if not isinstance(result, dict):
        raise DamagedPair(where_what_fix(str(path), f"holds {_json_kind(result)}, not the object d3stereo writes",
                                         RERUN_RESULT))
    return result


def left_image(pair_dir: Path, result: dict) -> Path | None:
    """The left image's path recorded in result.json (``inputs.left``), None when absent.

    Raises
    ------
    DamagedPair
        ``inputs`` is not an object, or ``inputs.left`` not a string.
    """
    inputs = result.get("inputs")
    if inputs is None:
        return None
    where = str(pair_dir / RESULT_FILE)
    if not isinstance(inputs, dict):
        raise DamagedPair(where_what_fix(where, f"inputs is {_json_kind(inputs)}, not an object of input file "
                                                "paths", RERUN_RESULT))
    left = inputs.get("left")
    if left is None:
        return None
    if not isinstance(left, str):
        raise DamagedPair(where_what_fix(where, f"inputs.left is {_json_kind(left)}, not a file path", RERUN_RESULT))
    return Path(left) if left else None


def verified_disparity(pair_dir: Path, result: dict) -> np.ndarray:
    """The pair's disparity map, once its size and SHA-256 are the ones result.json records.

    Raises
    ------
    DamagedPair
        No usable record, disp.pfm missing, of another size or content, or not a PFM.
    """
    files = result.get("files")
    record = files.get(DISPARITY_FILE) if isinstance(files, dict) else None
    size = record.get("size") if isinstance(record, dict) else None
    digest = record.get("sha256") if isinstance(record, dict) else None
    if (not isinstance(size, int) or isinstance(size, bool) or size < 0 or not isinstance(digest, str)
            or not re.fullmatch(r"[0-9a-f]{64}", digest)):
        raise DamagedPair(where_what_fix(str(pair_dir / RESULT_FILE), f"records no size and SHA-256 of "
                                         f"{DISPARITY_FILE}, so the map cannot be checked", RERUN_RESULT))
    path = pair_dir / DISPARITY_FILE
    found = _regular_size(path, RERUN_MAP)
    if found != size:
        raise DamagedPair(where_what_fix(str(path), f"has {found} bytes, {size} when the run wrote it", RERUN_MAP))
    if _sha256(path, RERUN_MAP) != digest:
        raise DamagedPair(where_what_fix(str(path), "changed since the run wrote it (SHA-256 differs from "
                                                    "result.json's)", RERUN_MAP))
    try:
        return read_pfm(path)
    except InputError as exc:  # the record was edited along with the file
        raise DamagedPair(str(exc)) from None


def kitti_name(pair: str, result: dict) -> str:
    """The KITTI frame a pair is (``000000_10``): the left image's own name when it is one,
    else the frame id ending the pair name; ``<pair>_10`` when neither is."""
    left = (result.get("inputs") or {}).get("left") if isinstance(result.get("inputs"), dict) else None
    stem = Path(left).stem if isinstance(left, str) else ""
    if KITTI_FRAME.match(stem):
        return stem
    match = KITTI_FRAME_IN_NAME.search(pair)
    return match.group(1) if match else f"{pair}_10"


def middeval3_place(pair: str, result: dict, split: str | None) -> tuple[str, str]:
    """``(Split, Scene)`` of a pair: from ``.../<Split>/<Scene>/im0.png``, else from a pair
    name ``middlebury2014-<scene>-<Q|H|F>`` of a MiddEval3 scene, else (split, the scene
    folder of ``im0.png`` or the pair name).

    Raises
    ------
    InputError
        The split is neither in the path or the name nor given.
    """
    inputs = result.get("inputs")
    given = inputs.get("left") if isinstance(inputs, dict) else None
    left = Path(given) if isinstance(given, str) else Path()
    folder = left.parent.name if left.name.lower() == "im0.png" and left.parent.name not in ("", "..") else None
    if folder and MIDDEVAL3_SPLIT.match(left.parent.parent.name):
        return left.parent.parent.name, folder
    scene = folder or pair
    named = MIDDLEBURY_PAIR.match(pair)
    known = {name.lower(): (kind, name) for kind, names in MIDDEVAL3_SCENES.items() for name in names}
    if named and named.group("scene").lower() in known:
        kind, scene = known[named.group("scene").lower()]
        if named.group("size"):
            return f"{kind}{named.group('size')}", scene
    if split is None:
        raise InputError(where_what_fix(pair, f"the MiddEval3 split is not in the path of its left image {left}",
                                        "pass --split (e.g. --split trainingQ)"))
    return split, scene


def pair_seconds(pair_dir: Path, result: dict) -> float:
    """The method's seconds for the pair (``timings.total``; ``wall`` where that is missing).

    Raises
    ------
    DamagedPair
        Neither is a finite number of seconds >= 0.
    """
    timings = result.get("timings")
    seconds = timings.get("total", timings.get("wall")) if isinstance(timings, dict) else None
    if isinstance(seconds, int) and not isinstance(seconds, bool) and 0 <= seconds < 10**15:
        return float(seconds)
    if isinstance(seconds, float) and np.isfinite(seconds) and seconds >= 0:
        return seconds
    raise DamagedPair(where_what_fix(str(pair_dir / RESULT_FILE), "no timings.total (seconds) to write",
                                     RERUN_RESULT))
