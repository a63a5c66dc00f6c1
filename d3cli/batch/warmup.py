"""Compiling the numba kernels once, before the first pair, so no pair's time includes it.

A batch calls :func:`warm_jit` up front (in the parent before a local pool fans out, on
every worker of a Dask cluster before pairs are submitted).  The kernels are compiled
with ``cache=True``, so a warm-up writes the on-disk cache that pool workers then load
instead of each compiling the same kernels at once (a compile storm).  The time it took
is stored in ``run.json`` as ``compile_s``; per-pair ``wall`` times exclude it.

A first run compiles for a minute or more: on a cold cache it says so before it starts
(:func:`d3cli.kernels.cache_location.announce`, which the command line calls before its imports)
and reports progress while it compiles (:class:`CompileProgress`), as log records of level
:data:`~d3cli.kernels.cache_location.NOTICE`, shown unless ``-q``.

Ctrl-C and SIGTERM are answered within a fraction of a second meanwhile: the compile runs
in a thread of its own while the main thread waits in short steps
(:func:`call_interruptibly`).  A signal ends the wait; the compile thread is left
running (the command line ends the process without waiting for it,
:func:`compiling_in_background`), every function it finished is in the cache already (numba
saves each one as it is compiled, writing a file whole or not at all), and how far it got
is recorded for the next run's notice (:func:`d3cli.kernels.cache_location.record_interrupted`).
"""

from __future__ import annotations

import logging
import signal
import threading
import time

import numpy as np
from numba.core import event as numba_event

from ..config import Config, method_spec
from ..errors import D3Error
from ..kernels import cache_location
from ..method.pipeline import fallback_settings
from . import dispatch
from .signals import STOP_SIGNALS

log = logging.getLogger(__name__)

NOTICE = cache_location.NOTICE
#: Seconds between two progress lines while the kernels compile.
PROGRESS_EVERY_S = 10.0
#: Seconds the main thread waits for the compile thread at a time (how late a signal is
#: seen at most, besides waiting for the interpreter's lock).
WAIT_STEP_S = 0.1
# The signals that end a wait for the compile (when their handler is a Python function):
# STOP_SIGNALS, Ctrl-C, SIGTERM and a closed terminal's SIGHUP.

#: Compile threads a signal left running (daemon threads: they never hold up an exit).
_left_running: list[threading.Thread] = []

#: Size of the warm-up pair (H, W) and its disparity range, pixels: small enough to cost
#: nothing once compiled, large enough for every window and pyramid level of the defaults.
_WARM_SHAPE = (64, 96)
_WARM_DMAX = 16


def warm_pair(shape: tuple[int, int] = _WARM_SHAPE, shift: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """A fixed textured uint8 pair ``(left, right)``, shape (H, W), right = left shifted by ``shift`` px."""
    rng = np.random.default_rng(12345)
    height, width = shape
    wide = rng.integers(0, 256, size=(height, width + shift), dtype=np.uint8)
    return wide[:, shift:].copy(), wide[:, :width].copy()


class CompileProgress(numba_event.Listener):
    """Counts numba's compiles (cache misses only; a kernel's callees each count) and logs
    progress every :data:`PROGRESS_EVERY_S` seconds:
    ``compiled 40 of about 120 kernel functions (31 s)``.

    Parameters
    ----------
    expected : int or None
        Functions a cold compile compiles, for the "of about N"; None: count only.
    every : float
        Seconds between two progress lines.
    clock : callable
        Seconds now (``time.perf_counter``).
    """

    def __init__(self, expected: int | None, every: float = PROGRESS_EVERY_S, clock=time.perf_counter):
        self.expected = expected
        self.every = every
        self.clock = clock
        self.compiled = 0
        self._t0 = self._last = clock()

    def on_start(self, event) -> None:
        pass

    def on_end(self, event) -> None:
        self.compiled += 1
        now = self.clock()
        if now - self._last >= self.every:
            self._last = now
            log.log(NOTICE, self.line(now - self._t0))

    def line(self, seconds: float) -> str:
        """``compiled 40 of about 120 kernel functions (31 s)``."""
        total = f" of about {self.expected}" if self.expected and self.expected > self.compiled else ""
        return f"compiled {self.compiled}{total} kernel functions ({seconds:.0f} s)"


def compiling_in_background() -> bool:
    """Whether a compile thread that a signal stopped waiting for still runs.

    The process should then end with ``os._exit`` once its status is decided: an ordinary
    exit finalises the interpreter and runs the C++ destructors of LLVM while that thread
    may still be compiling inside LLVM, which can crash the process at exit.
    """
    return any(thread.is_alive() for thread in _left_running)


def call_interruptibly(fn, *args) -> tuple[bool, list[tuple[int, object]]]:
    """Call ``fn(*args)`` in a thread of its own and wait for it in steps of
    :data:`WAIT_STEP_S`, so that Ctrl-C and SIGTERM are seen at once.

    numba compiles and loads kernels for minutes on a cold cache, and a handler that
    holds signals back while it does (the batch defers them: a KeyboardInterrupt raised
    inside numba's loading of a cached kernel can crash the process) would hold them for
    as long.  Here only this thread's wait sees a signal: Python runs signal handlers in
    the main thread alone, never inside the compile.

    Returns
    -------
    finished : bool
        Whether ``fn`` returned (its exception, if any, is raised here unless a signal
        came); if not, it goes on in its daemon thread (:func:`compiling_in_background`).
    signals : list of (signum, handler)
        Empty when no signal came.  Otherwise the signal that ended the wait, with the
        handler that was in place for it, which the caller calls (``handler(signum,
        None)``) once it has recorded what it must: it raises the interrupt, or holds it
        for later.  Outside the main thread, or where neither signal has a Python
        handler, ``fn`` runs in this thread: ``(True, [])``.
    """
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        handlers = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
        handlers = {sig: handler for sig, handler in handlers.items() if callable(handler)}
    if not handlers:
        fn(*args)
        return True, []
    outcome: list[BaseException] = []

    def run():
        try:
            fn(*args)
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread
            outcome.append(exc)

    received: list[int] = []

    def stop(signum, frame):
        received.append(signum)  # raising here could cut the restoring of handlers short

    worker = threading.Thread(target=run, name="d3stereo-compile", daemon=True)
    installed = []
    try:
        for sig in handlers:
            signal.signal(sig, stop)
            installed.append(sig)
        worker.start()
        while worker.is_alive() and not received:
            worker.join(WAIT_STEP_S)
    finally:
        for sig in installed:
            signal.signal(sig, handlers[sig])
    finished = not worker.is_alive()
    if not finished:
        _left_running.append(worker)
    if received:
        return finished, [(received[0], handlers[received[0]])]
    if outcome:
        raise outcome[0]
    return True, []


def _warm_pair(method: str, cfg: Config, left: np.ndarray, right: np.ndarray) -> None:
    """Run ``method`` on the warm-up pair; a failure of the pair itself (e.g. no road plane
    found by PT) is logged and ignored: the kernels it reached are compiled anyway.

    With ``pt.fallback_config`` the pair runs with those settings too: a pair of the batch
    that is not a road is matched with them, and their kernels (the semi-global smoothing
    of the defaults, say) must not be compiled inside that pair's time.
    """
    fallback = fallback_settings(cfg) if dispatch.spec_of(method).falls_back else None
    for settings in [cfg] if fallback is None else [cfg, fallback]:
        try:
            dispatch.compute_pair(method, settings, left, right, max_disparity=_WARM_DMAX)
        except D3Error as exc:
            log.debug("JIT warm-up pair failed (ignored): %s", exc)


def warm_jit(cfg: Config, method: str) -> float:
    """Run ``method`` with ``cfg`` once on a tiny pair; returns the seconds it took.

    Compiles (or loads from the numba cache) every kernel the run will use with the
    run's own types and backend.  A failure of the tiny pair itself (e.g. no road plane
    found by PT) is logged and ignored: the kernels it reached are compiled anyway.  On
    a cold cache it logs the compile notice first (unless the command line did) and
    progress while compiling.

    Ctrl-C or SIGTERM ends the wait at once (:func:`call_interruptibly`): how far the
    compile got is recorded and logged, then the signal's handler is called, which raises
    the interrupt or holds it back until the caller's block ends (the batch's deferral);
    in the latter case this returns the seconds spent.
    """
    spec = method_spec(method)
    if spec is None or not spec.kernels:  # no numba kernels: nothing to compile
        return 0.0
    compiling = cache_location.announce(method)
    done = cache_location.resume_point(method) if compiling else None  # what an interrupted compile left
    before = done or {"seconds": 0.0, "kernels": 0}
    expected = None
    if compiling:
        expected = max(cache_location.compile_estimate(method)["kernels"] - before["kernels"], 0) or None
    left, right = warm_pair()
    t0 = time.perf_counter()
    with numba_event.install_listener("numba:compile", CompileProgress(expected)) as progress:
        finished, signals = call_interruptibly(_warm_pair, method, cfg, left, right)
    seconds = time.perf_counter() - t0
    compiled = progress.compiled
    if compiling and not finished:
        cache_location.record_interrupted(method, before["seconds"] + seconds, before["kernels"] + compiled)
        log.log(NOTICE, f"compiled {compiled} kernel functions in {seconds:.0f} s before the interrupt; "
                        "they are kept in the cache, the next run compiles the rest")
    elif compiling:
        estimate = cache_location.compile_estimate(method)
        if done is None:
            cache_location.record_compile(method, seconds, compiled)
        elif not compiled:  # nothing was left after all: the estimate stands
            cache_location.record_compile(method, **estimate)
        else:
            # The rest of an interrupted compile: the seconds of both runs, and the estimate's
            # count of functions unless this run alone compiled more.  Not the sum of both
            # counts: the functions of numba's own that a kernel's compile compiles with it
            # (not cached by themselves) are compiled again for the kernels of this run.
            cache_location.record_compile(method, before["seconds"] + seconds, max(estimate["kernels"], compiled))
        log.log(NOTICE, f"compiled {compiled} kernel functions in {seconds:.0f} s")
    log.info("JIT warm-up (%s): %.2f s, %d kernel functions compiled%s", method, seconds, compiled,
             "" if finished else " (interrupted)")
    for signum, handler in signals:
        handler(signum, None)
    return seconds
