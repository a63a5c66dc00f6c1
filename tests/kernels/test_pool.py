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



def test_a_task_waiting_for_one_that_failed_is_told_to_give_up():
    # task 2 waits for task 1, which raises: run_tasks sets abort before it waits for the
    # other threads, the waiting task gives up, the error comes out (before the abort
    # array, run_tasks waited for good on the waiting task)
    import threading
    import time

    import numpy as np

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two threads")
    done = np.zeros(3, np.int64)
    abort = np.zeros(1, np.int64)

    def task(i, n, done, abort):
        if i == 1:
            raise ValueError("task 1")
        if i == 2:
            while not done[1]:
                if abort[0]:
                    return
                time.sleep(0.001)
        done[i] = 1

    outcome = []

    def call():
        try:
            pool.run_tasks(task, 3, done, abort, abort=abort)
        except ValueError as error:
            outcome.append(str(error))

    numba.set_num_threads(2)
    try:
        caller = threading.Thread(target=call, daemon=True)
        caller.start()
        caller.join(timeout=30)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert not caller.is_alive()
    assert outcome == ["task 1"] and abort[0] == 1 and done.tolist() == [1, 0, 0]
