"""The methods' declarations (d3cli.config.methods) are what the CLI, the dispatch and the
resume fingerprint read: each names an entry point that exists, in a room batch may import."""

from __future__ import annotations

import dataclasses
import inspect

import click
import pytest

from d3cli.batch import dispatch, settings_fingerprint
from d3cli.cli import main
from d3cli.config import METHOD_SPECS, METHODS, NOT_READ_BY_MAP, Config, ConfigError


def test_the_names_are_the_declarations_and_unique():
    assert METHODS == tuple(spec.name for spec in METHOD_SPECS)
    assert len(set(METHODS)) == len(METHODS)
    assert METHODS[0] == "d3stereo"  # the default of run.method


@pytest.mark.parametrize("spec", METHOD_SPECS, ids=lambda s: s.name)
def test_each_entry_point_exists_in_method_or_baselines_and_takes_the_call(spec):
    module = spec.compute.partition(":")[0]
    assert module.split(".")[:2] in (["d3cli", "method"], ["d3cli", "baselines"]), spec.compute
    function = spec.entry_point()
    parameters = inspect.signature(function).parameters
    assert {"max_disparity", "cfg"} <= set(parameters)
    assert ("pair_dir" in parameters) == spec.pair_dir
    assert spec.section is None or spec.section in Config().to_dict()
    assert spec.doc and "\n" not in spec.doc


def test_the_cli_offers_the_declared_methods():
    option = next(p for p in main.commands["run"].params if p.name == "method")
    assert isinstance(option.type, click.Choice) and tuple(option.type.choices) == METHODS


def test_an_unknown_method_is_named_with_the_choices():
    with pytest.raises(ConfigError) as caught:
        dispatch.spec_of("nope")
    assert str(caught.value) == "--method nope: unknown method; use one of " + ", ".join(METHODS)


@pytest.mark.parametrize("spec", METHOD_SPECS, ids=lambda s: s.name)
def test_the_fingerprint_covers_what_the_method_is_handed(spec):
    cfg = Config()
    sections = list(cfg.to_dict())
    covered = spec.fingerprinted(sections)
    if spec.section is not None:
        assert covered == (spec.section,)
    else:
        assert set(covered) == set(sections) - set(NOT_READ_BY_MAP)
    base = settings_fingerprint(cfg, spec.name, None)
    for name in sections:
        if name == "run":
            continue
        first = next(f for f in Config.__dataclass_fields__[name].default_factory.__dataclass_fields__.values())
        value = getattr(getattr(cfg, name), first.name)
        changed = not value if isinstance(value, bool) else (
            (value or 0) + 1 if isinstance(value, (int, float)) or value is None else
            (value + "x" if isinstance(value, str) else value + (1,)))
        other = dataclasses.replace(cfg, **{name: dataclasses.replace(getattr(cfg, name), **{first.name: changed})})
        assert (settings_fingerprint(other, spec.name, None) != base) == (name in covered), name


def test_only_the_kernel_methods_compile_warm_up_and_prefetch_and_the_peers_name_their_extra():
    from d3cli.batch.executors import resolve_prefetch
    from d3cli.batch.warmup import warm_jit

    assert {s.name for s in METHOD_SPECS if s.kernels} == {"d3stereo", "pt-sgm"}
    assert {s.name: s.extra for s in METHOD_SPECS if s.extra} == {"elas": "peers", "pandora-sgm": "peers"}
    cfg = dataclasses.replace(Config(), run=dataclasses.replace(Config().run, backend="cuda"))
    for spec in METHOD_SPECS:
        if not spec.kernels:
            # Nothing of ours to compile, and nothing that uses the device to keep busy.
            assert warm_jit(cfg, spec.name) == 0.0
            assert resolve_prefetch(None, cfg, spec.name) == 0


@pytest.mark.parametrize("spec", METHOD_SPECS, ids=lambda s: s.name)
def test_each_memory_model_is_declared_and_grows_with_the_pair(spec):
    cfg = Config()
    small = spec.estimate_peak_bytes((48, 96), 32, cfg)
    assert small > 48 * 96  # at least a byte per pixel
    assert spec.estimate_peak_bytes((96, 96), 32, cfg) > small
    assert spec.estimate_peak_bytes((48, 96, 3), 32, cfg) == small  # colour images: the same (H, W)


def test_a_missing_package_is_named_with_its_install_command(monkeypatch):
    from d3cli.errors import BackendUnavailable

    spec = dataclasses.replace(METHOD_SPECS[0], name="toy", requires=("d3stereo_no_such_module",), install="pip install toy")
    with pytest.raises(BackendUnavailable) as caught:
        spec.require()
    assert str(caught.value) == ("--method toy needs the package(s) d3stereo_no_such_module, which are not "
                                 "installed; install them with pip install toy")
    METHOD_SPECS[0].require()  # nothing beyond d3stereo's dependencies: no error


TOY_METHOD = '''
import numpy as np
from d3cli.method import DisparityResult

CALLS = []


def toy_disparity(left, right, *, max_disparity, cfg):
    """A constant disparity of 3 px everywhere: enough to see the batch run it."""
    CALLS.append(cfg.outputs)
    shape = np.asarray(left).shape[:2]
    return DisparityResult(np.full(shape, 3.0, np.float32), np.ones(shape, bool), info={"method": "toy"})


def toy_peak_bytes(shape, max_disparity, cfg):
    return 100 * int(shape[0]) * int(shape[1])
'''


def test_a_method_declared_once_runs_a_batch(tmp_path, monkeypatch, pairs_root):
    """Adding a method is its module and its declaration: the dispatch, the memory check,
    the warm-up, the fingerprint and the outputs need no change (docs/design.md, 'Extending')."""
    import json
    import sys

    from d3cli.batch import run_batch
    from d3cli.config import methods as declarations
    from d3cli.data.layouts import discover

    (tmp_path / "toy_method.py").write_text(TOY_METHOD, encoding="utf-8")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "toy_method", raising=False)
    toy = declarations.MethodSpec("toy", "toy_method:toy_disparity", doc="a constant disparity",
                                  peak_bytes="toy_method:toy_peak_bytes", section="run")
    monkeypatch.setattr(declarations, "METHOD_SPECS", declarations.METHOD_SPECS + (toy,))
    result = run_batch(discover([pairs_root]), tmp_path / "out", cfg=Config(), method="toy", progress=False)
    assert (result.n_computed, result.n_failed) == (3, 0)
    import toy_method

    assert toy_method.CALLS == [Config().run.outputs] * 3  # handed its declared section
    record = json.loads((tmp_path / "out" / "a" / "result.json").read_text())
    assert record["method"] == "toy"
