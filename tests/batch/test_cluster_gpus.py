"""Dask workers that declare GPUs (``dask worker --resources GPU=1``, one worker per GPU):
each pair holds one GPU while it runs, so two pairs never share a device."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from d3cli.batch.executors import DaskExecutor


def _gpus_left_while_running(pair):
    """The task: how many GPU slots its worker has left while the pair runs."""
    import distributed

    return distributed.get_worker().state.available_resources.get("GPU")


def _pairs(n):
    return [SimpleNamespace(name=f"p{i}", left="missing.png", max_disparity=1) for i in range(n)]


@pytest.mark.parametrize("gpus, expected", [(1, 0), (None, None)], ids=["gpu-workers", "cpu-workers"])
def test_each_pair_holds_one_gpu_where_workers_declare_them(tmp_path, gpus, expected):
    distributed = pytest.importorskip("distributed")
    extra = {"resources": {"GPU": gpus}} if gpus else {}
    with distributed.LocalCluster(n_workers=2, processes=False, protocol="tcp://", threads_per_worker=2, host="127.0.0.1",
                                  dashboard_address=None, **extra) as cluster:
        with DaskExecutor(cluster.scheduler_address, tmp_path) as executor:
            assert executor.describe()["gpus"] == (2 if gpus else 0)
            left = [value for _, value in executor.imap(_gpus_left_while_running, _pairs(6))]
    # with GPU=1 on each worker, a running pair holds the worker's only GPU: 0 left
    assert left == [expected] * 6
