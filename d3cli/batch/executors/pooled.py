"""``--workers N``: N local processes, each taking whole pairs (largest first).

Numba and OpenCV threads are set per worker so that workers x threads <= cores.  Workers
are forked where that is safe, inheriting every imported module (a spawned worker
re-imports them: 1.2 s of CPU each on the 2-core test machine, as much as two pairs of
640x360); the first worker compiles or loads the kernels, the others then load the cache
it wrote.  At most 2 N pairs are in flight, so a huge manifest never becomes a huge
queue.  Ctrl-C: queued pairs are cancelled; the workers ignore SIGINT and finish the pair
they hold (whole pairs only, written atomically; counted as done, :meth:`PoolExecutor.drain`).
"""

from __future__ import annotations

import gc
import logging
import os
import signal
import sys
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Iterator, Sequence

from ...errors import ConfigError, D3Error
from .. import warmup
from ..warmup import call_interruptibly
from .base import available_cores, largest_first

log = logging.getLogger(__name__)

#: Environment variable forcing the pool's start method (``fork``, ``spawn``,
#: ``forkserver``); for measurements and for platforms where fork misbehaves.
START_METHOD_ENV = "D3STEREO_POOL_START"

_WORKER_WARM_S: float | None = None  # set in each pool worker by its initializer


def _numba_threads_started() -> bool:
    """Whether this process has started numba's threading layer (OpenMP); True if unknown.

    GNU OpenMP is not fork-safe: numba kills (SIGTERM) a forked child whose parent had
    started it.  Private numba state, read defensively: when it cannot be read the pool
    spawns instead of forking.
    """
    try:
        from numba.np.ufunc import parallel
    except ImportError:  # pragma: no cover - numba is a dependency
        return True
    return bool(getattr(parallel, "_is_initialized", True))


def pool_start_method() -> str:
    """How pool workers start: ``fork`` where safe (Linux, numba's threads not started and
    no other thread in this process), else ``spawn``; ``$D3STEREO_POOL_START`` overrides.

    A forked worker inherits every module this process imported (about 1.2 s of CPU per
    worker here) and numba's typing registries (0.4 s); a spawned one imports all again.
    """
    import multiprocessing
    import threading

    forced = os.environ.get(START_METHOD_ENV, "").strip().lower()
    if forced:
        if forced not in multiprocessing.get_all_start_methods():
            raise ConfigError(f"${START_METHOD_ENV}={forced}: use one of "
                              f"{', '.join(multiprocessing.get_all_start_methods())}")
        return forced
    if (sys.platform.startswith("linux") and threading.active_count() == 1
            and not _numba_threads_started()):
        return "fork"
    return "spawn"


def _preload_numba_registries() -> None:
    """Import numba's typing and lowering registries now, in the parent, so forked workers
    inherit them instead of each importing them on its first kernel (0.4 s CPU each here).

    Starts no thread (numba's threading layer is started by the first parallel kernel).
    """
    try:
        from numba.core.registry import cpu_target

        cpu_target.target_context.refresh()
    except Exception as exc:  # noqa: BLE001 - an optimisation only; the worker imports them itself
        log.debug("numba registries not preloaded: %s", exc)


def _init_pool_worker(threads: int, log_level: int, cfg, method: str | None, jit_lock, forked: bool) -> None:
    """Runs first in each worker: threads, signals, logging, then the kernels.

    ``jit_lock`` (a multiprocessing lock shared by the workers) makes the first worker
    compile the kernels, writing numba's on-disk cache, while the others wait and then
    load that cache: one compile, never a compile storm of N workers compiling the same
    kernels at once.  With a warm cache the first worker starts its first pair while the
    next one is still loading.
    """
    global _WORKER_WARM_S
    if forked:
        import numba

        # numba read NUMBA_NUM_THREADS in the parent; the mask is per thread, and the tasks
        # run in this (main) thread.
        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        # The parent's SIGTERM handler (end the batch like Ctrl-C) is not the worker's.
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
    else:
        # Before numba is imported: it reads the variable once, at import.
        os.environ["NUMBA_NUM_THREADS"] = str(threads)
    try:
        import cv2

        cv2.setNumThreads(threads)  # OpenCV's own pool too: workers x threads <= cores
    except ImportError:  # pragma: no cover - opencv is a dependency
        pass
    # Ctrl-C and a closed terminal's SIGHUP go to the whole process group; the parent
    # decides, the worker finishes its pair.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    logging.basicConfig(level=log_level, format="%(levelname)s: %(message)s", force=True)
    # numba's compiler passes and Pillow's chunk reads log at DEBUG: -v shows d3stereo's lines.
    for library in ("numba", "PIL"):
        logging.getLogger(library).setLevel(max(log_level, logging.INFO))
    if method is not None:
        with jit_lock:
            _WORKER_WARM_S = warmup.warm_jit(cfg, method)


def _worker_warm_seconds() -> float:
    """Runs in a pool worker: the seconds its initializer spent on the kernels."""
    return _WORKER_WARM_S or 0.0


class PoolExecutor:
    """``workers`` local processes taking whole pairs; ``threads`` numba threads each.

    The workers are forked from this process where that is safe (:func:`pool_start_method`),
    so they start with every module imported; the first compiles or loads the kernels,
    the others load them after it (see :func:`_init_pool_worker`).  Pairs are handed out
    largest first (:func:`largest_first`).

    Parameters
    ----------
    workers : int
        Number of worker processes (>= 2; 1 is :class:`SerialExecutor`).
    threads : int, optional, keyword-only
        Numba (and OpenCV) threads per worker; default ``max(1, cores // workers)``.
    start_method : str, optional, keyword-only
        ``fork``, ``spawn`` or ``forkserver``; default :func:`pool_start_method`.
    """

    mode = "local-pool"

    def __init__(self, workers: int, *, threads: int | None = None, start_method: str | None = None):
        self.workers = workers
        self.threads = threads or max(1, available_cores() // workers)
        self.start_method = start_method
        self.current = None
        self._pool = None
        self._pending: dict = {}  # future -> pair, submitted and not yet yielded

    def describe(self) -> dict:
        return {"mode": self.mode, "workers": self.workers, "threads_per_worker": self.threads,
                "start": self.start_method or pool_start_method()}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        # Queued pairs are dropped; pairs in flight finish (workers ignore SIGINT) and are complete.
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        return False

    def warm(self, cfg, method) -> float:
        """Start the workers; returns the seconds the first one spent compiling or loading
        the kernels (the others load the cache it wrote, see :func:`_init_pool_worker`).

        The kernels are not run here: a forked worker must not inherit a started OpenMP.
        """
        import multiprocessing

        self.start_method = self.start_method or pool_start_method()
        ctx = multiprocessing.get_context(self.start_method)
        forked = self.start_method == "fork"
        if forked:
            _preload_numba_registries()
            # The ~140,000 objects of the imported modules move to the permanent generation:
            # the workers' garbage collections no longer walk them, nor copy the memory pages
            # holding them (copy-on-write) by writing to their GC headers.
            gc.freeze()
        self._pool = ProcessPoolExecutor(
            max_workers=self.workers, mp_context=ctx, initializer=_init_pool_worker,
            initargs=(self.threads, logging.getLogger().getEffectiveLevel(), cfg, method, ctx.Lock(), forked))
        try:
            # Returns once one worker is ready, i.e. has compiled (or loaded) the kernels:
            # minutes on a cold cache, waited for in short steps so that Ctrl-C and SIGTERM
            # are answered at once (the workers ignore SIGINT and would compile on).
            ready = self._pool.submit(_worker_warm_seconds)
            _, signals = call_interruptibly(ready.result)
            if signals:
                self._stop_workers()
                signum, handler = signals[0]
                handler(signum, None)  # raises the interrupt, or holds it for the batch
                return 0.0
            return ready.result()
        except BrokenProcessPool:
            raise D3Error(f"the --workers processes could not start ({self.start_method}); "
                          f"run with --workers 1, or set {START_METHOD_ENV}=spawn") from None

    def _stop_workers(self) -> None:
        """End the worker processes now (an interrupt during their compile): what they
        compiled is in the cache already, each entry written whole (numba renames it into
        place), so the next run compiles only the rest."""
        pool, self._pool = self._pool, None
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            process.terminate()
        pool.shutdown(wait=False, cancel_futures=True)

    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, result)`` as pairs complete, largest pairs first, with at most
        2 x workers in flight."""
        todo = iter(largest_first(pairs))
        pending = self._pending

        def submit_next() -> bool:
            pair = next(todo, None)
            if pair is None:
                return False
            pending[self._pool.submit(task, pair)] = pair
            return True

        for _ in range(2 * self.workers):
            if not submit_next():
                break
        try:
            while pending:
                done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for future in done:
                    pair = pending.pop(future)
                    self.current = pair  # the pair an exception belongs to
                    result = future.result()
                    self.current = None
                    submit_next()
                    yield pair, result
        except BrokenProcessPool:
            raise D3Error("a --workers process died (killed, or out of memory); finished pairs are complete: "
                          "rerun the same command to resume, with fewer --workers if memory ran out") from None
        finally:
            for future in pending:
                future.cancel()

    def drain(self) -> list:
        """``(pair, result)`` of the pairs that were running when the batch was interrupted
        and that their workers finished since (they ignore Ctrl-C); call after leaving
        the ``with`` block, which waits for them.  Their folders are complete, so the
        interrupted message counts them."""
        finished = [(pair, future.result()) for future, pair in self._pending.items()
                    if future.done() and not future.cancelled() and future.exception() is None]
        self._pending = {}
        return finished
