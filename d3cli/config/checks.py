"""Checking a configuration: types and ranges of every key, and the error messages.

Unknown sections or keys, wrong types and out-of-range values raise
:class:`~d3cli.errors.ConfigError` naming the file (and line), the dotted key, what was
expected and the valid keys.
"""

from __future__ import annotations

import math
import types
import typing
from dataclasses import fields, replace
from typing import Any, Mapping

from ..errors import QUOTE_CHARS, ConfigError, shorten
from .sections import Config

#: Integers in a config are bounded: the kernels take 32-bit scalars.
MAX_CONFIG_INT = 2**31 - 1


# ----------------------------------------------------------------------------- checks
def range_checks() -> dict[str, tuple[typing.Callable[[Any], bool], str]]:
    """``{"section.key": (predicate, text of what is expected)}`` of every key declared
    with a ``check`` (:func:`d3cli.config.sections.setting`); a key absent here takes any
    value of the right type."""
    return {f"{sec.name}.{f.name}": (f.metadata["check"], f.metadata["expected"])
            for sec in fields(Config) for f in fields(sec.default_factory)
            if f.metadata.get("check") is not None}


_RANGES = range_checks()


def _type_name(tp) -> str:
    names = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        return _type_name(args[0]) + " or null"
    if origin is tuple:
        return "a list of " + _type_name(typing.get_args(tp)[0])[2:] + "s"
    return names.get(tp, str(tp))


def quote(value: Any, limit: int = QUOTE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters, for error messages.

    A long or deeply nested value is quoted by its start, so that an error about it stays
    one readable line (and cannot itself exhaust memory).
    """
    if isinstance(value, (list, tuple, dict, set)) and len(value) > limit:
        return f"<{type(value).__name__} of {len(value)} items>"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _coerce(value: Any, tp, where: str, key: str):
    """Check ``value`` against the annotation ``tp``; return it in canonical form."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)][0]
        return _coerce(value, inner, where, key)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            _bad_type(value, tp, where, key)
        inner = typing.get_args(tp)[0]
        return tuple(_coerce(v, inner, where, key) for v in value)
    if tp is bool:
        if not isinstance(value, bool):
            _bad_type(value, tp, where, key)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                _bad_type(value, tp, where, key)
        if abs(value) > MAX_CONFIG_INT:
            raise ConfigError(
                f"{where}: {key} must be an integer of at most {MAX_CONFIG_INT} in size, got {quote(value)}; "
                f"fix the value of {key} (see d3cli/presets/default.yaml)"
            )
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            _bad_type(value, tp, where, key)
        if not math.isfinite(float(value)):
            _bad_type(value, tp, where, key)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            _bad_type(value, tp, where, key)
        return value
    raise TypeError(f"unsupported config annotation {tp!r}")  # programming error


def _bad_type(value, tp, where, key):
    raise ConfigError(
        f"{where}: {key} must be {_type_name(tp)}, got {quote(value)}; "
        f"fix the value of {key} (see d3cli/presets/default.yaml)"
    )


_HINTS_CACHE: dict[type, dict] = {}


def _hints(cls) -> dict:
    if cls not in _HINTS_CACHE:
        _HINTS_CACHE[cls] = typing.get_type_hints(cls)
    return _HINTS_CACHE[cls]


def _section_classes() -> dict[str, type]:
    hints = _hints(Config)
    return {f.name: hints[f.name] for f in fields(Config)}


def _at(where: str, lines: Mapping | None, *keys) -> str:
    """``where:line`` when the line of the (section, key) path is known, else ``where``."""
    line = (lines or {}).get(tuple(keys))
    return f"{where}:{line}" if line is not None else where


def apply_mapping(cfg: Config, data: Mapping, where: str, lines: Mapping | None = None) -> Config:
    """Return ``cfg`` updated with the nested mapping ``data`` (all checks applied).

    ``lines`` maps ``()``, ``(section,)`` and ``(section, key)`` to 1-based line numbers
    of the YAML file (see :func:`d3cli.config.yamlfile.read_yaml_lines`), so messages can
    name the line.

    Raises
    ------
    ConfigError
        Unknown section or key, wrong type or out-of-range value, naming ``where`` (and
        the line when known), the dotted key and what was expected.
    """
    if data is None:
        return cfg
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"{_at(where, lines)}: the top level must be a mapping of sections, got {type(data).__name__}; "
            f"valid sections: {', '.join(_section_classes())}"
        )
    sections = _section_classes()
    new_sections = {}
    for sec_name, sec_data in data.items():
        if sec_name not in sections:
            raise ConfigError(
                f"{_at(where, lines, sec_name)}: unknown section {quote(sec_name)}; valid sections: {', '.join(sections)}"
            )
        if sec_data is None:
            continue
        sec_cls = sections[sec_name]
        if not isinstance(sec_data, Mapping):
            raise ConfigError(
                f"{_at(where, lines, sec_name)}: section {sec_name} must be a mapping of keys, got {quote(sec_data)}; "
                f"valid keys: {', '.join(f.name for f in fields(sec_cls))}"
            )
        hints = _hints(sec_cls)
        changes = {}
        for key, value in sec_data.items():
            dotted = f"{sec_name}.{key}"
            at = _at(where, lines, sec_name, key)
            if key not in hints:
                raise ConfigError(
                    f"{at}: unknown key {quote(dotted)}; valid keys of {sec_name}: "
                    f"{', '.join(f.name for f in fields(sec_cls))}"
                )
            value = _coerce(value, hints[key], at, dotted)
            check = _RANGES.get(dotted)
            if check is not None and not check[0](value):
                raise ConfigError(
                    f"{at}: {dotted} must be {check[1]}, got {quote(value)}; "
                    f"fix the value of {dotted}"
                )
            changes[key] = _traced(value, where, at, dotted)
        new_sections[sec_name] = replace(new_sections.get(sec_name, getattr(cfg, sec_name)), **changes)
    return replace(cfg, **new_sections)



# ----------------------------------------------------------------------------- origins
#: Keys whose value is checked again later, against a pair or the machine (a pair's
#: width, a CUDA device), where the message must name where the value was written, not
#: the command-line option the user did not give.
TRACED_KEYS = ("run.max_disparity", "run.backend")


class _TracedInt(int):
    """An int that remembers where it was set (``origin``); equal to and used as the int."""

    origin = ""


class _TracedStr(str):
    """A str that remembers where it was set (``origin``); equal to and used as the str."""

    origin = ""


def _traced(value: Any, where: str, at: str, dotted: str) -> Any:
    if dotted not in TRACED_KEYS or isinstance(value, bool) or not isinstance(value, (int, str)):
        return value
    traced = _TracedInt(value) if isinstance(value, int) else _TracedStr(value)
    traced.origin = f"--set {dotted}" if where.startswith("--set") else f"{at}: {dotted}"
    return traced


def value_origin(value: Any, default: str) -> str:
    """Where a config value was written (``configs/x.yaml:3: run.max_disparity``, ``--set
    run.backend``), or ``default`` (the command-line option) for a value that did not
    come from a config file or ``--set``.

    Parameters
    ----------
    value : Any
        A value of a :class:`Config` (see :data:`TRACED_KEYS`) or given directly.
    default : str
        What to name when the value carries no origin, e.g. ``"--max-disparity"``.

    Returns
    -------
    str
    """
    return getattr(value, "origin", "") or default
