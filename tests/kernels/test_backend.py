"""The backend contract: both backends provide every function of
:class:`d3cli.kernels.backend.Backend`, with the same parameters."""

from __future__ import annotations

import inspect

import pytest

from d3cli.kernels import backend, cpu, cuda_status

CONTRACT = [name for name in vars(backend.Backend) if not name.startswith("_")]


def _parameters(function):
    return [p.name for p in inspect.signature(function).parameters.values()]


def test_the_contract_lists_the_pipeline_functions():
    assert {"ncc_cost_volume", "rbf_filter", "sgm_smooth", "decisive_seeds", "diffuse", "inherit", "subpixel",
            "pt_warp", "pt_restore", "to_device", "to_host", "merge_sparse", "count_decided"} <= set(CONTRACT)


@pytest.mark.parametrize("name", CONTRACT)
def test_the_cpu_backend_provides_the_contract(name):
    assert _parameters(getattr(cpu, name)) == _parameters(getattr(backend.Backend, name))[1:]


@pytest.mark.parametrize("name", CONTRACT)
def test_the_cuda_backend_provides_the_contract(name):
    usable, why = cuda_status()
    if not usable:
        pytest.skip(f"CUDA is not usable here: {why}")
    from d3cli.kernels import cuda

    assert _parameters(getattr(cuda, name)) == _parameters(getattr(backend.Backend, name))[1:]
