"""Fixtures shared by the batch tests."""

from __future__ import annotations

import pytest


@pytest.fixture
def local_cluster():
    """A ``distributed.LocalCluster`` of two single-threaded worker processes on 127.0.0.1."""
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                                       dashboard_address=None, worker_dashboard_address=None)
    try:
        yield cluster
    finally:
        cluster.close()
