"""Where the pairs of a batch run: in this process, a local process pool, or a Dask cluster.

Every executor runs the same picklable per-pair task (a ``functools.partial`` of
:func:`d3cli.batch.runner._batch_pair`, which writes one pair's outputs atomically into
OUT and returns its report row and run.json record), so the per-pair files are the same
whichever runs them.  The parent (client) keeps the OUT lock, collects the results and
writes ``run.json`` / the summary.

* :class:`SerialExecutor` - one pair after the other, here (``--workers 1``, the default).
* :class:`PoolExecutor` - ``--workers N``: N processes, each taking whole pairs (largest
  first), numba and OpenCV threads set per worker so that workers x threads <= cores.
  Workers are forked where that is safe, inheriting every imported module (a spawned
  worker re-imports them: 1.2 s of CPU each on the 2-core test machine, as much as
  two pairs of 640x360); the first worker compiles or loads the kernels, the others then
  load the cache it wrote.  At most 2 N pairs are in flight, so a huge manifest never
  becomes a huge queue.
* :class:`PipelinedExecutor` (:mod:`d3cli.batch.pipelined`) - ``--prefetch N`` (``auto``:
  2 on the CUDA backend): one process, the next pairs read by a thread while this one
  computes, the previous written behind by another; for one GPU.
* :class:`DaskExecutor` (:mod:`d3cli.batch.cluster`) - ``--scheduler tcp://HOST:PORT``: each pair a task on an existing
  ``dask.distributed`` cluster, submitted through a window of in-flight futures
  (``as_completed``), checked up front (scheduler reachable, workers present with the
  same d3stereo version, OUT writable from every worker).  A worker that dies mid-pair
  has its task rescheduled elsewhere by the scheduler (``distributed.scheduler.
  allowed-failures``); a pair failing deterministically returns a ``failed`` record from
  inside the task, so it is recorded once and never retried.

Ctrl-C: queued pairs are cancelled; pool workers ignore SIGINT and finish the pair they
hold (whole pairs only, written atomically; counted as done, :meth:`PoolExecutor.drain`), Dask tasks in flight are cancelled (a
cancelled pair leaves no ``result.json``, so a rerun computes it again); the pipelined
executor's writer finishes the pairs already computed.
"""

from __future__ import annotations

import gc
import logging
import os
import signal
import sys
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Callable, Iterator, Sequence

from ..data import formats as io
from ..errors import ConfigError, D3Error
from .warmup import call_interruptibly, warm_jit

log = logging.getLogger(__name__)

#: Most ``--workers`` processes accepted (multiprocessing's semaphores overflowed on a
#: 20-digit count); a pool never has more workers than the batch has pairs.
MAX_WORKERS = 1024


def available_cores() -> int:
    """CPU cores this process may use (affinity mask where the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


#: ``--workers auto`` runs serially on this many cores or fewer (one core: a pool has
#: nothing to gain); on two quiet cores two forked workers already take about 0.8x the
#: serial wall time with the same CPU seconds (README "Scaling out", scripts/bench_scaling.py).
AUTO_SERIAL_CORES = 1


def parse_workers(value: str | int) -> int:
    """``--workers`` value -> number of worker processes (``auto``: one per core, and 1 -
    serial - on :data:`AUTO_SERIAL_CORES` core).

    Raises
    ------
    ConfigError
        When the value is neither a positive integer nor ``auto``.
    """
    if isinstance(value, int):
        n = value
    elif str(value).strip().lower() == "auto":
        cores = available_cores()
        return 1 if cores <= AUTO_SERIAL_CORES else cores
    else:
        try:
            n = int(value)
        except ValueError:
            n = 0
    if n < 1:
        raise ConfigError(f"--workers {value}: use a positive number of processes or 'auto'")
    if n > MAX_WORKERS:
        raise ConfigError(f"--workers {str(value)[:30]}: at most {MAX_WORKERS} processes; use 'auto' for one "
                          f"per core ({available_cores()} here)")
    return n


def parse_shard(value: str) -> tuple[int, int]:
    """``--shard I/N`` -> (I, N) with 1 <= I <= N.

    Raises
    ------
    ConfigError
        When the value is not of the form ``I/N`` with 1 <= I <= N.
    """
    try:
        index, total = (int(part) for part in str(value).split("/"))
    except ValueError:
        index, total = 0, 0
    if not (total >= 1 and 1 <= index <= total):
        raise ConfigError(f"--shard {value}: use I/N with 1 <= I <= N, e.g. --shard 3/8 for the third of eight")
    return index, total


def select_shard(pairs: Sequence, index: int, total: int) -> list:
    """Shard ``index`` (1-based) of ``total``: the pairs at positions index-1, index-1+total, ...
    of the pairs sorted by name.

    Every pair lands in exactly one shard, whatever order discovery returned them in.
    """
    ordered = sorted(pairs, key=lambda p: p.name)
    return [p for i, p in enumerate(ordered) if i % total == index - 1]


# ----------------------------------------------------------------------------- serial
class SerialExecutor:
    """One pair after the other in this process."""

    mode = "serial"

    def __init__(self):
        self.current = None  # the pair in progress, for run.json after an interruption

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def describe(self) -> dict:
        return {"mode": self.mode, "workers": 1}

    def warm(self, cfg, method) -> float:
        return warm_jit(cfg, method)

    def drain(self) -> list:
        """Pairs finished after an interruption: none here (the pair in progress is dropped)."""
        return []

    def imap(self, task: Callable, pairs: Sequence) -> Iterator:
        """Yield ``(pair, task(pair))`` in order."""
        for pair in pairs:
            self.current = pair
            result = task(pair)
            self.current = None
            yield pair, result


# ----------------------------------------------------------------------------- local pool
#: Environment variable forcing the pool's start method (``fork``, ``spawn``,
#: ``forkserver``); for measurements and for platforms where fork misbehaves.
START_METHOD_ENV = "D3STEREO_POOL_START"

#: Above this many pairs the pool keeps the input order instead of reading every image
#: header to start the largest pairs first (the idle tail is then a tiny share of the run).
LARGEST_FIRST_LIMIT = 20_000

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
            _WORKER_WARM_S = warm_jit(cfg, method)


def _worker_warm_seconds() -> float:
    """Runs in a pool worker: the seconds its initializer spent on the kernels."""
    return _WORKER_WARM_S or 0.0


def pair_cost(pair) -> int:
    """Estimated work of a pair: pixels x disparity range (the cost volume's size).

    From the left image's header (no decoding); 0 when it cannot be read (the pair then
    fails on its own when it runs).
    """
    try:
        size = io.image_size(pair.left)
    except Exception:  # noqa: BLE001 - an estimate only: a broken file is reported by its pair
        size = None
    if not size:
        return 0
    width, height = size
    return width * height * max(1, pair.max_disparity or width // 4)


def largest_first(pairs: Sequence, *, limit: int = LARGEST_FIRST_LIMIT) -> list:
    """``pairs`` with the most expensive first (:func:`pair_cost`; ties keep their order).

    With whole pairs per worker, a large pair started last runs alone on one worker's
    threads while the others idle; started first, the small ones fill the end.  Beyond
    ``limit`` pairs the input order is kept (reading every header would cost more than
    the tail it saves).
    """
    pairs = list(pairs)
    if len(pairs) > limit:
        return pairs
    return sorted(pairs, key=pair_cost, reverse=True)


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


def parse_prefetch(value: str | int | None) -> int | None:
    """``--prefetch`` value -> pairs read ahead (0: none, serial), or None for ``auto``.

    Raises
    ------
    ConfigError
        When the value is neither a number from 0 to :data:`MAX_PREFETCH` nor ``auto``.
    """
    if value is None or str(value).strip().lower() == "auto":
        return None
    try:
        n = int(value)
    except ValueError:
        n = -1
    if not 0 <= n <= MAX_PREFETCH:
        raise ConfigError(f"--prefetch {str(value)[:30]}: use a number of pairs from 0 (none) to {MAX_PREFETCH}, "
                          f"or 'auto' ({DEFAULT_PREFETCH} on a GPU, none on the CPU)")
    return n


#: Most pairs ``--prefetch`` reads ahead (each holds its decoded images in memory).
MAX_PREFETCH = 64


def resolve_prefetch(prefetch: int | None, cfg=None, method: str | None = None) -> int:
    """Pairs read ahead by a batch in this process: ``prefetch``, or for ``auto`` (None)
    :data:`~d3cli.batch.pipelined.DEFAULT_PREFETCH` when ``method`` runs the kernels
    (d3stereo, pt-sgm) on the CUDA backend, whose host work would otherwise leave the device
    idle; else 0 (serial: on the CPU the reading and writing threads take cores from the
    numba kernels, and sgbm, elas and pandora-sgm never use the device)."""
    if prefetch is not None:
        return prefetch
    from ..kernels import chosen_backend
    from ..kernels.cachedir import KERNEL_METHODS

    if cfg is None or method not in KERNEL_METHODS:  # sgbm, elas, pandora-sgm never use the device
        return 0

    return DEFAULT_PREFETCH if chosen_backend(cfg.run.backend) == "cuda" else 0


def make_executor(workers: int = 1, scheduler: str | None = None, out: Path | None = None,
                  n_pairs: int | None = None, *, prefetch: int | None = 0, cfg=None, method: str | None = None):
    """The executor for ``--workers`` / ``--scheduler`` / ``--prefetch`` (scheduler wins;
    1 worker is serial, or pipelined with ``prefetch`` >= 1).

    A pool gets at most ``n_pairs`` workers: more would only start, load the kernels one
    after the other and idle (``--workers 1000`` on two pairs would keep 999 processes
    alive long after both pairs are done).  ``prefetch`` (None: ``auto``, resolved for ``cfg``
    and ``method`` by :func:`resolve_prefetch`) applies to a batch in this process only:
    a pool's or a cluster's workers take whole pairs.
    """
    if scheduler:
        return DaskExecutor(scheduler, Path(out).resolve())
    if n_pairs is not None and workers > max(1, n_pairs):
        log.info("--workers %d: %d pair(s) to run, so %d worker process(es)", workers, n_pairs, max(1, n_pairs))
        workers = max(1, n_pairs)
    if workers > 1:
        if prefetch:
            log.info("--prefetch %d: not used with --workers %d (each worker takes whole pairs)", prefetch, workers)
        return PoolExecutor(workers)
    prefetch = resolve_prefetch(prefetch, cfg, method)
    if prefetch >= 1:
        return PipelinedExecutor(prefetch)
    return SerialExecutor()


from .cluster import CONNECT_TIMEOUT_S, SCHEDULER_ENV, WORKER_TIMEOUT_S, DaskExecutor  # noqa: E402 - re-exported
from .pipelined import DEFAULT_PREFETCH, PipelinedExecutor  # noqa: E402 - re-exported
