"""Batch runs and batch evaluation: many pairs in, one output folder out.

Layout of an output folder ``OUT``::

    OUT/run.json                 resolved config, versions, backend, per-pair status
    OUT/<pair>/disp.pfm          float32 disparity, inf = invalid
    OUT/<pair>/disp.png          KITTI uint16 (disparity * 256, 0 = invalid)
    OUT/<pair>/disp_color.png    colour coded over [0, max disparity]
    OUT/<pair>/valid.png         255 where the method decided the disparity itself
    OUT/<pair>/error.png         error map (only with --eval and ground truth)
    OUT/<pair>/result.json       timings, metrics, info; written LAST
    OUT/metrics.csv, summary.json, summary.md   (only with --eval)

Every file is written atomically, and ``result.json`` last: its presence means the
pair is complete, so an interrupted batch resumes where it stopped.  A pair whose
stored ``result.json`` was made by another method, configuration or disparity
override is computed again.

One failing pair never stops a batch: its error is recorded (``run.json``, the
summary) and the next pair runs.  Two things end a batch early:

* Ctrl-C (KeyboardInterrupt): the pair in progress leaves no file behind (its temporary
  files and any of its outputs already renamed are removed; ``result.json`` is written
  last, so it never marks a half pair complete), ``run.json`` records the interruption,
  and :class:`BatchInterrupted` says how many pairs are done.  Rerunning the same command
  resumes and gives byte-identical per-pair files.
* A full disk (ENOSPC/EDQUOT on a write): every later pair would fail the same way, so
  the OutputError ends the batch; finished pairs stay complete.

Only one run writes into a folder at a time: ``OUT/.d3stereo.lock`` (created with
O_EXCL, holding pid and host) makes a second run fail with a clear error; a lock left by
a run that no longer exists on this host is taken over with a warning.

Before a pair is computed its estimated peak memory is checked
(:func:`d3cli.resources.check_memory`; a per-pair failure), and after it the map is
checked for the symptoms of an unrectified or swapped pair
(:func:`d3cli.diagnostics.suspicious_result`; warnings in ``result.json``, ``run.json``
and the summary).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import socket
import sys
import tempfile
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable, Sequence

from . import __version__
from .config import Config
from .errors import D3Error, InputError, OutputError, where_what_fix

log = logging.getLogger(__name__)

#: The per-pair files of a complete result, besides result.json.
OUTPUT_FILES = ("disp.pfm", "disp.png", "disp_color.png", "valid.png")
RESULT_FILE = "result.json"
ERROR_MAP = "error.png"
CLOUD_FILE = "cloud.ply"  # only with --pointcloud
RUN_FILE = "run.json"
LOCK_FILE = ".d3stereo.lock"
#: A lock file that cannot be read is taken as stale only when older than this (seconds):
#: a run that has just created it may not have written its pid yet.
LOCK_GRACE_S = 5.0


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C ended a batch; finished pairs are complete, the pair in progress left nothing.

    A KeyboardInterrupt, so code that does not know it still stops.

    Attributes
    ----------
    n_done : int
        Pairs complete in the output folder (computed now or skipped as complete).
    n_total : int
        Pairs of the batch.
    run_json : Path
        ``run.json`` recording the interruption.
    """

    def __init__(self, n_done: int, n_total: int, run_json: Path):
        super().__init__(f"Interrupted: {n_done} of {n_total} pairs done; rerun the same command to resume")
        self.n_done, self.n_total, self.run_json = n_done, n_total, run_json

    def __str__(self) -> str:
        return self.args[0]


@dataclass
class BatchResult:
    """What a batch did.

    Attributes
    ----------
    out_dir : Path
        The output folder.
    rows : list of dict
        One row per pair for :mod:`d3cli.report` (``pair``, ``family``, ``status``,
        metric keys, ``time_s``, ``error``).
    n_failed : int
        Number of pairs that failed.
    run_json : Path
        Path of ``run.json``.
    summary : dict or None
        :func:`d3cli.report.summarize` of the rows when evaluating, else None.
    """

    out_dir: Path
    rows: list = field(default_factory=list)
    n_failed: int = 0
    run_json: Path | None = None
    summary: dict | None = None

    @property
    def n_pairs(self) -> int:
        return len(self.rows)

    @property
    def failures(self) -> list[tuple[str, str]]:
        """(pair, error message) of each failed pair."""
        return [(r["pair"], r.get("error", "")) for r in self.rows if r["status"] == "failed"]


# ----------------------------------------------------------------------------- helpers
def ensure_writable(out_dir: str | os.PathLike) -> Path:
    """Create ``out_dir`` (with parents) and prove it is writable with a probe file.

    Raises
    ------
    OutputError
        Naming the folder, when it cannot be created or written.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".d3stereo-probe-")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise OutputError(
            where_what_fix(str(out), f"cannot write to the output folder ({reason})",
                           "choose another folder with -o or fix its permissions")
        ) from None
    return out


def _pid_alive(pid: int) -> bool:
    """True when process ``pid`` exists on this host (or when that cannot be told)."""
    if pid <= 0:
        return False
    if os.name == "nt":  # os.kill(pid, 0) would terminate the process there
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: it exists, owned by someone else
        return True
    return True


def _read_lock(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("pid"), int):
        return None
    return data


def _lock_is_stale(path: Path, holder: dict | None) -> bool:
    if holder is None:
        try:
            age = time.time() - path.stat().st_mtime
        except OSError:
            return True  # gone already
        return age > LOCK_GRACE_S
    if holder.get("host") != socket.gethostname():
        return False  # another machine's process cannot be checked from here
    return not _pid_alive(holder["pid"])


def acquire_lock(out: Path) -> Path:
    """Create ``out/.d3stereo.lock`` (O_EXCL) holding this process's pid and host.

    A lock whose process is gone (same host) or that is unreadable and older than
    :data:`LOCK_GRACE_S` is taken over with a warning.

    Returns
    -------
    Path
        The lock file, for :func:`release_lock`.

    Raises
    ------
    OutputError
        ``OUT: another d3stereo run (pid N) is writing here; wait for it or use another
        -o folder``, or when the lock cannot be created.
    """
    path = out / LOCK_FILE
    for attempt in range(2):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = _read_lock(path)
            if attempt == 0 and _lock_is_stale(path, holder):
                who = f"pid {holder['pid']} on {holder.get('host')}" if holder else "an unreadable lock"
                log.warning("%s: taking over the stale lock of a run that is gone (%s)", path, who)
                path.unlink(missing_ok=True)
                continue
            pid = holder["pid"] if holder else "unknown"
            host = "" if holder is None or holder.get("host") == socket.gethostname() else f" on {holder.get('host')}"
            raise OutputError(where_what_fix(str(out), f"another d3stereo run (pid {pid}{host}) is writing here",
                                             "wait for it or use another -o folder")) from None
        except OSError as exc:
            raise OutputError(where_what_fix(str(path), f"cannot create the lock file ({exc.strerror or exc})",
                                             "choose another folder with -o or fix its permissions")) from None
        holder = {"pid": os.getpid(), "host": socket.gethostname(),
                  "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(holder, fh)
        return path
    raise OutputError(where_what_fix(str(out), "another d3stereo run took the lock over at the same moment",
                                     "wait for it or use another -o folder"))


def release_lock(path: Path) -> None:
    """Remove the lock file when it is still this process's (not one taken over since)."""
    holder = _read_lock(path)
    if holder is not None and holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
        try:
            path.unlink()
        except OSError as exc:
            log.warning("%s: could not remove the lock file (%s); delete it by hand", path, exc)


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` as indented JSON (NaN/inf as null), atomically."""
    from .io import atomic_write
    from .report import _jsonable  # the one JSON-cleaning rule shared by every report file

    text = json.dumps(_jsonable(data), indent=2, allow_nan=False) + "\n"
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


#: Config sections that shape each baseline's result; d3stereo uses all but run and sgbm.
_BASELINE_SECTIONS = {"sgbm": ("sgbm",), "pt-sgm": ("sgbm", "pt")}


def settings_fingerprint(cfg: Config, method: str, max_disparity: int | None) -> str:
    """Short hash of what determines a pair's result: method, its config sections, range.

    The backend is left out on purpose: CPU and CUDA give the same result.
    """
    sections = cfg.to_dict()
    del sections["run"]  # method and max_disparity are hashed as resolved; backend does not matter
    if method in _BASELINE_SECTIONS:
        sections = {name: sections[name] for name in _BASELINE_SECTIONS[method]}
    else:
        del sections["sgbm"]
    blob = json.dumps([method, sections, max_disparity], sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def read_result(pair_dir: Path) -> dict | None:
    """The stored result of a complete pair folder, or None when incomplete."""
    result_path = pair_dir / RESULT_FILE
    if not result_path.is_file() or not all((pair_dir / f).is_file() for f in OUTPUT_FILES):
        return None
    try:
        return json.loads(result_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        log.warning("%s: unreadable, computing the pair again", result_path)
        return None


def package_versions() -> dict:
    """Versions of d3stereo and the libraries that shape its results."""
    import cv2
    import numba
    import numpy
    import skimage

    return {
        "d3stereo": __version__,
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "cv2": cv2.__version__,
        "skimage": skimage.__version__,
    }


def _row(pair, status: str, *, time_s: float | None = None, error: str = "", metrics=None) -> dict:
    row = {"pair": pair.name, "family": pair.family, "status": status, "time_s": time_s, "error": error}
    row.update(metrics or {})
    return row


def _progress(pairs: Sequence, enabled: bool, desc: str):
    from tqdm import tqdm

    return tqdm(pairs, desc=desc, unit="pair", disable=not (enabled and sys.stderr.isatty()))


# ----------------------------------------------------------------------------- one pair
def _evaluate(pair, left, right, disparity, pair_dir: Path) -> dict:
    """Metrics of one estimate: against ground truth when there is one, photometric always.

    Writes the error map ``pair_dir/error.png`` when the pair has ground truth.
    """
    from . import datasets, io, metrics

    shape = left.shape[:2]
    scores = {}
    gt, mask = datasets.load_ground_truth(pair, shape)
    if gt is not None:
        scores.update(metrics.disparity_errors(disparity, gt, mask=mask))
        pair_dir.mkdir(parents=True, exist_ok=True)
        io.write_image(pair_dir / ERROR_MAP, metrics.error_map(disparity, gt, mask=mask))
    scores.update(metrics.photometric_scores(io.to_grey(left), io.to_grey(right), disparity))
    return scores


def _run_pair(pair, pair_dir: Path, *, cfg, method, evaluate, max_disparity, fingerprint) -> dict:
    """Compute, write and (optionally) score one pair; returns the stored result dict."""
    from . import baselines, datasets, io

    from . import diagnostics, resources

    t0 = time.perf_counter()
    left, right = datasets.load_pair_images(pair)
    height, width = left.shape[:2]
    dmax = datasets.resolve_max_disparity(pair, width, override=max_disparity)
    resources.check_memory((height, width), dmax, cfg, method=method, where=pair.name)
    result = baselines.compute_pair(method, cfg, left, right, max_disparity=dmax)
    result.warnings.extend(diagnostics.suspicious_result(result, dmax))
    for text in result.warnings:
        log.warning("%s: %s", pair.name, text)
    try:
        # An old result.json beside new, maybe half-written outputs would mark them complete;
        # an old error map would describe another estimate.
        _remove_pair_files(pair_dir)
        io.write_disparity_outputs(pair_dir, result.disparity, result.valid, vmax=dmax)
        scores = _evaluate(pair, left, right, result.disparity, pair_dir) if evaluate else None
    except BaseException:  # Ctrl-C, a full disk, a broken writer: no half pair stays behind
        _remove_pair_files(pair_dir, remove_folder=True)
        raise
    wall = time.perf_counter() - t0
    stored = {
        "pair": pair.name,
        "family": pair.family,
        "method": method,
        "settings": fingerprint,
        "inputs": {"left": pair.left, "right": pair.right, "gt": pair.gt},
        "shape": [height, width],
        "max_disparity": dmax,
        "color_range": [0, dmax],
        "valid_share": float(result.valid.mean()) if result.valid.size else 0.0,
        "timings": {**result.timings, "wall": wall},
        "metrics": scores,
        "info": result.info,
        "warnings": list(result.warnings),
    }
    try:
        write_json(pair_dir / RESULT_FILE, stored)  # last: marks the pair complete
    except BaseException:
        _remove_pair_files(pair_dir, remove_folder=True)
        raise
    return stored


def _remove_pair_files(pair_dir: Path, *, remove_folder: bool = False) -> None:
    """Delete a pair's outputs, result.json, error map and leftover temporary files.

    Used before a pair is written (stale files of an earlier run, temporary files of a
    killed one) and when writing it failed or was interrupted.  Other files stay.
    """
    if not pair_dir.is_dir():
        return
    names = (*OUTPUT_FILES, RESULT_FILE, ERROR_MAP, CLOUD_FILE)
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


def _write_cloud(pair, pair_dir: Path, stored: dict, cfg) -> dict:
    """Write ``cloud.ply`` of a complete pair from its stored outputs; returns ``stored``.

    Reads disp.pfm and valid.png back, so a rerun with ``--pointcloud`` adds clouds to
    pairs computed earlier without computing them again.  Without a camera the pair gets
    a warning in result.json instead.
    """
    from . import datasets, io
    from .pointcloud import camera_from, save_pair_cloud

    left, _ = datasets.load_pair_images(pair)
    calib = io.read_calib(pair.calib) if pair.calib is not None else None
    camera = camera_from(calib, cfg, left.shape[:2])
    if camera is None:
        text = ("no cloud.ply: focal length or baseline unknown; add calib.txt to the pair "
                "or set camera.f and camera.baseline")
        if text not in stored.get("warnings", []):
            log.warning("%s: %s", pair.name, text)
            stored = {**stored, "warnings": [*stored.get("warnings", []), text]}
            write_json(pair_dir / RESULT_FILE, stored)
        return stored
    disparity = io.read_pfm(pair_dir / "disp.pfm")
    valid = io.read_mask(pair_dir / "valid.png")
    n_points = save_pair_cloud(pair_dir / CLOUD_FILE, disparity, valid, left, camera)
    log.info("%s: cloud.ply with %d points", pair.name, n_points)
    return stored


def _reuse_pair(pair, pair_dir: Path, stored: dict, *, evaluate) -> dict:
    """A complete earlier result; scored now from disp.pfm if it was stored unscored."""
    if evaluate and not stored.get("metrics"):
        from . import datasets, io

        left, right = datasets.load_pair_images(pair)
        disparity = io.read_pfm(pair_dir / "disp.pfm")
        stored = {**stored, "metrics": _evaluate(pair, left, right, disparity, pair_dir)}
        write_json(pair_dir / RESULT_FILE, stored)
    return stored


# ----------------------------------------------------------------------------- batches
def run_batch(
    pairs: Sequence,
    out_dir: str | os.PathLike,
    *,
    cfg: Config,
    method: str,
    evaluate: bool = False,
    overwrite: bool = False,
    max_disparity: int | None = None,
    progress: bool = True,
    config_source: str | None = None,
    pointcloud: bool = False,
) -> BatchResult:
    """Run ``method`` on every pair, writing ``out_dir/<pair>/...`` and ``out_dir/run.json``.

    Parameters
    ----------
    pairs : sequence of d3cli.datasets.Pair
        The pairs, e.g. from :func:`d3cli.datasets.discover`.
    out_dir : path-like
        Output folder; created when missing.
    cfg : Config, keyword-only
        Resolved configuration (stored in run.json).
    method : {"d3stereo", "sgbm", "pt-sgm"}, keyword-only
    evaluate : bool, keyword-only
        Score each result: against ground truth where the pair has it (EPE, PEP,
        density, ``error.png``), photometric scores always; writes the summary files.
    overwrite : bool, keyword-only
        Compute pairs again even when their outputs are complete.
    max_disparity : int, optional, keyword-only
        Override of every pair's disparity range, pixels.
    progress : bool, keyword-only
        Show a tqdm bar (only on a terminal).
    config_source : str, optional, keyword-only
        Where the configuration came from, recorded in run.json.
    pointcloud : bool, keyword-only
        Also write ``cloud.ply`` per pair (decided pixels, metres, left-camera frame) from
        the pair's calib.txt or the ``camera`` config section; pairs without a focal length
        and baseline get a warning instead.

    Returns
    -------
    BatchResult

    Raises
    ------
    OutputError
        When ``out_dir`` cannot be written (checked before any pair runs).
    BackendUnavailable
        When ``cfg.run.backend`` is ``cuda`` and CUDA cannot be used (checked up front).
    """
    out = ensure_writable(out_dir)
    if method != "sgbm" and cfg.run.backend == "cuda":
        from .kernels import get_backend

        get_backend("cuda")  # BackendUnavailable now, not once per pair
    lock = acquire_lock(out)
    try:
        return _locked_batch(list(pairs), out, cfg=cfg, method=method, evaluate=evaluate, overwrite=overwrite,
                             max_disparity=max_disparity, progress=progress, config_source=config_source,
                             pointcloud=pointcloud)
    finally:
        release_lock(lock)


def _locked_batch(pairs: list, out: Path, *, cfg, method, evaluate, overwrite, max_disparity, progress,
                  config_source, pointcloud) -> BatchResult:
    """The body of :func:`run_batch`, run while holding the output folder's lock."""
    from .io import is_disk_full

    fingerprint = settings_fingerprint(cfg, method, max_disparity)
    batch = BatchResult(out_dir=out, run_json=out / RUN_FILE)
    records = []
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    meta = dict(cfg=cfg, method=method, max_disparity=max_disparity, started=started,
                config_source=config_source, n_total=len(pairs))
    current = None
    try:
        for current in _progress(pairs, progress, method):
            row, record = _batch_pair(current, out / current.name, cfg=cfg, method=method, evaluate=evaluate,
                                      overwrite=overwrite, max_disparity=max_disparity,
                                      fingerprint=fingerprint, pointcloud=pointcloud)
            batch.rows.append(row)
            records.append(record)
        current = None
    except KeyboardInterrupt:
        _write_run_json(batch, records, **meta, interrupted=True, stopped_at=current and current.name,
                        stop_reason="interrupted (Ctrl-C / SIGINT)")
        n_done = sum(r["status"] in ("ok", "skipped") for r in records)
        raise BatchInterrupted(n_done, len(pairs), batch.run_json) from None
    except OutputError as exc:
        if not is_disk_full(exc):
            raise
        row, record = _failed(current, str(exc), 0.0)
        batch.rows.append(row)
        records.append(record)
        try:  # the disk is full: this may well fail too
            _write_run_json(batch, records, **meta, interrupted=True, stopped_at=current.name,
                            stop_reason=str(exc))
        except OutputError as again:
            log.warning("run.json not written: %s", again)
        raise
    batch.n_failed = sum(r["status"] == "failed" for r in batch.rows)
    if evaluate:
        from . import report

        report.write_summary(out, batch.rows, method=method, extra={"settings": fingerprint})
        batch.summary = report.summarize(batch.rows)
    _write_run_json(batch, records, **meta, interrupted=False)
    return batch


def _batch_pair(pair, pair_dir: Path, *, cfg, method, evaluate, overwrite, max_disparity, fingerprint,
                pointcloud=False):
    """One pair of a batch -> (report row, run.json record).

    Raises only KeyboardInterrupt and the OutputError of a full disk; any other failure
    becomes a ``failed`` row.
    """
    t0 = time.perf_counter()
    reused = False
    try:
        stored = None if overwrite else read_result(pair_dir)
        if stored is not None and stored.get("settings") == fingerprint:
            log.info("%s: complete, skipped (use --overwrite to compute it again)", pair.name)
            stored = _reuse_pair(pair, pair_dir, stored, evaluate=evaluate)
            reused = True
        else:
            stored = _run_pair(pair, pair_dir, cfg=cfg, method=method, evaluate=evaluate,
                               max_disparity=max_disparity, fingerprint=fingerprint)
        if pointcloud and not (pair_dir / CLOUD_FILE).is_file():
            stored = _write_cloud(pair, pair_dir, stored, cfg)
    except D3Error as exc:
        from .io import is_disk_full

        if is_disk_full(exc):
            raise  # every later pair would fail the same way: the batch stops
        return _failed(pair, str(exc), time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - one broken pair must not end the batch
        log.debug("%s: unexpected error", pair.name, exc_info=True)
        return _failed(pair, f"{pair.name}: {type(exc).__name__}: {exc}", time.perf_counter() - t0)
    wall = stored.get("timings", {}).get("wall")
    row = _row(pair, "ok", time_s=wall, metrics=stored.get("metrics"))
    if stored.get("warnings"):
        row["warnings"] = list(stored["warnings"])
    record = {"pair": pair.name, "status": "skipped" if reused else "ok", "wall_s": wall,
              "max_disparity": stored.get("max_disparity"), "backend": stored.get("info", {}).get("backend"),
              "warnings": stored.get("warnings", [])}
    if stored.get("info", {}).get("pt") is not None:
        record["pt"] = stored["info"]["pt"]  # the fitted road model and its inlier share
    return row, record


def _failed(pair, message: str, wall: float):
    log.debug("%s failed: %s", pair.name, message)
    row = _row(pair, "failed", time_s=wall, error=message)
    return row, {"pair": pair.name, "status": "failed", "wall_s": wall, "error": message}


def _write_run_json(batch: BatchResult, records, *, cfg, method, max_disparity, started,
                    config_source, interrupted, n_total=None, stopped_at=None, stop_reason=None) -> None:
    failed = [{"pair": r["pair"], "error": r["error"]} for r in records if r["status"] == "failed"]
    data = {
        "d3stereo": __version__,
        "started": started,
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "interrupted": interrupted,
        "method": method,
        "backend": cfg.run.backend,
        "backends_used": sorted({r["backend"] for r in records if r.get("backend")}),
        "max_disparity_override": max_disparity,
        "config_source": config_source,
        "config": cfg.to_dict(),
        "versions": package_versions(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "n_pairs": len(records),
        "n_total": len(records) if n_total is None else n_total,
        "stopped_at": stopped_at,
        "stop_reason": stop_reason,
        "n_failed": len(failed),
        "pairs": records,
        "failed": failed,
    }
    write_json(batch.run_json, data)


# ----------------------------------------------------------------------------- evaluation
def method_names(pred_dirs: Sequence[Path]) -> list[str]:
    """Column names for prediction folders: run.json's method when unique, else the folder name."""
    from_run = []
    for folder in pred_dirs:
        try:
            from_run.append(json.loads((Path(folder) / RUN_FILE).read_text(encoding="utf-8")).get("method"))
        except (OSError, ValueError, AttributeError):
            from_run.append(None)
    names = []
    for folder, name in zip(pred_dirs, from_run):
        unique = name and from_run.count(name) == 1
        names.append(name if unique else Path(folder).resolve().name)
    if len(set(names)) < len(names):  # same folder names: fall back to the full paths
        names = [str(Path(f)) for f in pred_dirs]
    return names


def evaluate_predictions(
    pred_dir: str | os.PathLike,
    pairs: Iterable,
    *,
    report_dir: str | os.PathLike | None = None,
    progress: bool = True,
) -> list[dict]:
    """Score ``pred_dir/<pair>/disp.pfm`` for each pair; rows for :mod:`d3cli.report`.

    Error maps go to ``report_dir/<pair>/error.png`` (default: beside the prediction).
    A pair without a prediction, or whose prediction cannot be scored, becomes a
    ``failed`` row naming the problem.
    """
    from . import io

    pred_dir = Path(pred_dir)
    report_dir = Path(report_dir) if report_dir is not None else pred_dir
    rows = []
    for pair in _progress(list(pairs), progress, pred_dir.name):
        t0 = time.perf_counter()
        pred_path = pred_dir / pair.name / "disp.pfm"
        try:
            if not pred_path.is_file():
                raise InputError(where_what_fix(str(pred_path), "no prediction for this pair",
                                                "run `d3stereo run` on the pair or check --gt"))
            left, right = _load_images(pair)
            disparity = io.read_pfm(pred_path)
            scores = _evaluate(pair, left, right, disparity, report_dir / pair.name)
        except D3Error as exc:
            rows.append(_failed(pair, str(exc), time.perf_counter() - t0)[0])
            continue
        except Exception as exc:  # noqa: BLE001 - one broken pair must not end the evaluation
            log.debug("%s: unexpected error", pair.name, exc_info=True)
            rows.append(_failed(pair, f"{pair.name}: {type(exc).__name__}: {exc}", time.perf_counter() - t0)[0])
            continue
        rows.append(_row(pair, "ok", time_s=_stored_time(pred_dir / pair.name), metrics=scores))
    return rows


def _load_images(pair):
    from . import datasets

    return datasets.load_pair_images(pair)


def _stored_time(pair_dir: Path) -> float | None:
    """The wall time recorded by the run that made a prediction, if any."""
    try:
        return json.loads((pair_dir / RESULT_FILE).read_text(encoding="utf-8"))["timings"]["wall"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def evaluate_folders(
    pred_dirs: Sequence[str | os.PathLike],
    pairs: Sequence,
    *,
    out_dir: str | os.PathLike | None = None,
    progress: bool = True,
) -> dict:
    """Score one or more prediction folders against the same pairs and write the reports.

    One folder: ``metrics.csv``, ``summary.json``, ``summary.md`` and the error maps
    ``<pair>/error.png`` in ``out_dir`` (default: the prediction folder).  Several: each
    folder's reports go to ``out_dir/<method>/`` (default: the prediction folder itself)
    and the side-by-side table to ``out_dir/comparison.md`` (default: in the first
    prediction folder).

    Returns
    -------
    dict
        ``results`` (method -> rows), ``summaries`` (method -> summary dict),
        ``comparison`` (Markdown text or None), ``comparison_path``, ``n_failed``,
        ``n_rows``, ``out_dir``.
    """
    from . import report

    pred_dirs = [Path(p) for p in pred_dirs]
    for folder in pred_dirs:
        if not folder.is_dir():
            raise InputError(where_what_fix(str(folder), "prediction folder not found",
                                            "give the -o folder of a `d3stereo run`"))
    names = method_names(pred_dirs)
    out = Path(out_dir) if out_dir is not None else pred_dirs[0]
    ensure_writable(out)
    results, summaries = {}, {}
    for folder, name in zip(pred_dirs, names):
        if len(pred_dirs) == 1:
            target = out
        else:
            target = ensure_writable(out / name) if out_dir is not None else folder
        rows = evaluate_predictions(folder, pairs, report_dir=target, progress=progress)
        report.write_summary(target, rows, method=name, extra={"predictions": str(folder)})
        results[name] = rows
        summaries[name] = report.summarize(rows)
    comparison = comparison_path = None
    if len(pred_dirs) > 1:
        comparison = report.side_by_side(results)
        comparison_path = out / "comparison.md"
        from .io import atomic_write

        atomic_write(comparison_path, lambda tmp: Path(tmp).write_text(comparison + "\n", encoding="utf-8"))
    return {
        "results": results,
        "summaries": summaries,
        "comparison": comparison,
        "comparison_path": comparison_path,
        "n_failed": sum(r["status"] == "failed" for rows in results.values() for r in rows),
        "n_rows": sum(len(rows) for rows in results.values()),
        "out_dir": out,
    }
