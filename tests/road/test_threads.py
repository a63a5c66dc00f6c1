"""The road report's helper thread (d3cli.road.threads): results in order, errors raised."""

import numba
import pytest

from d3cli.road import threads


@pytest.mark.parametrize("n_threads", [1, 2])
def test_map_on_threads_keeps_the_order_and_job_raises(n_threads):
    before = numba.get_num_threads()
    numba.set_num_threads(min(n_threads, numba.config.NUMBA_NUM_THREADS))
    try:
        assert threads.map_on_threads(lambda x: x * x, range(50)) == [x * x for x in range(50)]
        done = []
        job = threads.Job(done.append, 1)
        job.result()
        job.restart(done.append, 2)
        job.result()
        assert done == [1, 2]

        def fail():
            raise ValueError("no")

        with pytest.raises(ValueError):
            threads.Job(fail).result()
        with pytest.raises(ValueError):
            threads.map_on_threads(lambda x: fail() if x == 7 else x, range(10))
    finally:
        numba.set_num_threads(before)


def test_map_on_threads_does_not_wait_for_a_busy_helper():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one thread: no helper")
    import threading
    import time

    before = numba.get_num_threads()
    numba.set_num_threads(2)
    release = threading.Event()
    try:
        job = threads.Job(release.wait, 30.0)  # the helper is busy until released
        t0 = time.perf_counter()
        assert threads.map_on_threads(lambda x: x + 1, range(20)) == list(range(1, 21))
        # every item taken here; the call queued for the helper is dropped, not waited for
        assert time.perf_counter() - t0 < 5.0 and not release.is_set()
    finally:
        release.set()
        job.result()
        numba.set_num_threads(before)
