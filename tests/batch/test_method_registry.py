"""The methods' declarations (d3cli.config.methods) are what the CLI, the dispatch and the
resume fingerprint read: each names an entry point that exists, in a room batch may import."""

from __future__ import annotations

import dataclasses
import inspect

import click
import pytest

from d3cli.batch import methods, settings_fingerprint
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
    function = methods.entry_point(spec)
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
        methods.spec_of("nope")
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
