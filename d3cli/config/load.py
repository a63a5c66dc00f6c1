"""Building a configuration: defaults, then a YAML file, then ``--set`` overrides."""

from __future__ import annotations

import os
import typing
from typing import Mapping

from ..errors import ConfigError
from .checks import apply_mapping
from .sections import Config
from .yamlfile import parse_override, read_yaml_lines


def load_config(path: str | os.PathLike | None = None, overrides: typing.Iterable[str] = ()) -> Config:
    """Build a :class:`Config` from defaults, an optional YAML file and overrides.

    Parameters
    ----------
    path : path-like or None
        YAML file with sections as in ``configs/default.yaml``.
    overrides : iterable of str
        ``section.key=value`` strings applied after the file.

    Returns
    -------
    Config
        The frozen, validated configuration.

    Raises
    ------
    ConfigError
        Unknown sections/keys, wrong types, out-of-range values, bad YAML.
    """
    cfg = Config()
    overrides = list(overrides)
    if path is not None:
        data, lines = read_yaml_lines(path)
        cfg = apply_mapping(cfg, data, os.fspath(path), lines)
    for text in overrides:
        section, key, value = parse_override(text)
        cfg = apply_mapping(cfg, {section: {key: value}}, f"--set {text}")
    where = " and ".join(filter(None, [os.fspath(path) if path is not None else "", "--set" if overrides else ""]))
    _check_depth_range(cfg, where or "defaults")
    return cfg


def _check_depth_range(cfg: Config, where: str) -> None:
    """camera.min_depth_m < camera.max_depth_m, checked once all values are in (file and --set)."""
    cam = cfg.camera
    if cam.min_depth_m >= cam.max_depth_m:
        raise ConfigError(
            f"{where}: camera.min_depth_m ({cam.min_depth_m:g}) must be smaller than camera.max_depth_m "
            f"({cam.max_depth_m:g}); fix the depth range of the point clouds"
        )


def config_from_dict(data: Mapping | None, where: str = "<dict>") -> Config:
    """Build a validated :class:`Config` from a nested mapping (e.g. run.json)."""
    cfg = apply_mapping(Config(), data or {}, where)
    _check_depth_range(cfg, where)
    return cfg
