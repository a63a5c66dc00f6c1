"""The task pool of the host kernels (``d3cli.kernels.pool``): every task once, errors raised,
a kernel's first call in the calling thread."""

from __future__ import annotations

import numba
import pytest

from d3cli.kernels import pool


def test_run_tasks_runs_every_task_once_and_raises_a_task_error():
    seen = []
    pool.run_tasks(lambda i, n, out: out.append((i, n)), 7, seen)
    assert sorted(seen) == [(i, 7) for i in range(7)]

    def fail(i, n):
        if i == 3:
            raise ValueError("task 3")

    with pytest.raises(ValueError, match="task 3"):
        pool.run_tasks(fail, 5)


def test_run_tasks_loads_a_kernel_in_the_calling_thread_before_fanning_out():
    import threading

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two threads")
    numba.set_num_threads(2)
    try:
        calls = []

        def task(i, n, out):
            out.append((i, threading.current_thread() is threading.main_thread()))

        pool.run_tasks(task, 6, calls)
        assert calls[0] == (0, True)  # the first call: task 0 here, before any pool thread
        assert sorted(i for i, _ in calls) == list(range(6))
        calls.clear()
        pool.run_tasks(task, 6, calls)  # afterwards the calling thread and the pool share them
        assert sorted(i for i, _ in calls) == list(range(6))
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)

