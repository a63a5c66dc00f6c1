"""Optional peers: ELAS and pandora census + SGM (extra ``peers``).

Without the packages (as in CI) the methods must say how to install them, in one line,
before any pair runs.  With them installed the peers must find a known disparity.
"""

import importlib.util
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from d3cli.baselines import elas_disparity, pandora_sgm_disparity
from d3cli.baselines.peers import pandora_config
from d3cli.config import INSTALL_ELAS, INSTALL_PANDORA, method_spec
from d3cli.cli import main
from d3cli.config import PeersConfig
from d3cli.errors import BackendUnavailable
from tests.helpers import textured_pair


def _hide(monkeypatch, *names):
    for name in names:
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name in names else real(name, *a))


@pytest.mark.parametrize("method, module, command", [("elas", "elas", INSTALL_ELAS),
                                                     ("pandora-sgm", "pandora", INSTALL_PANDORA)])
def test_missing_peer_is_one_error_line_naming_the_install_command(tmp_path, make_pair_folder, monkeypatch,
                                                                   method, module, command):
    _hide(monkeypatch, module)
    with pytest.raises(BackendUnavailable, match="install"):
        method_spec(method).require()
    make_pair_folder(tmp_path / "pairs", "a")
    result = CliRunner().invoke(main, ["run", str(tmp_path / "pairs"), "-o", str(tmp_path / "out"),
                                       "--method", method])
    assert result.exit_code == 1 and "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and command in errors[0] and f"--method {method} needs" in errors[0]
    assert not (tmp_path / "out" / "a").exists()  # refused before any pair ran


def test_peer_functions_raise_the_same_error_without_their_package(monkeypatch):
    _hide(monkeypatch, "elas", "pandora")
    left, right, _ = textured_pair(6)
    with pytest.raises(BackendUnavailable, match="pyelas"):
        elas_disparity(left, right, max_disparity=16)
    with pytest.raises(BackendUnavailable, match=r"pandora\[sgm\]"):
        pandora_sgm_disparity(left, right, max_disparity=16)


def test_pandora_configuration_is_the_documented_one():
    conf = pandora_config("l.tif", "r.tif", 40, PeersConfig())
    assert conf["input"]["left"]["disp"] == [-40, 0]  # pandora: x_right - x_left
    pipe = conf["pipeline"]
    assert pipe["matching_cost"] == {"matching_cost_method": "census", "window_size": 5, "subpix": 1}
    assert pipe["optimization"]["penalty"]["P1"] == 8.0 and pipe["optimization"]["penalty"]["P2"] == 32.0
    assert pipe["validation"]["cross_checking_threshold"] == 1.0
    assert pipe["filter"]["filter_size"] == 3 == pipe["filter.after.validation"]["filter_size"]


@pytest.mark.parametrize("method", ["elas", "pandora-sgm"])
def test_peer_finds_a_constant_disparity(method):
    pytest.importorskip("elas" if method == "elas" else "pandora_plugin_libsgm")
    left, right, gt = textured_pair(7, (64, 128), seed=4)
    run = elas_disparity if method == "elas" else pandora_sgm_disparity
    result = run(left, right, max_disparity=24, cfg=PeersConfig(fill=False))
    inside = result.valid & np.isfinite(gt)
    inside[:, :24] = False
    assert inside.mean() > 0.5
    assert np.median(np.abs(result.disparity[inside] - gt[inside])) < 0.5
    filled = run(left, right, max_disparity=24, cfg=PeersConfig(fill=True))
    rows = result.valid.any(axis=1)  # row-wise filling: rows with no estimate stay holes
    assert np.isfinite(filled.disparity[rows]).all() and (filled.valid == result.valid).all()
