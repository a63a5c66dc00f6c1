"""Running a method over many pairs into one output folder (``d3stereo run``).

The files a batch writes are described in :mod:`d3cli.batch.outputs`.  A pair whose
stored ``result.json`` is complete and was made with the same settings fingerprint
(:mod:`d3cli.batch.fingerprint`) is skipped, so an interrupted batch resumes where it
stopped.

One failing pair never stops a batch: its error is recorded (``run.json``, the
summary) and the next pair runs; an unexpected exception is reported as an internal
error naming the pair and its step (:mod:`d3cli.batch.steps`).  A pair is skipped as
complete only when its fingerprint matches and its files are as ``result.json``
recorded them (sizes, SHA-256); otherwise it is computed again, with a warning.  Two things end a batch early:

* Ctrl-C (KeyboardInterrupt): the pair in progress leaves no file behind (it is written
  into a staging folder renamed into place once complete, :mod:`d3cli.batch.staging`; a
  staging folder a killed run left is removed by the next run over the same pairs),
  ``run.json`` records the interruption,
  and :class:`BatchInterrupted` says how many pairs are done.  Rerunning the same command
  resumes and gives byte-identical per-pair files.
* A full disk (ENOSPC/EDQUOT on a write): every later pair would fail the same way, so
  the OutputError ends the batch; finished pairs stay complete.

Only one command writes into a folder at a time, or the shards of one batch together
(:mod:`d3cli.batch.lock`).  Before a pair is computed its estimated peak memory is
checked (:func:`d3cli.batch.resources.check_memory`; a per-pair failure), and after it the
map is checked for the symptoms of an unrectified or swapped pair
(:func:`d3cli.evaluation.diagnostics.suspicious_result`; warnings in ``result.json``,
``run.json`` and the summary).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import os
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Sequence

from ..config import Config, method_spec, output_groups
from ..data import formats as io, layouts as datasets
from ..errors import D3Error, InputError, OutputError, Terminated, interrupt_behind, plural
from ..evaluation import diagnostics, report
from ..road.outputs import DEFECTS_CSV, write_defects_csv
from ..survey import survey_map
from . import resources
from .scoring import evaluate_pair, failed_row, pair_row, progress_bar, progress_done, progress_start
from .device import device_activity
from .executors import make_executor, select_shard
from .extras import write_extras
from .fingerprint import feature_files, package_versions, pair_fingerprint, settings_fingerprint
from .lock import acquire_lock, ensure_writable, release_lock
from .dispatch import compute_pair
from ..evaluation.html import write_report_html
from .records import BatchResult, record_complete, write_run_json
from .signals import (exit_status, interrupts_unwrapped, mark_terminated, restore_handlers, signal_name,
                      signals_deferred, signals_held, sigterm_as_interrupt)
from .staging import changed_files, clean_leftovers, discard, named_as_target, new_staging, publish
from .steps import internal_message, step
from .outputs import (
    ERROR_MAP,
    OVERLAY_FILE,
    PAIR_FILES,
    PANEL_FILE,
    RUN_FILE,
    add_missing_outputs,
    check_output_folder,
    check_pair_name,
    clipped_warning,
    read_result,
    is_our_summary,
    remove_ours,
    remove_pair_files,
    remove_stale_summaries,
    write_disparity_outputs,
    write_panel,
    write_result,
)

log = logging.getLogger(__name__)


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

    def __init__(self, n_done: int, n_total: int, run_json: Path, *, terminated: bool = False,
                 stopped_by: str = "SIGTERM"):
        what = f"Terminated ({stopped_by})" if terminated else "Interrupted"
        super().__init__(f"{what}: {n_done} of {plural(n_total, 'pair')} done; rerun the same command to resume")
        self.n_done, self.n_total, self.run_json = n_done, n_total, run_json
        self.terminated = terminated  # the shell's exit status is 143 (129: SIGHUP) then, 130 for Ctrl-C
        self.exit_status = exit_status(stopped_by) if terminated else 130

    def __str__(self) -> str:
        return self.args[0]


def _run_pair(pair, pair_dir: Path, *, cfg, method, evaluate, max_disparity, settings, fingerprint,
              pointcloud=False):
    """Compute, write and (optionally) score one pair: a generator of its stages, whose
    return value is the stored result dict.

    It yields :data:`READ` once the images are read and :data:`COMPUTED` once the map
    is computed, so a pipelined executor can run the three stages in different threads
    (:mod:`d3cli.batch.executors.pipelined`); run one after the other they are the serial pair.
    ``timings.wall`` counts the stages' own time, not the waits between them.

    Everything (maps, error map, panel, cloud and road outputs, result.json) is written
    into a staging folder beside ``pair_dir`` that then replaces it in one rename
    (:mod:`d3cli.batch.staging`): a kill at any moment leaves the old folder or the new
    one, never a mix.  A ground truth that cannot be scored (unreadable, another size)
    fails the pair's evaluation only: its maps are written and kept, ``evaluation_error``
    says why.
    """
    t0 = time.perf_counter()
    with step("loading the images"):
        left, right = datasets.load_pair_images(pair)
    height, width = left.shape[:2]
    dmax, range_note = _resolve_range(pair, width, max_disparity)
    resources.check_memory((height, width), dmax, cfg, method=method, where=pair.name)
    waited = yield from _pause(READ)
    with step(f"matching ({method})"):
        result = compute_pair(method, cfg, left, right, max_disparity=dmax, pair_dir=Path(pair.left).parent)
    if range_note:
        result.warnings.insert(0, range_note)
    result.warnings.extend(diagnostics.suspicious_result(result, dmax, left=left))
    waited += yield from _pause(COMPUTED)
    staging = new_staging(pair_dir)
    groups = output_groups(cfg.run.outputs)  # the optional files asked for (run.outputs)
    try:
        with step("writing the outputs"):
            written = write_disparity_outputs(staging, result.disparity, result.valid, left=left,
                                              color_range=tuple(cfg.run.color_range) or None, groups=groups)
        if written["png_clipped"] and "kitti" in groups:  # said once per pair, kept in result.json
            result.warnings.append(clipped_warning(written["png_clipped"]))
        scores, eval_error = _score(pair, left, right, result.disparity, staging) if evaluate else (None, None)
        if "pictures" in groups:
            with step("the panel"):
                write_panel(staging, pair.name, left, scores)  # panel.png: the pair at a glance
        else:
            (staging / ERROR_MAP).unlink(missing_ok=True)  # a picture: written only with them
        for text in result.warnings:
            log.warning("%s: %s", pair.name, text)
        stored = _stored_result(pair, method, settings, fingerprint, result, (height, width), dmax, written, scores,
                                eval_error, time.perf_counter() - t0 - waited)
        stored = write_result(staging, stored)
        # The extras asked for belong to the pair: one that fails leaves no pair behind.
        stored = write_extras(pair, staging, stored, cfg, pointcloud=pointcloud)
        publish(staging, pair_dir, PAIR_FILES)
    except BaseException as exc:  # Ctrl-C, a full disk, a broken writer: no half pair stays behind
        discard(staging, PAIR_FILES)
        # The old files are stale now (another fingerprint, or a failed check): a pair
        # that could not be written leaves nothing.
        remove_pair_files(pair_dir, remove_folder=True)
        if isinstance(exc, D3Error):
            raise named_as_target(exc, staging, pair_dir) from None
        raise
    return stored


#: The stages a pair's generator (:func:`_pair_stages`) yields: images read, map computed.
READ, COMPUTED = "read", "computed"


def _pause(stage: str):
    """Yield ``stage`` (a stage of the pair is done); returns the seconds until resumed."""
    paused = time.perf_counter()
    yield stage
    return time.perf_counter() - paused


def _stored_result(pair, method, settings, fingerprint, result, shape, dmax, written, scores, eval_error,
                   wall) -> dict:
    """What result.json records of a computed pair."""
    height, width = shape
    return {
        "pair": pair.name,
        "family": pair.family,
        "method": method,
        "settings": settings,
        "fingerprint": fingerprint,  # settings + input files: a rerun skips the pair only when equal
        "inputs": {"left": pair.left, "right": pair.right, "gt": pair.gt},
        "shape": [height, width],
        "max_disparity": dmax,
        "color_range": written["color_range"],  # the robust range of disp_color.png, stated
        "valid_share": float(result.valid.mean()) if result.valid.size else 0.0,
        "timings": {**result.timings, "wall": wall},
        "metrics": scores,
        "evaluation_error": eval_error,
        "info": result.info,
        "warnings": list(result.warnings),
    }


def _resolve_range(pair, width: int, override: int | None) -> tuple[int, str | None]:
    """The pair's disparity range, and a note when its ground truth could not give it.

    A ground truth that cannot be read must not stop the map (its evaluation fails
    later): the range then falls back to ``width // 4``, said in the note.
    """
    try:
        return datasets.resolve_max_disparity(pair, width, override=override), None
    except InputError as exc:
        if override is not None or pair.max_disparity is not None or pair.gt is None:
            raise
        dmax = datasets.resolve_max_disparity(dataclasses.replace(pair, gt=None), width)
        return dmax, (f"disparity range {dmax} px (image width / 4): the ground truth gives none ({exc}); "
                      f"set max_disparity in a manifest or pass --max-disparity")


def _score(pair, left, right, disparity, pair_dir: Path) -> tuple[dict | None, str | None]:
    """(metrics, None), or (None, why) when the pair's ground truth cannot be scored.

    Ctrl-C and a full disk still end the batch.
    """
    try:
        return evaluate_pair(pair, left, right, disparity, pair_dir), None
    except D3Error as exc:
        if io.is_disk_full(exc):
            raise
        message = str(exc)
    except Exception as exc:  # noqa: BLE001 - a broken ground truth fails the evaluation only
        interrupt = interrupt_behind(exc)
        if interrupt is not None:
            raise interrupt from None
        message = f"{type(exc).__name__}: {exc}"
    (pair_dir / ERROR_MAP).unlink(missing_ok=True)  # never an error map without its metrics
    return None, message


def _reuse_pair(pair, pair_dir: Path, stored: dict, *, cfg, evaluate, pointcloud) -> dict:
    """A complete earlier result: scored now from disp.pfm if it was stored unscored, and
    given the extras asked for.  An extra that fails leaves the pair incomplete (its files
    removed), so a rerun computes it again rather than skipping it as complete."""
    groups = output_groups(cfg.run.outputs)
    pictures = "pictures" in groups
    scored = False
    if evaluate and (not stored.get("metrics") or (pictures and pair.gt is not None
                                                   and not (pair_dir / ERROR_MAP).is_file())):
        # unscored, or scored by a run without pictures: the error map is made now
        left, right = datasets.load_pair_images(pair)
        disparity = io.read_pfm(pair_dir / "disp.pfm")
        scores, eval_error = _score(pair, left, right, disparity, pair_dir)
        stored = {**stored, "metrics": scores, "evaluation_error": eval_error}
        if not pictures:
            (pair_dir / ERROR_MAP).unlink(missing_ok=True)
        scored = True
    made = []
    if pictures and scored or _lacks(pair_dir, groups):
        # A run with fewer outputs wrote this pair: the files asked for now are made from its
        # maps, and the panel again when the pair was scored now (its error tile and title).
        with step("writing the outputs"):
            left = datasets.load_pair_images(pair)[0] if pictures else None
            if pictures and scored:
                (pair_dir / PANEL_FILE).unlink(missing_ok=True)
            made = add_missing_outputs(pair_dir, pair.name, stored, groups, left=left,
                                       disparity=io.read_pfm(pair_dir / "disp.pfm"),
                                       valid=io.read_mask(pair_dir / "valid.png"))
        if made:
            log.info("%s: added %s", pair.name, ", ".join(made))
    if made or scored:
        stored = write_result(pair_dir, stored)
    try:
        return write_extras(pair, pair_dir, stored, cfg, pointcloud=pointcloud)
    except Exception:
        remove_pair_files(pair_dir)
        raise


def _lacks(pair_dir: Path, groups: frozenset) -> bool:
    """Whether a complete pair folder lacks a map file of ``groups`` (the error map aside)."""
    want = (["disp.png"] if "kitti" in groups else []) + (
        ["disp_color.png", OVERLAY_FILE, PANEL_FILE] if "pictures" in groups else [])
    return any(not (pair_dir / name).is_file() for name in want)


def run_batch(pairs: Sequence, out_dir: str | os.PathLike, *, cfg: Config, method: str, evaluate: bool = False,
              overwrite: bool = False, max_disparity: int | None = None, progress: bool = True,
              config_source: str | None = None, pointcloud: bool = False, workers: int = 1,
              scheduler: str | None = None, shard: tuple[int, int] | None = None,
              break_lock: bool = False, prefetch: int | None = None, on_recorded=None) -> BatchResult:
    """Run ``method`` on every pair, writing ``out_dir/<pair>/...`` and ``out_dir/run.json``.

    Parameters
    ----------
    pairs : sequence of d3cli.data.layouts.Pair
        The pairs, e.g. from :func:`d3cli.data.layouts.discover`.
    out_dir : path-like
        Output folder; created when missing.
    cfg : Config, keyword-only
        Resolved configuration (stored in run.json).
    method : str, keyword-only
        One of :data:`d3cli.config.METHODS`.
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
    workers : int, keyword-only
        Local worker processes (:class:`d3cli.batch.executors.PoolExecutor`); 1 runs here.
    scheduler : str, optional, keyword-only
        Address of a Dask scheduler (:class:`d3cli.batch.executors.DaskExecutor`); wins over
        ``workers``.  OUT must be the same path on the client and every worker.
    shard : (int, int), optional, keyword-only
        ``(I, N)``: run only shard I of N (:func:`d3cli.batch.executors.select_shard`),
        writing ``run-I-of-N.json`` under its own lock and OUT's shared one, so the N runs
        share one OUT (and nothing else writes there meanwhile); the summary files are
        left to ``d3stereo eval`` over OUT.
    break_lock : bool, keyword-only
        Take over the folder's lock even when its record names another host or a live
        pid, as long as no running d3stereo holds it (:func:`d3cli.batch.lock.acquire_lock`).
    prefetch : int or None, keyword-only
        With one worker: pairs read ahead while one computes, outputs written behind
        (:class:`d3cli.batch.executors.pipelined.PipelinedExecutor`); 0 runs serially; None
        (``auto``) pipelines on the CUDA backend only.
    on_recorded : callable or None, keyword-only
        Called without arguments right after run.json records the batch complete, with
        Ctrl-C and SIGTERM held back in between (the ``d3stereo`` command ignores Ctrl-C
        from there on).  A Ctrl-C after that point is ignored by this function too: the
        batch returns complete.

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
    out, pairs = _prepare(pairs, out_dir, cfg=cfg, method=method, scheduler=scheduler, shard=shard)
    # SIGTERM handled before the lock file exists: a kill between the two would leave a lock behind.
    previous = sigterm_as_interrupt()
    try:
        batch = _lock_and_run(pairs, out, shard=shard, break_lock=break_lock, workers=workers, scheduler=scheduler,
                              prefetch=prefetch, cfg=cfg, method=method, evaluate=evaluate, overwrite=overwrite,
                              max_disparity=max_disparity, progress=progress, config_source=config_source,
                              pointcloud=pointcloud, on_recorded=on_recorded)
    finally:
        if previous is not None:
            restore_handlers(previous)
    return batch


def _lock_command(shard: tuple[int, int] | None) -> str:
    """The command a run's lock records, named to a writer refused meanwhile."""
    return "d3stereo run" if shard is None else "d3stereo run --shard {}/{}".format(*shard)


def _lock_and_run(pairs: list, out: Path, *, shard, break_lock, workers, scheduler, prefetch,
                  **batch_args) -> BatchResult:
    """Take OUT's lock (shared by the shards of one batch, and the shard's own), run the
    batch, release the lock.

    A SIGTERM after run.json recorded the batch complete (while the lock is released) is
    recorded there too, and ends the command with 143 like any other.
    """
    lock = batch = None
    try:
        try:
            # A Ctrl-C in the middle of taking the lock left the lock file behind: it is
            # taken whole, and the interrupt raised once it is held (and released below).
            with signals_deferred():
                lock = acquire_lock(out, shard=shard, command=_lock_command(shard), break_lock=break_lock)
            executor = make_executor(workers, scheduler, out, n_pairs=len(pairs), prefetch=prefetch,
                                     cfg=batch_args["cfg"], method=batch_args["method"])
            batch = _locked_batch(pairs, out, executor=executor, shard=shard, **batch_args)
        finally:
            if lock is not None:
                # A Ctrl-C now would leave the lock behind: held back, and after a complete
                # batch delivered once the lock is gone (ignored, it was lost: exit 0).
                with signals_deferred() if batch is not None else signals_held():
                    release_lock(lock)
    except Terminated as exc:
        if batch is None:
            raise
        mark_terminated(batch.run_json, signal_name(exc))
        raise BatchInterrupted(batch.n_computed + batch.n_skipped, batch.n_pairs, batch.run_json,
                               terminated=True, stopped_by=signal_name(exc)) from None
    except KeyboardInterrupt:
        if batch is None or not batch.recorded:
            raise
        # A Ctrl-C held back while the lock was released: the batch is complete and recorded.
    return batch


def _prepare(pairs: Sequence, out_dir, *, cfg: Config, method: str, scheduler: str | None,
             shard: tuple[int, int] | None) -> tuple[Path, list]:
    """(output folder, pairs of this run): the folder checked and created, CUDA checked,
    the shard selected, paths made absolute for a Dask cluster."""
    check_output_folder(Path(out_dir), pairs)  # before anything is written or removed
    out = ensure_writable(out_dir)
    spec = method_spec(method)
    if spec is not None and spec.kernels and cfg.run.backend == "cuda":
        from ..kernels import get_backend

        get_backend("cuda")  # BackendUnavailable now, not once per pair
    pairs = list(pairs)
    if shard is not None:
        pairs = select_shard(pairs, *shard)
    if scheduler:
        # Workers may run in another folder, on another machine: only absolute paths mean the same there.
        out = out.resolve()
        pairs = [_absolute(p) for p in pairs]
    return out, pairs


def _absolute(pair):
    """``pair`` with every path made absolute."""
    changes = {f.name: Path(getattr(pair, f.name)).resolve() for f in dataclasses.fields(pair)
               if isinstance(getattr(pair, f.name), Path)}
    return dataclasses.replace(pair, **changes)


def _pair_task(pair, *, out: Path, staged: bool = False, **kwargs):
    """The task every executor runs for one pair: :func:`_batch_pair` into ``out/<pair>``;
    with ``staged`` its stages as a generator (:func:`_pair_stages`), for the pipelined
    executor."""
    if staged:
        return _pair_stages(pair, out / pair.name, **kwargs)
    return _batch_pair(pair, out / pair.name, **kwargs)


def _locked_batch(pairs: list, out: Path, *, cfg, method, evaluate, overwrite, max_disparity, progress,
                  config_source, pointcloud, executor, shard=None, on_recorded=None) -> BatchResult:
    """The body of :func:`run_batch`, run while holding the output folder's (or shard's) lock."""
    run_name = RUN_FILE if shard is None else "run-{}-of-{}.json".format(*shard)
    batch = BatchResult(out_dir=out, run_json=out / run_name)
    records = []
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    meta = dict(cfg=cfg, method=method, max_disparity=max_disparity, started=started,
                config_source=config_source, n_total=len(pairs), shard=shard)
    order = {pair.name: i for i, pair in enumerate(pairs)}
    # From here on an interrupt is recorded in run.json: the lock is held, the batch has begun.
    try:
        settings = settings_fingerprint(cfg, method, max_disparity)  # reads library versions: imports
        task = functools.partial(_pair_task, out=out, cfg=cfg, method=method, evaluate=evaluate,
                                 overwrite=overwrite, max_disparity=max_disparity, settings=settings,
                                 pointcloud=pointcloud)
        # The staging folders of a killed run over these pairs (only these: shards share OUT).
        clean_leftovers(out, order, PAIR_FILES)
        with interrupts_unwrapped(), executor:
            meta["execution"] = executor.describe()
            # Compile before the first pair (and before a pool fans out): no pair's time includes it.
            # A KeyboardInterrupt must never be raised inside numba's loading of a cached
            # kernel (a ctypes callback of llvmlite: the process can crash, SIGSEGV instead
            # of 130), so signals are deferred here; the warm-up itself waits for the
            # compile in another thread and answers Ctrl-C, SIGTERM and SIGHUP at once
            # (warmup.call_interruptibly), and the deferred interrupt is raised right after.
            with signals_deferred():
                meta["compile_s"] = round(executor.warm(cfg, method), 3) if pairs else 0.0
            bar = progress_bar(None, progress, method)
            bar.reset(total=len(pairs))
            # A CUDA batch in this process: launches, copies and kernel time for run.json's
            # ``device`` (how busy the GPU was); None otherwise.
            with device_activity(cfg, method, meta["execution"]) as device:
                try:
                    for _pair, (row, record) in executor.imap(task, pairs):
                        batch.rows.append(row)
                        records.append(record)
                        if device is not None:
                            device.pair_done()
                        progress_start(bar, _pair)  # the bar names the pair last finished
                        # Without a terminal: one line per pair, saying "skipped" as run.json does.
                        progress_done(bar, {**row, "status": record["status"]})
                        bar.update()
                finally:
                    bar.close()
                    if device is not None:
                        meta["device"] = device.record()
    except KeyboardInterrupt as exc:
        for _pair, (row, record) in executor.drain():  # pool workers finish the pair they hold
            batch.rows.append(row)
            records.append(record)
        raise _interrupted(batch, records, meta, executor.current, exc) from None
    except OutputError as exc:
        current = executor.current
        if not io.is_disk_full(exc) or current is None:
            raise
        _record_disk_full(batch, records, meta, current, exc)
        raise
    try:
        _finish(batch, records, meta, pairs, out, order=order, evaluate=evaluate, settings=settings,
                on_recorded=on_recorded)
    except KeyboardInterrupt as exc:
        # After the last pair, while the summary files are written: recorded as an
        # interruption (a rerun writes them) unless run.json already records the batch
        # complete.  Then a Ctrl-C is ignored (exit 0, not 130 and "rerun the same command
        # to resume" beside a run.json saying the batch was complete:
        # tests/batch/test_interrupts.py's eight moments) and a SIGTERM recorded (143).
        if not batch.recorded:
            raise _interrupted(batch, records, meta, None, exc) from None
        if isinstance(exc, Terminated):
            mark_terminated(batch.run_json, signal_name(exc))
            raise BatchInterrupted(batch.n_computed + batch.n_skipped, batch.n_pairs, batch.run_json,
                                   terminated=True, stopped_by=signal_name(exc)) from None
    return batch


def _interrupted(batch: BatchResult, records: list, meta: dict, current, exc: KeyboardInterrupt) -> BatchInterrupted:
    """Record Ctrl-C or SIGTERM in run.json; the :class:`BatchInterrupted` to raise."""
    terminated = isinstance(exc, Terminated)
    with signals_held():  # a second Ctrl-C must not cut the record of the first short
        write_run_json(batch, records, **meta, interrupted=True, stopped_at=current and current.name,
                       stop_reason=(f"terminated ({signal_name(exc)})" if terminated
                                    else "interrupted (Ctrl-C / SIGINT)"))
    n_done = sum(r["status"] in ("ok", "skipped") for r in records)
    return BatchInterrupted(n_done, meta["n_total"], batch.run_json, terminated=terminated,
                            stopped_by=signal_name(exc))


def _record_disk_full(batch: BatchResult, records: list, meta: dict, current, exc: OutputError) -> None:
    """Fail the pair that met a full disk and record the stop in run.json, if the disk allows."""
    row, record = failed_row(current, str(exc), 0.0)
    batch.rows.append(row)
    records.append(record)
    try:  # the disk is full: this may well fail too
        write_run_json(batch, records, **meta, interrupted=True, stopped_at=current.name,
                       stop_reason=str(exc))
    except OutputError as again:
        log.warning("run.json not written: %s", again)


def _finish(batch: BatchResult, records: list, meta: dict, pairs: list, out: Path, *, order: dict,
            evaluate: bool, settings: str, on_recorded=None) -> None:
    """After the last pair: counts, defects.csv, the summary files, run.json and report.html."""
    cfg, method, shard = meta["cfg"], meta["method"], meta["shard"]
    # Parallel executors finish pairs in any order; the files list them in input order.
    batch.rows.sort(key=lambda r: order[r["pair"]])
    records.sort(key=lambda r: order[r["pair"]])
    batch.n_failed = sum(r["status"] == "failed" for r in batch.rows)
    batch.n_computed = sum(r["status"] == "ok" for r in records)
    batch.n_skipped = sum(r["status"] == "skipped" for r in records)
    run_counts = {"n_computed": batch.n_computed, "n_skipped": batch.n_skipped, "n_failed": batch.n_failed}
    if cfg.road.report or (shard is None and is_our_summary(out / DEFECTS_CSV)):
        # Without --road-report too: pairs computed again lost their defects.json, so an
        # earlier defects.csv would list defects of maps that are gone.
        if (write_defects_csv(out, [out / p.name for p in pairs], frame_spacing_m=cfg.road.frame_spacing_m) is None
                and remove_ours(out / DEFECTS_CSV)):
            log.info("%s: removed (no pair of this run has road outputs now)", out / DEFECTS_CSV)
        survey_map(out, pairs, cfg)  # OUT/defects.geojson, track.geojson where the frames have positions
    if evaluate and shard is not None:
        log.info("--shard: summary files are left to `d3stereo eval %s --gt ... -o REPORT` once every shard is done", out)
    elif evaluate:
        report.write_summary(out, batch.rows, method=method, extra={"settings": settings}, run_counts=run_counts)
        batch.summary = report.summarize(batch.rows)
    if not evaluate or shard is not None:
        # The summary of an earlier --eval run (maybe another method) would
        # describe maps this run may have replaced; only d3stereo's own files are removed.
        for name in remove_stale_summaries(out):
            log.info("%s: removed the summary of an earlier --eval run (rerun with --eval to score)", out / name)
    # The page people look at, after every batch; before run.json, whose complete record
    # is the batch's last act (records.record_complete).
    write_report_html(out, batch.rows, title=f"d3stereo run: {out} ({method})", config=cfg.to_dict(),
                      versions=package_versions(), run_counts=run_counts)
    record_complete(batch, records, meta, on_recorded)


def _batch_pair(pair, pair_dir: Path, **kwargs):
    """One pair of a batch -> (report row, run.json record): its stages one after the other.

    Raises only KeyboardInterrupt and the OutputError of a full disk; any other failure
    becomes a ``failed`` row (an unexpected exception: ``<pair>: internal error in
    <step> (...); please report it``).
    """
    stages = _pair_stages(pair, pair_dir, **kwargs)
    while True:
        try:
            next(stages)
        except StopIteration as done:
            return done.value


def _pair_stages(pair, pair_dir: Path, *, cfg, method, evaluate, overwrite, max_disparity, settings,
                 pointcloud=False):
    """:func:`_batch_pair` as a generator: yields :data:`READ` and :data:`COMPUTED` between the
    stages of a computed pair (none for a skipped or failed one), returns its (row, record)."""
    t0 = time.perf_counter()
    reused = False
    try:
        # A pair named like a file of the batch (run.json...): its folder would take that
        # file's name.  Failed before it is computed; the other pairs run.
        check_pair_name(pair.name, pair_dir.parent)
        with step("the resume check"):
            # settings, the pair's input files and the feature files it reads
            fingerprint = pair_fingerprint(settings, pair, feature_files(cfg, method, pair))
            stored = None if overwrite else read_result(pair_dir)
            if stored is not None and stored.get("fingerprint") == fingerprint:
                changed = changed_files(pair_dir, stored.get("files"))
                if changed is not None:  # a complete pair is skipped only as it was written
                    log.warning("%s: %s; computing the pair again", pair.name, changed)
                    stored = None
        if stored is not None and stored.get("fingerprint") == fingerprint:
            log.info("%s: complete, skipped (use --overwrite to compute it again)", pair.name)
            stored = _reuse_pair(pair, pair_dir, stored, cfg=cfg, evaluate=evaluate, pointcloud=pointcloud)
            reused = True
        else:
            stored = yield from _run_pair(pair, pair_dir, cfg=cfg, method=method, evaluate=evaluate,
                                          max_disparity=max_disparity, settings=settings, fingerprint=fingerprint,
                                          pointcloud=pointcloud)
    except D3Error as exc:
        if io.is_disk_full(exc):
            raise  # every later pair would fail the same way: the batch stops
        return failed_row(pair, str(exc), time.perf_counter() - t0)
    except Exception as exc:  # noqa: BLE001 - one broken pair must not end the batch
        interrupt = interrupt_behind(exc)
        if interrupt is not None:
            raise interrupt from None  # Ctrl-C inside a numba kernel: stop the batch
        log.debug("%s: internal error", pair.name, exc_info=True)
        return failed_row(pair, internal_message(pair.name, exc), time.perf_counter() - t0)
    return _pair_outcome(pair, stored, evaluate=evaluate, reused=reused)


def _pair_outcome(pair, stored: dict, *, evaluate: bool, reused: bool):
    """(report row, run.json record) of a pair whose folder is complete."""
    wall = stored.get("timings", {}).get("wall")
    if evaluate and stored.get("evaluation_error"):
        # The maps are complete and kept; only the evaluation failed.
        message = f"{pair.name}: evaluation failed, maps kept: {stored['evaluation_error']}"
        row, record = failed_row(pair, message, wall or 0.0)
        record["stage"] = "evaluation"
        return row, record
    row = pair_row(pair, "ok", time_s=wall, metrics=stored.get("metrics"))
    if stored.get("warnings"):
        row["warnings"] = list(stored["warnings"])
    record = {"pair": pair.name, "status": "skipped" if reused else "ok", "wall_s": wall,
              "max_disparity": stored.get("max_disparity"), "backend": stored.get("info", {}).get("backend"),
              "warnings": stored.get("warnings", [])}
    if stored.get("info", {}).get("pt") is not None:
        record["pt"] = stored["info"]["pt"]  # the fitted road model and its inlier share
    return row, record
