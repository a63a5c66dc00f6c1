"""The ``d3stereo`` command line: parse, call the library, turn the outcome into an exit code.

Exit codes: 0 success; 1 a user error (any :class:`~d3cli.errors.D3Error`, printed as
one line ``Error: <message>``) or a batch with failed pairs; 2 a usage error (click);
130 Ctrl-C (``Interrupted: N of M pairs done; rerun the same command to resume``).
Unexpected exceptions keep their traceback: they are bugs, not user mistakes.
"""

from __future__ import annotations

import logging
import math
import os
import platform
import signal
import sys
from dataclasses import replace
from pathlib import Path

import click

from . import __version__
from .config import (BACKENDS, MAX_CONFIG_INT, METHODS, OUTPUT_CHOICES, Config, bundled_configs, load_config,
                     method_spec, output_groups, quote, resolve_config)
from .errors import D3Error, InputError, interrupt_behind, plural, raise_hung_up, raise_terminated, where_what_fix

log = logging.getLogger("d3cli")
#: --break-lock of run and eval: the one writer of OUT at a time (batch/lock.py).
BREAK_LOCK_HELP = ("Take over OUT's lock when its record names a run on another host or a live pid that "
                   "is not writing (check first); a lock held by a running d3stereo is never broken.")

#: Exit code after Ctrl-C (128 + SIGINT, as a shell reports it).
INTERRUPTED_EXIT = 130
#: Exit status after SIGTERM: 128 + 15, as a shell reports a process killed by it.
TERMINATED_EXIT = 143
#: Environment variable naming a config file used when -c is not given.
CONFIG_ENV = "D3STEREO_CONFIG"
#: Config file picked up from the working folder when neither -c nor the variable is set.
LOCAL_CONFIG = "d3stereo.yaml"


class _Group(click.Group):
    """A click group that turns every D3Error into ``Error: <message>`` and exit code 1."""

    def invoke(self, ctx):
        if _own_process():
            # The batch turns SIGTERM into an interrupt while it runs and puts the previous
            # handler back at its end; with the default one there, a SIGTERM between the
            # end of the batch and the exit (the summary lines) would kill the process by
            # the signal, status -15 instead of 143 or 0 (a fast machine gets there).
            # SIGHUP (the terminal or ssh session closed) likewise, with 129.
            signal.signal(signal.SIGTERM, raise_terminated)
            signal.signal(signal.SIGHUP, raise_hung_up)
        try:
            result = super().invoke(ctx)
            _end_of_command()
            return result
        except D3Error as exc:
            raise click.ClickException(str(exc)) from None
        except KeyboardInterrupt as exc:
            _interrupted(ctx, exc)
        except Exception as exc:
            # A Ctrl-C that lands inside a numba kernel comes out as "SystemError: ...
            # returned a result with an exception set" with the KeyboardInterrupt as its
            # cause: an interrupt, not a crash.
            interrupt = interrupt_behind(exc)
            if interrupt is None:
                raise
            _interrupted(ctx, interrupt)


def _interrupted(ctx, exc: KeyboardInterrupt):
    """Say what was kept and exit 130 (143 after SIGTERM, 129 after SIGHUP), like a shell;
    click would print "Aborted!" and exit 1."""
    _end_of_command()  # first: a second Ctrl-C from here on must not end us by the signal
    # No import here: Ctrl-C may have landed in the middle of importing the batch
    # package (numpy, scipy...), and importing it again recurses until a
    # RecursionError traceback comes out instead of this line.
    batch = sys.modules.get(f"{__package__}.batch")
    interrupted = getattr(batch, "BatchInterrupted", None)
    if interrupted is not None and isinstance(exc, interrupted):
        message = str(exc)
    else:
        message = "Interrupted; rerun the same command to resume"
    click.echo(message, err=True)
    status = getattr(exc, "exit_status", TERMINATED_EXIT) if getattr(exc, "terminated", False) else INTERRUPTED_EXIT
    _exit_if_compiling(status)
    ctx.exit(status)


def _exit_if_compiling(status: int) -> None:
    """End the process with ``status`` now when the interrupt left the kernels' compile
    running in its thread (:func:`d3cli.batch.warmup.compiling_in_background`): an ordinary
    exit would finalise the interpreter and LLVM under that thread's feet.  What it compiled
    is in the cache already; its own files are written whole or not at all.  In the
    command's own process only."""
    warmup = sys.modules.get(f"{__package__}.batch.warmup")  # no import: see _interrupted
    if _own_process() and warmup is not None and warmup.compiling_in_background():
        logging.shutdown()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (AttributeError, OSError, ValueError):  # closed, or None: nothing to flush
                pass
        os._exit(status)


def _own_process() -> bool:
    """True in a ``d3stereo`` / ``python -m d3cli`` process; False when the CLI runs inside
    another program (tests, notebooks), whose signal handling is not ours to change."""
    main_module = sys.modules.get("__main__")
    spec = getattr(main_module, "__spec__", None)
    return (spec is not None and spec.name == f"{__package__}.__main__") or Path(sys.argv[0]).name == "d3stereo"


def _end_of_command() -> None:
    """The command's exit status is decided: make sure the process ends with it.

    Two ways a handled Ctrl-C would still end a ``d3stereo`` process by the signal (status
    -2 instead of 130):

    * a second SIGINT during the interpreter's shutdown (atexit, thread joins): SIGINT
      is ignored from here on;
    * CPython sets its "unhandled KeyboardInterrupt" flag (``_Py_UnhandledKeyboardInterrupt``,
      checked by ``Py_RunMain`` after shutdown, which then kills the process with SIGINT)
      whenever a KeyboardInterrupt leaves code run by ``exec()`` of a string, even when
      the interrupt is caught further up.  The standard library runs such code while
      importing (dataclasses, namedtuple): a Ctrl-C during the batch package's imports
      set it in 2 of 60 trials.  Every ``exec()`` of a string clears the flag first, so
      one harmless ``exec`` clears it; nothing can set it again once SIGINT is ignored.

    Only in the command's own process, never when the CLI runs inside another program.
    """
    if _own_process():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        for sig in (signal.SIGTERM, signal.SIGHUP):
            if not getattr(signal.getsignal(sig), "after_batch", False):  # run's own: exits 143 / 129
                signal.signal(sig, signal.SIG_IGN)  # the status is decided: exit with it
        exec("pass")  # noqa: S102 - clears the flag, see above


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever sys.stderr is at the time of each record (click's test runner swaps it).

    While a progress bar is on the terminal a line goes above it (``tqdm.write``: the bar
    is cleared, the line written, the bar drawn again below), never glued to the bar's end.
    """

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value):
        pass

    def emit(self, record):
        if self.stream is None:  # closed where the program started (outside the d3stereo command)
            return
        bars = sys.modules.get("tqdm")  # no bar without tqdm imported: not imported here
        if bars is None:
            super().emit(record)
            return
        try:
            bars.tqdm.write(self.format(record), file=self.stream)
            self.flush()  # as StreamHandler.emit does: the line is out before the next stdout line
        except Exception:  # noqa: BLE001 - logging's own rule: a failed line never ends the command
            self.handleError(record)


class _OwnLines(logging.Filter):
    """Lets through d3stereo's own records at any level the logger allows, other loggers'
    (Pillow, distributed, Python warnings) only from WARNING up unless ``libraries``."""

    def __init__(self, libraries: bool):
        super().__init__()
        self.libraries = libraries

    def filter(self, record):
        own = record.name == "d3cli" or record.name.startswith("d3cli.")
        return own or self.libraries or record.levelno >= logging.WARNING


def _setup_logging(verbose: int, quiet: bool) -> None:
    """Log lines on stderr: warnings and errors; ``-q`` errors only; ``-v`` d3stereo's debug
    lines too; ``-vv`` the libraries' debug lines and Python warnings as well."""
    level = logging.DEBUG if verbose else logging.ERROR if quiet else logging.WARNING
    handler = _StderrHandler()
    handler.addFilter(_OwnLines(libraries=verbose >= 2))
    logging.basicConfig(level=level, format="%(levelname)s: %(message)s", handlers=[handler], force=True)
    # numba logs its compiler passes at DEBUG; they drown the useful lines.
    logging.getLogger("numba").setLevel(max(level, logging.INFO))
    route_library_warnings(verbose)


class _AsDebug(logging.Filter):
    """Turns a record into a DEBUG one: shown with -vv only."""

    def filter(self, record):
        record.levelno, record.levelname = logging.DEBUG, "DEBUG"
        return logging.getLogger().isEnabledFor(logging.DEBUG)


def route_library_warnings(verbose: bool) -> None:
    """Send Python warnings (numpy's ``RuntimeWarning: overflow``, a library's
    DeprecationWarning) to the log at DEBUG instead of stderr.

    On stderr a user sees only d3stereo's own ``Error:`` and ``WARNING:`` lines; what
    a warning says about an input is d3stereo's to report.  ``-vv`` shows them (``-v``
    shows d3stereo's own lines only: the handler's filter, :func:`_setup_logging`).

    Parameters
    ----------
    verbose : int or bool
        Whether the command runs with ``-v`` or ``-vv`` (the root logger then shows DEBUG).
    """
    logging.captureWarnings(True)
    channel = logging.getLogger("py.warnings")
    channel.filters = [_AsDebug()]
    channel.setLevel(logging.DEBUG if verbose else logging.WARNING)


def _verbosity(fn):
    fn = click.option("-q", "--quiet", is_flag=True, help="Only errors; no progress bar.")(fn)
    fn = click.option("-v", "--verbose", count=True,
                      help="d3stereo's debug lines; -vv also the libraries' own (Pillow, numba, Python "
                           "warnings).")(fn)
    return fn


def config_search(explicit: str | None) -> tuple[str | None, str]:
    """Which config file to load and why: -c FILE, $D3STEREO_CONFIG, ./d3stereo.yaml, or none."""
    if explicit:
        return explicit, "-c option"
    env = os.environ.get(CONFIG_ENV)
    if env:
        return env, f"${CONFIG_ENV}"
    if Path(LOCAL_CONFIG).is_file():
        return LOCAL_CONFIG, "working folder"
    return None, "built-in defaults"


def samples_dir() -> Path:
    """Folder of the bundled sample pairs (pair-folder layout)."""
    from .data import samples

    return Path(samples.__file__).resolve().parent


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="d3stereo")
def main():
    """D3Stereo: dense disparity from rectified stereo pairs, with batch evaluation."""


# ----------------------------------------------------------------------------- run
@main.command()
@click.argument("inputs", nargs=-1, type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_dir", type=click.Path(path_type=Path), default=Path("d3stereo-out"),
              show_default=True, help="Output folder.")
@click.option("--method", type=click.Choice(METHODS), default=None,
              help="Stereo method [default: run.method of the config, d3stereo].")
@click.option("--backend", type=click.Choice(BACKENDS), default=None,
              help="Compute backend [default: run.backend of the config, auto].")
@click.option("-c", "--config", "config_path", type=click.Path(path_type=Path), default=None,
              help=f"YAML config file, or a bundled config's name (road, kitti, middlebury, paper, default; "
                   f"see `d3stereo configs`); "
                   f"else ${CONFIG_ENV} or ./{LOCAL_CONFIG}.")
@click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE",
              help="Override one config value; repeatable.")
@click.option("--max-disparity", type=int, default=None, metavar="N",
              help="Largest disparity searched in every pair, pixels.")
@click.option("--eval/--no-eval", "evaluate", default=False,
              help="Score each pair (ground truth where present, photometric always).")
@click.option("--overwrite", is_flag=True, help="Compute pairs again even when their outputs are complete.")
@click.option("--break-lock", is_flag=True, help=BREAK_LOCK_HELP)
@click.option("--no-fill", is_flag=True, help="Leave undecided pixels invalid (inf) instead of filling them.")
@click.option("--pointcloud", is_flag=True,
              help="Also write OUT/<pair>/cloud.ply (x, y, z metres in the left camera frame, colour from the "
                   "left image, decided pixels only) from calib.txt or the camera config section.")
@click.option("--workers", default="1", show_default=True, metavar="N|auto",
              help="Local worker processes, each taking whole pairs (auto: one per core); numba threads "
                   "per worker = cores // N.")
@click.option("--prefetch", default="auto", show_default=True, metavar="N|auto",
              help="With one worker: read N pairs ahead and write outputs behind, in threads, while a pair "
                   "computes (auto: 2 on the CUDA backend, 0 - serial - on the CPU).")
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT",
              help="Run each pair as a task on this Dask scheduler [default: $DASK_SCHEDULER_ADDRESS]; "
                   "OUT must be shared with the workers. Needs the 'distributed' extra.")
@click.option("--shard", default=None, metavar="I/N",
              help="Run only shard I of N (every N-th pair by name); shards share OUT and write run-I-of-N.json.")
@click.option("--color-range", default=None, metavar="MIN:MAX",
              help="Fixed disparity range (pixels) of disp_color.png for every pair [default: run.color_range, "
                   "else each pair's 1st-99th percentile].")
@click.option("--road-report", is_flag=True,
              help="Also write the road inspection outputs (height.pfm, height_color.png, defects.json, "
                   "defects.png per pair, OUT/defects.csv); same as road.report: true.")
@click.option("--outputs", default=None, metavar="SET",
              help="Per-pair files to write [default: run.outputs, all]: all, or survey (disp.pfm, valid.png, "
                   "result.json; defects.json with --road-report) plus any of kitti (disp.png), pictures (the PNG "
                   "pictures), height (height.pfm), comma-separated, e.g. survey,pictures.")
@click.option("--track", type=click.Path(path_type=Path), default=None, metavar="FILE",
              help="Positions of the frames (track.csv or GPX) for the map of the road report (OUT/defects.geojson, "
                   "track.geojson) [default: road.track, else track.csv or track.gpx beside the pair folders, else "
                   "the EXIF GPS tags]. Needs the 'gis' extra.")
@_verbosity
def run(inputs, out_dir, method, backend, config_path, overrides, max_disparity, evaluate, overwrite,
        break_lock, no_fill, pointcloud, workers, prefetch, scheduler, shard, color_range, road_report, outputs,
        track, verbose, quiet):
    """Compute disparity maps for INPUT pairs (default: the bundled samples) into OUT.

    INPUT: a folder of pair folders (left.png, right.png[, disp_gt.*]), a Middlebury or
    KITTI root, a manifest YAML, or two image files.
    """
    _setup_logging(verbose, quiet)
    if max_disparity is not None and not 0 < max_disparity <= MAX_CONFIG_INT:
        # bounded like every integer setting: the kernels take 32-bit scalars
        raise click.BadParameter(f"must be a positive number of pixels (at most {MAX_CONFIG_INT}), got "
                                 f"{str(max_disparity)[:30]}", param_hint="--max-disparity")
    cfg, source = _resolve_config(config_path, overrides, method=method, backend=backend, no_fill=no_fill)
    if color_range is not None:
        cfg = replace(cfg, run=replace(cfg.run, color_range=_color_range(color_range)))
    if road_report:
        cfg = replace(cfg, road=replace(cfg.road, report=True))
    if track is not None:
        cfg = replace(cfg, road=replace(cfg.road, track=str(track)))
    if outputs is not None:
        if output_groups(outputs) is None:
            raise InputError(where_what_fix(f"--outputs {quote(outputs)}", "not a set of per-pair files",
                                            "give a comma-separated list of " + ", ".join(OUTPUT_CHOICES)
                                            + " (e.g. survey,pictures)"))
        cfg = replace(cfg, run=replace(cfg.run, outputs=outputs))
    method = cfg.run.method
    spec = method_spec(method)
    if spec is not None and spec.kernels:
        from .kernels.cache_location import announce

        announce(method)  # a cold cache: say so before the imports below (numba: a second or more)
    from . import batch
    from .data import layouts as datasets
    from .evaluation import report

    if spec is not None and not spec.kernels and cfg.run.backend == "cuda":
        log.warning(f"--backend cuda: {method} does not run d3stereo's kernels; it runs on the CPU")
    if spec is not None:
        spec.require()  # an Error now, not one failed pair after another
    n_workers = batch.parse_workers(workers)
    n_ahead = batch.parse_prefetch(prefetch)
    shard_of = batch.parse_shard(shard) if shard else None
    scheduler = scheduler or os.environ.get(batch.SCHEDULER_ENV) or None
    pairs = datasets.discover(list(inputs) if inputs else [samples_dir()])
    from .survey import check_positions

    check_positions(pairs, cfg)  # a malformed track: an Error now, not after the batch
    override = max_disparity if max_disparity is not None else cfg.run.max_disparity
    result = batch.run_batch(pairs, out_dir, cfg=cfg, method=method, evaluate=evaluate,
                             overwrite=overwrite, max_disparity=override, progress=not quiet,
                             config_source=source, pointcloud=pointcloud, workers=n_workers,
                             scheduler=scheduler, shard=shard_of, break_lock=break_lock, prefetch=n_ahead,
                             on_recorded=_batch_recorded)
    if _own_process():  # a SIGTERM (SIGHUP) from now on still exits 143 (129), recorded in run.json
        batch.terminate_after_batch(result.run_json, f"{result.n_computed + result.n_skipped} of "
                                                     f"{plural(result.n_pairs, 'pair')} done; rerun the same "
                                                     "command to resume")
    if not quiet:
        # The counts as run.json has them: "skipped" = kept complete from an earlier run
        # (an ok result in the table), never a pair left out.
        counts = f"{method}: {result.counts_line()}"
        if result.summary is not None:
            table = report.format_table(result.summary).splitlines()
            counts = "\n".join([counts, *table[1:]])  # the table's first line is its counts line
        click.echo(counts)
        if cfg.road.report:  # what the road report found, in one line
            from .road.outputs import survey_line

            road_line = survey_line(Path(out_dir))
            if road_line:
                click.echo(road_line)
        _say_where(Path(out_dir), evaluate)
    _finish(result.failures, result.n_pairs, result.run_json)


def _batch_recorded() -> None:
    """run.json has just recorded the batch complete (called by the batch, signals held):
    a Ctrl-C from here on is ignored (exit 0, everything written; README "Failure
    behaviour"), in the command's own process.  One during the summary lines, or between
    run.json and the batch's return (tests/batch/test_interrupts.py), would otherwise end
    the command with 130 and the resume line although nothing is left to resume.  SIGTERM
    still stops the command there (143)."""
    if _own_process():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _say_where(folder: Path, with_summary: bool = True) -> None:
    """The end-of-run lines: where the page and the summary are."""
    click.echo(f"report: {folder / 'report.html'}")
    if with_summary:
        click.echo(f"summary: {folder / 'summary.md'}")


def config_by_name(config_path):
    """``-c road`` -> the bundled ``configs/road.yaml`` unless a file ``road`` (or,
    for a bare name, ``./road.yaml``) exists (:func:`d3cli.config.resolve_config`); a
    value that names nothing is returned unchanged, so the usual "not found" error names it.
    """
    if config_path is None:
        return None
    return resolve_config(config_path)[0]


def _color_range(text: str) -> tuple[float, float]:
    """``MIN:MAX`` -> (min, max), 0 <= min < max, else a usage error naming the option."""
    try:
        low, high = (float(part) for part in text.split(":"))
    except ValueError:
        raise click.BadParameter(f"expected MIN:MAX in pixels (e.g. 0:64), got {text!r}",
                                 param_hint="--color-range") from None
    if not (0 <= low < high and math.isfinite(high)):  # inf would make every colour black
        raise click.BadParameter(f"needs 0 <= MIN < MAX, both finite, got {text!r}", param_hint="--color-range")
    return low, high


def _resolve_config(config_path, overrides, *, method, backend, no_fill) -> tuple[Config, str]:
    config_path = config_by_name(config_path)
    path, why = config_search(str(config_path) if config_path else None)
    cfg = load_config(path, overrides)
    if path:
        log.info("config: %s (%s)", path, why)
    if method is not None:
        cfg = replace(cfg, run=replace(cfg.run, method=method))
    if backend is not None:
        cfg = replace(cfg, run=replace(cfg.run, backend=backend))
    if no_fill:
        cfg = replace(cfg, refine=replace(cfg.refine, fill=False), sgbm=replace(cfg.sgbm, fill=False))
    return cfg, f"{path} ({why})" if path else why


def _finish(failures, n_total: int, where) -> None:
    """Report failed pairs on stderr; exit 1 when there are any."""
    for pair, message in failures:
        prefix = "" if message.startswith(f"{pair}:") else f"{pair}: "
        click.echo(f"failed: {prefix}{message}", err=True)
    if failures:
        raise click.ClickException(f"{len(failures)} of {plural(n_total, 'pair')} failed (see {where})")


# ----------------------------------------------------------------------------- eval
@main.command("eval")
@click.argument("pred_dirs", nargs=-1, required=True, metavar="PRED_DIR...", type=click.Path(path_type=Path))
@click.option("--gt", "gt_input", required=True, multiple=True, type=click.Path(path_type=Path),
              help="The pairs with ground truth (any layout `run` accepts); repeatable.")
@click.option("-o", "--out", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Folder for the reports (the prediction folders are only read).")
@click.option("--break-lock", is_flag=True, help=BREAK_LOCK_HELP)
@_verbosity
def eval_(pred_dirs, gt_input, out_dir, break_lock, verbose, quiet):
    """Score the predictions in PRED_DIR(s) against the pairs of --gt.

    A prediction is <pair>/disp.{pfm,png,npy} or <pair>.{pfm,png,npy} (PNG: KITTI
    uint16, value/256). Only pairs present in every PRED_DIR are compared. Several
    PRED_DIRs give one side-by-side table (comparison.md).
    """
    from . import batch
    from .data import layouts as datasets
    from .evaluation import report

    _setup_logging(verbose, quiet)
    pairs = datasets.discover(list(gt_input))
    outcome = batch.evaluate_folders(pred_dirs, pairs, out_dir=out_dir, progress=not quiet, break_lock=break_lock)
    if outcome["comparison"] is not None:
        click.echo(outcome["comparison"])
    elif not quiet:
        (summary,) = outcome["summaries"].values()
        click.echo(report.format_table(summary))
    failures = [(f"{name}/{pair}", msg) for name, rows in outcome["results"].items()
                for pair, msg in ((r["pair"], r.get("error", "")) for r in rows if r["status"] == "failed")]
    if not quiet:
        for target in ([Path(out_dir)] if len(pred_dirs) == 1 else [Path(out_dir) / n for n in outcome["results"]]):
            _say_where(target)
    report_file = outcome["comparison_path"] or Path(outcome["out_dir"]) / "summary.json"
    _finish(failures, outcome["n_rows"], report_file)


# ----------------------------------------------------------------------------- synth
@main.command()
@click.argument("out_dir", type=click.Path(path_type=Path))
@click.option("--n", "n", type=click.IntRange(min=1), default=12, show_default=True, help="Number of pairs.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed (same seed, same pairs).")
@click.option("--width", type=click.IntRange(min=32, max=8192), default=1280, show_default=True,
              help="Image width, pixels.")
@click.option("--height", type=click.IntRange(min=32, max=8192), default=720, show_default=True,
              help="Image height, pixels.")
@click.option("--drive", "drive", type=int, default=None, metavar="N",
              help="Write a drive instead: N overlapping frames along one road, a GPS track and drive_gt.json.")
@click.option("--spacing", type=float, default=None, metavar="M",
              help="With --drive: metres between frames [default: every pothole in two frames or more].")
@click.option("--potholes", type=int, default=None, metavar="K",
              help="With --drive: number of potholes [default: one per 3 m of road].")
@click.option("--gps-noise", "gps_noise", type=float, default=None, metavar="M",
              help="With --drive: std of the track's position error, metres [default: 0].")
@_verbosity
@click.pass_context
def synth(ctx, out_dir, n, seed, width, height, drive, spacing, potholes, gps_noise, verbose, quiet):
    """Write N synthetic road stereo pairs with exact ground truth into OUT_DIR, or with
    --drive a sequence of overlapping frames with a GPS track."""
    from tqdm import tqdm

    from .data import synth as synth_mod

    _setup_logging(verbose, quiet)
    _check_synth_options(ctx, drive, spacing, potholes, gps_noise)
    total, unit = (n, "pair") if drive is None else (max(drive, 0), "frame")
    # A pair takes seconds: a bar on a terminal, else one line per pair (as `run` does); -q: neither.
    on_terminal = sys.stderr is not None and sys.stderr.isatty()
    bar = tqdm(total=total, desc="synth", unit=unit, disable=quiet or not on_terminal)

    def written_one(index: int, folder: Path, seconds: float) -> None:
        if not bar.disable:
            bar.set_postfix_str(folder.name, refresh=False)
            bar.update()
        elif not quiet:
            click.echo(f"[{index + 1}/{total}]  {folder.name}  written  {seconds:.1f} s", err=True)

    try:
        if drive is None:
            written = synth_mod.generate_dataset(out_dir, n=n, seed=seed, width=width, height=height,
                                                 on_pair=written_one)
        else:
            written = synth_mod.generate_drive(out_dir, frames=drive, seed=seed, width=width, height=height,
                                               spacing=spacing, potholes=potholes, gps_noise=gps_noise or 0.0,
                                               on_frame=written_one)
    finally:
        bar.close()
    if not quiet:
        click.echo(f"wrote {plural(len(written), unit)} to {out_dir}")


def _check_synth_options(ctx, drive, spacing, potholes, gps_noise) -> None:
    """--n belongs to pair sets, --spacing/--potholes/--gps-noise to drives."""
    if drive is not None and ctx.get_parameter_source("n") is not click.core.ParameterSource.DEFAULT:
        raise InputError(where_what_fix("synth", "--n and --drive both given",
                                        "give --n for a set of pairs or --drive for a drive, not both"))
    given = [name for name, value in (("--spacing", spacing), ("--potholes", potholes), ("--gps-noise", gps_noise))
             if value is not None]
    if drive is None and given:
        raise InputError(where_what_fix("synth", f"{', '.join(given)} given without --drive",
                                        "add --drive N, or leave them out"))


# ----------------------------------------------------------------------------- export
@main.command()
@click.argument("out_dir", type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(("kitti", "middeval3")), required=True,
              help="kitti: disp_0/<name>_10.png; middeval3: <Split>/<Scene>/disp0<ALG>.pfm and time<ALG>.txt.")
@click.option("-o", "--out", "submission", type=click.Path(path_type=Path), required=True,
              help="Folder for the submission (outside OUT_DIR).")
@click.option("--algorithm", default="D3Stereo", show_default=True, metavar="ALG",
              help="Algorithm name in MiddEval3's file names.")
@click.option("--split", default=None, metavar="SPLIT",
              help="MiddEval3 split (e.g. trainingQ) of pairs whose input path and pair name give none.")
@_verbosity
def export(out_dir, fmt, submission, algorithm, split, verbose, quiet):
    """Write the benchmark submission layout of the complete pairs of a run's OUT_DIR.

    A pair whose result.json is damaged, or whose disp.pfm is not the one the run wrote
    (size and SHA-256 in result.json), is left out with a "failed:" line; the others are
    written and the exit code is 1.
    """
    from .batch.export import export_submission

    _setup_logging(verbose, quiet)
    done = export_submission(out_dir, submission, fmt, algorithm=algorithm, split=split)
    if done.incomplete:
        click.echo(f"skipped {len(done.incomplete)} pair folders without a complete result: "
                   f"{', '.join(done.incomplete)}", err=True)
    for _pair, message in done.failed:  # damaged pairs: the others are exported, the exit is 1
        click.echo(f"failed: {message}", err=True)
    if not quiet:
        click.echo(f"wrote {plural(len(done.pairs), 'pair')} ({fmt}, {plural(len(done.files), 'file')}) to {submission}")
    if done.failed:
        raise click.ClickException(f"{out_dir}: {len(done.failed)} of "
                                   f"{plural(len(done.failed) + len(done.pairs), 'pair')} not exported (see the failed: lines); fix each as its line says, then export "
                                   "again")


# ----------------------------------------------------------------------------- info
@main.command()
def info():
    """Versions, threads, CUDA availability and the config file in use."""
    from .batch import package_versions
    from .kernels import cuda_status, device_description

    versions = package_versions()
    lines = [f"d3stereo {__version__}", f"python {platform.python_version()} ({sys.executable})",
             f"platform {platform.platform()}"]
    lines += [f"{name} {version}" for name, version in versions.items() if name != "d3stereo"]
    lines.append(f"cpu count {os.cpu_count()}")
    lines.append(_numba_threads())
    usable, reason = cuda_status()
    lines.append(f"cuda usable: {reason}" if usable else f"cuda not usable: {reason}")
    lines.append(f"cuda device: {device_description()}")
    path, why = config_search(None)
    lines.append(f"config {path} ({why})" if path else f"config none: {why} "
                 f"(searched -c, ${CONFIG_ENV}, ./{LOCAL_CONFIG})")
    lines.append(f"samples {samples_dir()}")
    click.echo("\n".join(lines))


# ----------------------------------------------------------------------------- configs
@main.command()
def configs():
    """The bundled configs (-c NAME) and the file each name resolves to from here."""
    for name, bundled in bundled_configs().items():
        resolved, how = resolve_config(name)
        where = f"{bundled} (bundled)" if how == "bundled" else f"{Path(resolved).resolve()} (local file, wins)"
        click.echo(f"{name:<11} {where}")


def _numba_threads() -> str:
    import numba

    return f"numba threads {numba.get_num_threads()} (NUMBA_NUM_THREADS={numba.config.NUMBA_NUM_THREADS})"


if __name__ == "__main__":  # pragma: no cover
    main()
