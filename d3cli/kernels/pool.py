"""The task pool of the host kernels: ``func(i, n, *args)`` for every task i, on threads.

The kernels that run here (the finishing, :mod:`d3cli.kernels.finishing`, and the
semi-global smoothing's sweeps, :mod:`d3cli.kernels.sgm`) are numba functions compiled
with ``nogil``; :func:`run_tasks` runs their tasks on the calling thread and a pool,
numba's thread count of threads in all, and :func:`row_tasks` says how many blocks of rows
a map is cut into.  Tasks write disjoint cells, so results do not depend on the thread
count.  Tasks are taken in increasing order, each by a thread that runs it to the end: a
task may wait for a lower one (the smoothing's segments do), never for a higher one.  A thread pool, not ``prange``: OpenMP's spin-waiting makes the parallel
kernels slower than one thread whenever the machine is shared with other work; idle pool
threads block instead of spinning.

May import: the standard library and numba only (no kernel module: every step may use it).
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor

import numba

_POOL: ThreadPoolExecutor | None = None
_POOL_KEY: tuple[int, int] = (0, 0)  # (process id, threads) the pool was made for
_LOADED: set = set()  # (process id, task function) already called once in this process


def threads() -> int:
    """Threads the tasks run on: numba's thread count (``--threads``, NUMBA_NUM_THREADS)."""
    return max(1, numba.get_num_threads())


def run_tasks(func, n_tasks, *args, abort=None):
    """``func(i, n_tasks, *args)`` for every task i, on the pool; returns when all are done.

    The calling thread and ``threads() - 1`` pool threads take the tasks in turn from a
    shared counter: one submission per helping thread, not one per task, and the calling
    thread works instead of waiting (the finishing makes about ten such calls per map, so
    their overhead counts).  With one thread (or one task) everything runs in the calling
    thread, and so does task 0 of the first call of ``func`` in a process (it compiles or
    loads the kernel) before any other.
    Exceptions of a task are raised here, once every thread has stopped taking tasks.

    ``abort`` (tasks that wait for another): an array whose cell 0 is set to 1 as soon as a
    thread stops with an exception (a task's error, or Ctrl-C between two tasks), before
    this call waits for the other threads; a waiting task must give up when it sees it, or
    it would wait for good on a task that failed or was never taken.
    """
    global _POOL, _POOL_KEY
    n = threads()
    if n == 1 or n_tasks <= 1:
        for i in range(n_tasks):
            func(i, n_tasks, *args)
        return
    start = 0
    if (os.getpid(), func) not in _LOADED:
        # The first call of a kernel in a process compiles it or loads it from numba's
        # cache: do that here, in the calling thread, with task 0, and fan out after.
        # A pool thread loading a kernel while Ctrl-C interrupts the main thread can hang
        # in llvmlite's global lock (seen in gdb, 1 of 13 runs of the interrupt tests);
        # with the loading in the main thread an interrupt cannot strand it.
        func(0, n_tasks, *args)
        _LOADED.add((os.getpid(), func))
        start = 1
    key = (os.getpid(), n)
    if _POOL is None or _POOL_KEY != key:
        if _POOL is not None and _POOL_KEY[0] == key[0]:
            _POOL.shutdown(wait=False)  # the thread count changed (numba.set_num_threads)
        # a forked worker inherits the pool object but not its threads: make a new one
        _POOL = ThreadPoolExecutor(max_workers=n, thread_name_prefix="d3stereo-finish")
        _POOL_KEY = key
    counter = itertools.count(start)  # next() of a count is atomic (one C call under the GIL)

    def take():
        try:
            for i in counter:
                if i >= n_tasks:
                    return
                func(i, n_tasks, *args)
        except BaseException:
            if abort is not None:
                abort[0] = 1
            raise

    helpers = [_POOL.submit(take) for _ in range(min(n, n_tasks - start) - 1)]
    try:
        take()
    finally:
        for future in helpers:
            future.result()


def row_tasks(h: int) -> int:
    """Blocks of rows: a few per thread, so that a thread that was descheduled on a
    shared machine holds up little."""
    n = threads()
    return 1 if n == 1 else max(1, min(h, 4 * n))
