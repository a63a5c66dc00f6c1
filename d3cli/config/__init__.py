"""Configuration: YAML -> frozen dataclasses, with every default and every check here.

A configuration is built in three layers, later ones winning:

1. the defaults written in the dataclasses (``sections``),
2. a YAML file (``-c FILE``) or a bundled config (``-c road``; ``configs/default.yaml``
   documents every key),
3. ``--set section.key=value`` overrides (values parsed as YAML scalars).

Unknown sections or keys, wrong types and out-of-range values raise
:class:`~d3cli.errors.ConfigError` naming the file, the dotted key, what was expected
and the valid keys.

- ``methods``: the stereo methods, one :class:`MethodSpec` each (name, entry point, memory
  model, the configuration it is handed and its fingerprint covers, kernels, packages):
  :data:`METHOD_SPECS`, :data:`METHODS`;
- ``sections``: one frozen dataclass per section, each key a ``setting`` (default, one-line
  meaning, range check), :class:`Config`, the backend names;
- ``checks``: the type of every key and the range checks declared with it (``setting``),
  :func:`quote`, the error messages;
- ``yamlfile``: bounded, strict YAML reading (YAML 1.2 numbers), ``--set`` parsing;
- ``bundled``: the presets, the configs shipped in the package as ``d3cli/presets`` (a link
  to the checkout's ``configs/``), by name (:func:`bundled_configs`);
- ``load``: :func:`load_config` and :func:`config_from_dict`.

May import: :mod:`d3cli.errors` only (and PyYAML); every other room may import this one.
``from d3cli.config import NAME`` works for every public name below.
"""

from ..errors import ConfigError
from .checks import MAX_CONFIG_INT, QUOTE_CHARS, quote, shorten
from .load import bundled_configs, config_from_dict, load_config, resolve_config
from .methods import INSTALL_ELAS, INSTALL_PANDORA, METHOD_SPECS, METHODS, NOT_READ_BY_MAP, MethodSpec, method_spec
from .sections import (
    BACKENDS,
    INSTALL_GIS,
    OUTPUT_CHOICES,
    OUTPUT_GROUPS,
    output_groups,
    AggregationConfig,
    CameraConfig,
    Config,
    CostConfig,
    DiffusionConfig,
    FeaturesConfig,
    InheritanceConfig,
    PeersConfig,
    PTConfig,
    PyramidConfig,
    RefineConfig,
    RoadConfig,
    RunConfig,
    SeedConfig,
    SGBMConfig,
)
from .yamlfile import (
    MAX_YAML_BYTES,
    MAX_YAML_DEPTH,
    MAX_YAML_NODES,
    parse_override,
    parse_yaml,
    read_bounded,
    read_yaml,
    read_yaml_lines,
)

__all__ = [
    "BACKENDS",
    "INSTALL_ELAS",
    "INSTALL_GIS",
    "INSTALL_PANDORA",
    "OUTPUT_CHOICES",
    "OUTPUT_GROUPS",
    "output_groups",
    "METHODS",
    "METHOD_SPECS",
    "MethodSpec",
    "NOT_READ_BY_MAP",
    "method_spec",
    "MAX_CONFIG_INT",
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "MAX_YAML_NODES",
    "QUOTE_CHARS",
    "AggregationConfig",
    "CameraConfig",
    "Config",
    "ConfigError",
    "CostConfig",
    "DiffusionConfig",
    "FeaturesConfig",
    "InheritanceConfig",
    "PeersConfig",
    "PTConfig",
    "PyramidConfig",
    "RefineConfig",
    "RoadConfig",
    "RunConfig",
    "SeedConfig",
    "SGBMConfig",
    "bundled_configs",
    "config_from_dict",
    "load_config",
    "parse_override",
    "parse_yaml",
    "quote",
    "shorten",
    "read_bounded",
    "read_yaml",
    "read_yaml_lines",
    "resolve_config",
]
