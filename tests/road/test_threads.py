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
