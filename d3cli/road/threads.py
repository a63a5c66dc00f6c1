"""The road report's second thread: work that runs beside the report's own.

The stereo runs on numba's threads (``--threads``); while a pair's road report runs they
are idle, so the report hands independent work (the height files, the re-match of each
defect, the candidate regions of a map) to one helper thread.  Most of that work is
OpenCV, NumPy on whole arrays and compiled loops, which release the interpreter lock.
Results never depend on which thread ran what.  May import numba and the standard
library only.
"""

from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba

_HELPER: tuple = (0, None)  # (process id, ThreadPoolExecutor of one thread)
_NAME = "d3stereo-road"


def helper():
    """The helper thread (an executor of one), or None with one thread (numba's thread count)."""
    global _HELPER
    if numba.get_num_threads() < 2 or threading.current_thread().name.startswith(_NAME):
        return None  # one thread, or the helper itself (it never waits for its own queue)
    if _HELPER[0] != os.getpid():  # a forked worker inherits the object but not its thread
        _HELPER = (os.getpid(), ThreadPoolExecutor(max_workers=1, thread_name_prefix=_NAME))
    return _HELPER[1]


class Job:
    """``func(*args)`` started on the helper thread; :meth:`result` waits for it and raises
    its exception.  Without a helper thread the call runs when its result is asked for, and
    a :meth:`restart` before that replaces it (the work done once, with the last arguments)."""

    def __init__(self, func, *args):
        self._future = self._call = None
        self.restart(func, *args)

    def restart(self, func, *args):
        """Start ``func(*args)``; a call already started must be finished (:meth:`result`)."""
        pool = helper()
        if pool is None:
            self._call = (func, args)
        else:
            self._future = pool.submit(func, *args)

    def result(self):
        """Wait for the call (or make it here); its exception is raised here."""
        if self._call is not None:
            (func, args), self._call = self._call, None
            func(*args)
        if self._future is not None:
            future, self._future = self._future, None
            future.result()


def halves(n: int) -> tuple:
    """The two slices of ``n`` items (the first ``n // 2``, then the rest) that
    :func:`map_on_threads` hands to this thread and the helper: one large compiled loop
    split over both."""
    return slice(0, n // 2), slice(n // 2, n)


def map_on_threads(func, items) -> list:
    """``[func(x) for x in items]``, the items taken in turn by this thread and the helper
    thread; the results in the items' order.  The helper may be busy (a :class:`Job`, or
    the items of another call): this thread then takes every item, and does not wait for
    the helper to come round to a call that has nothing left to take."""
    items = list(items)
    pool = helper()
    if pool is None or len(items) < 2:
        return [func(x) for x in items]
    results = [None] * len(items)
    counter = itertools.count()  # next() of a count is atomic (one C call under the interpreter lock)

    def take():
        for i in counter:
            if i >= len(items):
                return
            results[i] = func(items[i])

    future = pool.submit(take)
    try:
        take()
    finally:
        if not future.cancel():  # started: wait for the item it is on
            future.result()
    return results
