"""A value from a config file that a pair or the machine cannot take is blamed on the file
and its key, not on a command-line option the user did not give."""

import pytest

from d3cli import kernels
from d3cli.config import load_config
from d3cli.config.checks import value_origin
from d3cli.data import layouts as datasets
from d3cli.errors import BackendUnavailable, InputError


def config_file(tmp_path, text):
    path = tmp_path / "x.yaml"
    path.write_text(text)
    return path


def test_max_disparity_from_a_config_names_the_file_and_key(tmp_path, pairs_root):
    path = config_file(tmp_path, "run:\n  max_disparity: 500\n")
    cfg = load_config(path)
    pair = datasets.discover([pairs_root])[0]
    with pytest.raises(InputError) as info:
        datasets.resolve_max_disparity(pair, 96, override=cfg.run.max_disparity)
    assert str(info.value) == (f"{path}:2: run.max_disparity: 500 must be in [1, 95] for pair a (image width 96); "
                               "set a smaller value there, or pass --max-disparity")


def test_max_disparity_from_set_names_the_option(pairs_root):
    cfg = load_config(None, ["run.max_disparity=500"])
    pair = datasets.discover([pairs_root])[0]
    with pytest.raises(InputError) as info:
        datasets.resolve_max_disparity(pair, 96, override=cfg.run.max_disparity)
    assert str(info.value).startswith("--set run.max_disparity: 500 must be in [1, 95] for pair a")


def test_max_disparity_from_the_option_keeps_its_message(pairs_root):
    pair = datasets.discover([pairs_root])[0]
    with pytest.raises(InputError) as info:
        datasets.resolve_max_disparity(pair, 96, override=500)
    assert str(info.value) == "a: --max-disparity 500 must be in [1, 95] (image width 96); give a smaller positive value"


def test_traced_values_equal_plain_ones(tmp_path):
    cfg = load_config(config_file(tmp_path, "run:\n  max_disparity: 64\n  backend: cpu\n"))
    assert cfg.run.max_disparity == 64 and cfg.run.backend == "cpu"
    assert cfg.to_dict()["run"]["max_disparity"] == 64
    assert value_origin(cfg.run.backend, "--backend") == f"{tmp_path / 'x.yaml'}:3: run.backend"
    assert value_origin("cpu", "--backend") == "--backend"


def test_cuda_backend_from_a_config_names_the_file_and_key(tmp_path, monkeypatch):
    monkeypatch.setattr(kernels, "_cuda_probe", lambda: (None, "no CUDA driver"))
    path = config_file(tmp_path, "run:\n  backend: cuda\n")
    with pytest.raises(BackendUnavailable) as info:
        kernels.get_backend(load_config(path).run.backend)
    assert str(info.value) == (f"{path}:2: run.backend: cuda cannot be used (no CUDA driver); set it to cpu or auto "
                               "there, or pass --backend cpu")
    with pytest.raises(BackendUnavailable) as info:
        kernels.get_backend("cuda")
    assert str(info.value) == "--backend cuda: no CUDA driver; use --backend cpu or auto"
