"""Building a configuration: defaults, then a YAML file, then ``--set`` overrides.

A config is a YAML file or the name of one of the configs bundled in the package
(``configs/NAME.yaml`` of the checkout, shipped in the wheel as ``d3cli/presets``:
``road``, ``kitti``, ...), so ``-c road`` and ``load_config("road")`` work from an
installed wheel as from a checkout.
"""

from __future__ import annotations

import contextlib
import importlib.resources
import os
import typing
from pathlib import Path
from typing import Iterator, Mapping

from ..errors import ConfigError
from .checks import apply_mapping, shorten
from .bundled import CHECKOUT_FOLDER, bundled_configs
from .sections import Config
from .yamlfile import parse_override, read_yaml_lines


def _bundled_name(given: Path) -> str | None:
    """The bundled config a value may name: ``road``, ``road.yaml`` or ``configs/road.yaml``
    (its path in a source checkout, whose top-level ``configs/`` folder the package's
    ``d3cli/presets`` links to), so the checkout's path works from any folder."""
    parts = given.parts
    if len(parts) == 2 and parts[0] == CHECKOUT_FOLDER and given.suffix == ".yaml":
        return given.stem
    if len(parts) == 1 and given.suffix in ("", ".yaml"):
        return given.stem
    return None


def resolve_config(path: str | os.PathLike) -> tuple[str | os.PathLike, str]:
    """Which file a config value names, and why.

    A file at ``path`` wins; for a bare name ``road``, ``./road.yaml`` next; then the
    bundled config of that name.  Anything else is returned unchanged (reading it then
    fails with "config file not found").

    Parameters
    ----------
    path : str or path-like
        A YAML file, or the name of a bundled config (``road``, ``road.yaml``).

    Returns
    -------
    file : str or path-like
        The file to read.
    how : str
        ``"file"`` (a local file), ``"bundled"`` or ``"not found"``.
    """
    given = Path(os.fspath(path))
    if given.exists():
        return path, "file"
    name = _bundled_name(given)
    if name is None:
        return path, "not found"
    if _is_bare_name(given) and Path(f"{name}.yaml").is_file():
        return Path(f"{name}.yaml"), "file"
    bundled = bundled_configs()
    if name in bundled:
        return bundled[name], "bundled"
    return path, "not found"


def _is_bare_name(path: str | os.PathLike) -> bool:
    """``road``: no folder, no suffix (a name rather than a file)."""
    given = Path(os.fspath(path))
    return len(given.parts) == 1 and not given.suffix


@contextlib.contextmanager
def _readable(path: str | os.PathLike) -> Iterator[str | os.PathLike]:
    """A file system path for ``path`` (a bundled config inside a zipped package is
    extracted for the time of the read)."""
    if isinstance(path, (str, os.PathLike)):
        yield path
        return
    with importlib.resources.as_file(path) as real:
        yield real


def _missing(path: str | os.PathLike) -> ConfigError:
    """The error for a name that is neither a file nor a bundled config."""
    names = ", ".join(bundled_configs())
    return ConfigError(f"{os.fspath(path)}: no config file of that name and no bundled config {Path(path).stem!r}; "
                       f"give a YAML file or a bundled config: {names}")


def load_config(path: str | os.PathLike | None = None, overrides: typing.Iterable[str] = ()) -> Config:
    """Build a :class:`Config` from defaults, an optional YAML file and overrides.

    Parameters
    ----------
    path : path-like or None
        YAML file with sections as in the bundled ``default.yaml``, or the name of a
        bundled config (``"road"``, ``"road.yaml"``; see :func:`bundled_configs`); a file
        of that name wins (:func:`resolve_config`).
    overrides : iterable of str
        ``section.key=value`` strings applied after the file.

    Returns
    -------
    Config
        The frozen, validated configuration.

    Raises
    ------
    ConfigError
        Unknown sections/keys, wrong types, out-of-range values, bad YAML, a name that is
        neither a file nor a bundled config.
    """
    cfg = Config()
    overrides = list(overrides)
    if path is not None:
        path, how = resolve_config(path)
        if how == "not found" and _is_bare_name(path):
            raise _missing(path)
        with _readable(path) as real:
            data, lines = read_yaml_lines(real)
        cfg = apply_mapping(cfg, data, str(path), lines)
    for text in overrides:
        section, key, value = parse_override(text)
        # The option as written, cut: a 100,000-character value must not fill the message.
        cfg = apply_mapping(cfg, {section: {key: value}}, f"--set {shorten(text)}")
    where = " and ".join(filter(None, [str(path) if path is not None else "", "--set" if overrides else ""]))
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
