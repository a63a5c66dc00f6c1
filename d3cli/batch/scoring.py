"""Scoring estimates: one pair right after it is computed, or folders of predictions.

Also the report rows (one per pair) that :mod:`d3cli.evaluation.report` summarises.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from tqdm import tqdm

from ..config import METHODS
from ..data import formats as io, layouts as datasets
from ..errors import D3Error, InputError, where_what_fix
from ..evaluation import metrics, pictures, report
from ..evaluation.html import write_report_html
from .fingerprint import object_map_path, package_versions
from .lock import acquire_lock, ensure_writable, release_lock
from .outputs import ERROR_MAP, RESULT_FILE, RUN_FILE, check_batch_files, check_pair_name
from .signals import signals_deferred

log = logging.getLogger(__name__)


def pair_row(pair, status: str, *, time_s: float | None = None, error: str = "", metrics=None) -> dict:
    row = {"pair": pair.name, "family": pair.family, "status": status, "time_s": time_s, "error": error}
    row.update(metrics or {})
    return row


def progress_bar(pairs: Sequence, enabled: bool, desc: str):
    """A tqdm bar on a terminal; else (``lines``) one line per pair; neither without stderr
    (None: closed where the program started) or when not ``enabled``."""
    stream = sys.stderr
    on_terminal = stream is not None and stream.isatty()
    bar = tqdm(pairs, desc=desc, unit="pair", disable=not (enabled and on_terminal))
    bar.lines = enabled and stream is not None and not on_terminal  # no terminal: one line per pair instead
    return bar


def progress_start(bar, pair) -> None:
    """Show the pair being computed in the bar."""
    if not bar.disable:
        bar.set_postfix_str(pair.name, refresh=True)


def progress_done(bar, row: dict) -> None:
    """Without a terminal: one line per finished pair (name, seconds, EPE when known).

    Written to stderr like the bar, so long jobs' logs show life.
    """
    if not getattr(bar, "lines", False):
        return
    bar.n_done = getattr(bar, "n_done", 0) + 1  # a disabled tqdm does not count
    parts = [f"[{bar.n_done}/{bar.total}]", row["pair"], row["status"]]
    if isinstance(row.get("time_s"), (int, float)):
        parts.append(f"{row['time_s']:.2f} s")
    if isinstance(row.get("epe"), (int, float)):
        parts.append(f"EPE {row['epe']:.3f} px")
    if sys.stderr is not None:
        sys.stderr.write("  ".join(parts) + "\n")
        sys.stderr.flush()


def failed_row(pair, message: str, wall: float):
    log.debug("%s failed: %s", pair.name, message)
    row = pair_row(pair, "failed", time_s=wall, error=message)
    return row, {"pair": pair.name, "status": "failed", "wall_s": wall, "error": message}


def evaluate_pair(pair, left, right, disparity, pair_dir: Path) -> dict:
    """Metrics of one estimate: against ground truth when there is one, photometric always.

    Writes the error map ``pair_dir/error.png`` when the pair has ground truth.
    """
    shape = left.shape[:2]
    scores = {}
    gt, mask = datasets.load_ground_truth(pair, shape)
    if gt is not None:
        scores.update(metrics.disparity_errors(disparity, gt, mask=mask))
        object_map = _object_map(pair, gt.shape)
        noc_gt = _noc_ground_truth(pair, gt) if mask is not None else None
        scores.update(metrics.benchmark_metrics(disparity, gt, noc_mask=mask, noc_gt=noc_gt, object_map=object_map))
        # Name the pixels behind the _all and _noc figures (a NaN _noc = no mask file).
        scores["mask_all"] = f"{Path(pair.gt).name} > 0"
        scores["mask_noc"] = f"{Path(pair.nocc).name}" if mask is not None else ""
        pair_dir.mkdir(parents=True, exist_ok=True)
        io.write_image(pair_dir / ERROR_MAP, pictures.error_picture(disparity, gt, noc_mask=mask))
    scores.update(metrics.photometric_scores(io.to_grey(left), io.to_grey(right), disparity))
    return scores


def _noc_ground_truth(pair, gt):
    """KITTI's non-occluded ground truth (``disp_noc*``), whose own values the devkit scores
    on the non-occluded pixels; None for a mask file (Middlebury ``mask0nocc.png``...).

    Read like the pair's ground truth (``gt_scale``, ``gt_invalid``).  Where both maps
    have a value they agree but at a few pixels, so a median ratio off 1 means the two
    files were written with different scales.

    Raises
    ------
    InputError
        The two maps disagree in scale.
    """
    path = Path(pair.nocc)
    if not (path.name.lower().startswith("disp_noc") or path.parent.name.lower().startswith("disp_noc")):
        return None
    noc = io.read_disparity(path, scale=pair.gt_scale, invalid=pair.gt_invalid)
    with np.errstate(invalid="ignore"):
        both = np.isfinite(noc) & (noc > 0) & np.isfinite(gt) & (gt > 0)
    ratio = float(np.median(noc[both] / gt[both])) if both.any() else 1.0
    if not 0.99 <= ratio <= 1.01:
        raise InputError(where_what_fix(
            pair.name, f"non-occluded ground truth {path.name} holds {ratio:.3g} times the disparities of "
            f"{Path(pair.gt).name}", "write both with the same scale: gt_scale applies to both"))
    return noc


def _object_map(pair, shape):
    """KITTI 2015 ``obj_map.png`` beside the ground truth (0 = background), or None."""
    candidate = object_map_path(pair.gt)  # the file the resume fingerprint covers
    if candidate is None:
        return None
    obj = io.read_image(candidate)
    obj = obj if obj.ndim == 2 else obj[..., 0]
    return obj if obj.shape == tuple(shape) else None


def method_names(pred_dirs: Sequence[Path]) -> list[str]:
    """Column and folder names for prediction folders, unique and each one safe folder name.

    run.json's method (one of d3stereo's methods: any other value there is not trusted
    as a folder name) when no other folder has the same one, else the folder's name;
    folders of the same name take as many parent folder names as tell them apart
    (``exp1/out``, ``exp2/out`` -> ``exp1-out``, ``exp2-out``), the same folder given
    twice a number (``out``, ``out-2``).  Never a path: each report folder is
    ``-o/<name>``, so a name must not lead out of it, and at most :data:`MAX_NAME`
    characters (a longer tail keeps its end), so that it is a folder name every file
    system takes.
    """
    from_run = [_json_value(Path(folder) / RUN_FILE, "method") for folder in pred_dirs]
    from_run = [name if name in METHODS else None for name in from_run]
    parts = [Path(os.path.realpath(folder)).parts[1:] or ("predictions",) for folder in pred_dirs]
    names = []
    for index, name in enumerate(from_run):
        unique = name is not None and from_run.count(name) == 1
        names.append(name if unique else _distinct_tail(parts, index))
    return _numbered(names)


#: Longest report folder name ``method_names`` gives (file systems allow 255 bytes).
MAX_NAME = 100


def _distinct_tail(parts: Sequence[tuple[str, ...]], index: int) -> str:
    """The shortest tail of folder ``index``'s path that no other folder shares, as one name."""
    own = parts[index]
    others = [other for other in parts if other != own]  # the same folder twice is numbered instead
    for depth in range(1, len(own) + 1):
        if all(other[-depth:] != own[-depth:] for other in others):
            break
    return datasets.safe_name("-".join(own[-depth:]))[-MAX_NAME:].lstrip("-.") or "predictions"


def _numbered(names: list[str]) -> list[str]:
    """``names`` with a repeat numbered: ``out``, ``out-2`` (the same folder given twice)."""
    seen: set[str] = set()
    result = []
    for name in names:
        candidate, number = name, 1
        while candidate in seen:
            number += 1
            candidate = f"{name}-{number}"
        seen.add(candidate)
        result.append(candidate)
    return result


#: Prediction file suffixes that ``eval`` reads, in the order they are looked for.
PREDICTION_SUFFIXES = (".pfm", ".png", ".npy")


def find_prediction(pred_dir: str | os.PathLike, pair_name: str) -> Path | None:
    """A pair's prediction in a folder: ``<pair>/disp.{pfm,png,npy}`` or flat ``<pair>.{pfm,png,npy}``."""
    pred_dir = Path(pred_dir)
    for suffix in PREDICTION_SUFFIXES:
        for candidate in (pred_dir / pair_name / f"disp{suffix}", pred_dir / f"{pair_name}{suffix}"):
            if candidate.is_file() or io.special_file_kind(candidate) is not None:
                return candidate  # a FIFO or device: refused by its reader, naming it
    return None


def read_prediction(path: str | os.PathLike):
    """Disparity (px, float, inf = no estimate) of a prediction file.

    PFM: float values, non-finite = no estimate; PNG: KITTI uint16, value / 256,
    0 = no estimate; NPY: float values, non-finite = no estimate (as PFM).
    """
    path = Path(path)
    if path.suffix.lower() == ".png":
        return io.read_disparity(path, scale=256.0, invalid="zero")
    return io.read_disparity(path)


def evaluate_predictions(
    pred_dir: str | os.PathLike,
    pairs: Iterable,
    *,
    report_dir: str | os.PathLike,
    progress: bool = True,
) -> list[dict]:
    """Score each pair's prediction in ``pred_dir`` (see :func:`find_prediction`).

    Error maps go to ``report_dir/<pair>/error.png``; nothing is written into
    ``pred_dir``.  A pair without a prediction, or whose prediction cannot be scored,
    becomes a ``failed`` row naming the problem.
    """
    pred_dir = Path(pred_dir)
    report_dir = Path(report_dir)
    rows = []
    bar = progress_bar(list(pairs), progress, pred_dir.name)
    for pair in bar:
        progress_start(bar, pair)
        t0 = time.perf_counter()
        pred_path = find_prediction(pred_dir, pair.name)
        try:
            check_pair_name(pair.name, report_dir)  # its error map's folder would take a report's name
            if pred_path is None:
                raise InputError(where_what_fix(str(pred_dir / pair.name), "no prediction for this pair",
                                                "give <pair>/disp.{pfm,png,npy} or <pair>.{pfm,png,npy}"))
            left, right = _load_images(pair)
            disparity = read_prediction(pred_path)
            scores = evaluate_pair(pair, left, right, disparity, report_dir / pair.name)
        except D3Error as exc:
            rows.append(failed_row(pair, str(exc), time.perf_counter() - t0)[0])
            continue
        except Exception as exc:  # noqa: BLE001 - one broken pair must not end the evaluation
            log.debug("%s: unexpected error", pair.name, exc_info=True)
            rows.append(failed_row(pair, f"{pair.name}: {type(exc).__name__}: {exc}", time.perf_counter() - t0)[0])
            continue
        rows.append(pair_row(pair, "ok", time_s=_stored_time(pred_path.parent), metrics=scores))
        progress_done(bar, rows[-1])
    return rows


def _load_images(pair):
    return datasets.load_pair_images(pair)


def _stored_time(pair_dir: Path) -> float | None:
    """The wall time recorded by the run that made a prediction, if any."""
    timings = _json_value(pair_dir / RESULT_FILE, "timings")
    return timings.get("wall") if isinstance(timings, dict) else None


def _json_value(path: Path, key: str):
    """``key`` of the JSON object in ``path``, or None; only a regular file is opened (a
    FIFO named run.json in a prediction folder would block the evaluation)."""
    if not path.is_file():  # is_file: a regular file (or a link to one), never a FIFO
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data.get(key) if isinstance(data, dict) else None


def common_pairs(pred_dirs: Sequence[Path], pairs: Sequence) -> tuple[list, list[str]]:
    """The pairs with a prediction in every folder, and the names of the others."""
    kept, dropped = [], []
    for pair in pairs:
        (kept if all(find_prediction(f, pair.name) for f in pred_dirs) else dropped).append(pair)
    return kept, [pair.name for pair in dropped]


#: The fix of every report folder that overlaps the inputs.
_OVERLAP_FIX = "give -o a new folder that holds no input and lies inside none (predictions and ground truth are only read)"


def check_report_folder(out: Path, pred_dirs: Sequence[Path], pairs: Sequence) -> None:
    """Refuse a report folder that is, holds or lies inside a prediction folder or a
    folder of a pair's files (images, ground truth), compared by real path.

    The reports (``summary.md``, ``metrics.csv``, ``<pair>/error.png``...) would
    otherwise overwrite or join the user's data.  A new folder beside the pairs, inside
    the dataset's root, is fine: no input lies in it.

    Raises
    ------
    InputError
        Naming ``out``, the folder it overlaps and the fix.
    """
    root = Path(os.path.realpath(out))
    inputs = [(f"the prediction folder {folder}", Path(os.path.realpath(folder))) for folder in pred_dirs]
    for pair in pairs:
        files = [getattr(pair, key, None) for key in ("left", "right", "gt", "nocc", "calib")]
        real = [Path(os.path.realpath(f)) for f in files if f is not None]
        # A broken pair's left/right is its folder itself (Pair.error), not a file in it.
        for folder in sorted({path if path.is_dir() else path.parent for path in real}):
            inputs.append((f"the folder of pair {pair.name}'s files {folder}", folder))
    for what, folder in inputs:
        relation = ("is" if root == folder else "is inside" if folder in root.parents
                    else "holds" if root in folder.parents else None)
        if relation is not None:
            raise InputError(where_what_fix(str(out), f"the report folder {relation} {what}", _OVERLAP_FIX))


def evaluate_folders(
    pred_dirs: Sequence[str | os.PathLike],
    pairs: Sequence,
    *,
    out_dir: str | os.PathLike,
    progress: bool = True,
    break_lock: bool = False,
) -> dict:
    """Score one or more prediction folders against the same pairs and write the reports.

    Only the pairs that have a prediction in *every* folder are compared; the others are
    logged as a warning and listed under ``not_compared``.  Everything is written under
    ``out_dir`` (never into a prediction folder): one folder gives ``metrics.csv``,
    ``summary.json``, ``summary.md``, ``<pair>/error.png`` in ``out_dir``; several give
    each folder's reports in ``out_dir/<method>/`` and the side-by-side table
    ``out_dir/comparison.md``.  Each folder written is locked as a run's ``-o`` folder is
    (``break_lock``: ``--break-lock``), so no run, shard or other eval writes there
    meanwhile; a pair named like a report file fails alone (:func:`check_pair_name`).

    Returns
    -------
    dict
        ``results`` (method -> rows), ``summaries`` (method -> summary dict),
        ``comparison`` (Markdown text or None), ``comparison_path``, ``n_failed``,
        ``n_rows``, ``out_dir``, ``not_compared`` (pair names).

    Raises
    ------
    InputError
        A prediction folder does not exist, ``out_dir`` overlaps a prediction or
        ground-truth folder (:func:`check_report_folder`), or no pair has a prediction
        everywhere.
    OutputError
        Another d3stereo command (a run, a shard, an eval) writes into a report folder, or
        left a lock there that may still be in use (:func:`d3cli.batch.lock.acquire_lock`;
        ``break_lock`` takes over the latter); a report file's name is a folder
        (:func:`d3cli.batch.outputs.check_batch_files`).
    """
    pred_dirs = [Path(p) for p in pred_dirs]
    out = Path(out_dir)
    for folder in pred_dirs:
        if not folder.is_dir():
            raise InputError(where_what_fix(str(folder), "prediction folder not found",
                                            "give the -o folder of a `d3stereo run` or a folder of <pair>.png"))
    check_report_folder(out, pred_dirs, pairs)
    compared, not_compared = common_pairs(pred_dirs, pairs)
    if not compared:
        raise InputError(where_what_fix(", ".join(map(str, pred_dirs)), "no pair has a prediction in every folder",
                                        "check --gt and the prediction file names (<pair>/disp.pfm or <pair>.png)"))
    if not_compared:
        log.warning("not compared (no prediction in every folder): %s", ", ".join(not_compared))
    names = method_names(pred_dirs)
    targets = [out] if len(pred_dirs) == 1 else [out / name for name in names]
    for target in dict.fromkeys([out, *targets]):
        check_batch_files(target)  # before any pair is scored
    ensure_writable(out)
    # The lock of every folder written (as `d3stereo run` takes it): no run, shard or
    # other eval writes there meanwhile.  Taken whole, a Ctrl-C meanwhile delivered after.
    locks = []
    try:
        with signals_deferred():
            for folder in dict.fromkeys([out, *targets]):
                locks.append(acquire_lock(ensure_writable(folder), command="d3stereo eval", break_lock=break_lock))
        results, summaries, comparison, comparison_path = _evaluate_locked(
            pred_dirs, names, targets, compared, not_compared, out=out, progress=progress)
    finally:
        for lock in reversed(locks):
            release_lock(lock)
    return {
        "results": results,
        "summaries": summaries,
        "comparison": comparison,
        "comparison_path": comparison_path,
        "n_failed": sum(r["status"] == "failed" for rows in results.values() for r in rows),
        "n_rows": sum(len(rows) for rows in results.values()),
        "out_dir": out,
        "not_compared": not_compared,
    }


def _evaluate_locked(pred_dirs, names, targets, compared, not_compared, *, out: Path, progress: bool):
    """The body of :func:`evaluate_folders`, run while holding the report folders' locks:
    (results, summaries, comparison, comparison_path)."""
    results, summaries = {}, {}
    for folder, name, target in zip(pred_dirs, names, targets):
        rows = evaluate_predictions(folder, compared, report_dir=target, progress=progress)
        report.write_summary(target, rows, method=name,
                             extra={"predictions": str(folder), "not_compared": not_compared})
        write_report_html(target, rows, title=f"d3stereo eval: {name}",
                          config={"predictions": str(folder), "not_compared": not_compared},
                          versions=package_versions())
        results[name] = rows
        summaries[name] = report.summarize(rows)
    comparison = comparison_path = None
    if len(pred_dirs) > 1:
        comparison = report.side_by_side(results)
        comparison_path = out / "comparison.md"
        io.atomic_write(comparison_path, lambda tmp: Path(tmp).write_text(report.readable(comparison) + "\n",
                                                                              encoding="utf-8"))
    return results, summaries, comparison, comparison_path
