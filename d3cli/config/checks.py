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
from .bundled import bundled_configs
from .sections import BACKENDS, METHODS, OUTPUT_CHOICES, Config, output_groups

#: Integers in a config are bounded: the kernels take 32-bit scalars.
MAX_CONFIG_INT = 2**31 - 1


# ----------------------------------------------------------------------------- checks
# Range checks: (predicate, text of what is expected).  Keys absent here take any
# value of the right type.
_RANGES: dict[str, tuple[typing.Callable[[Any], bool], str]] = {
    "run.method": (lambda v: v in METHODS, "one of " + ", ".join(METHODS)),
    "run.backend": (lambda v: v in BACKENDS, "one of " + ", ".join(BACKENDS)),
    "run.max_disparity": (lambda v: v is None or v > 0, "a positive integer or null"),
    "run.max_memory_gb": (lambda v: v is None or v > 0, "a positive number (GB) or null"),
    "run.color_range": (lambda v: len(v) == 0 or (len(v) == 2 and 0 <= v[0] < v[1]),
                        "[] or [min, max] with 0 <= min < max (pixels)"),
    "run.outputs": (lambda v: output_groups(v) is not None,
                    "a comma-separated list of " + ", ".join(OUTPUT_CHOICES) + " (e.g. survey,pictures)"),
    "pyramid.levels": (lambda v: 1 <= v <= 8, "an integer in [1, 8]"),
    "pyramid.band_margin": (lambda v: 2 <= v <= 64, "an integer in [2, 64]"),
    "pyramid.band_tile": (lambda v: 4 <= v <= 256, "an integer in [4, 256]"),
    "pyramid.finest_band_tile": (lambda v: v is None or 4 <= v <= 256, "an integer in [4, 256] or null"),
    "cost.window": (lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]"),
    "cost.level_windows": (
        lambda v: all(w >= 1 and w % 2 == 1 and w <= 31 for w in v),
        "a list of odd integers in [1, 31]",
    ),
    "cost.min_variance": (lambda v: v >= 0, "a number >= 0"),
    "cost.kind": (lambda v: v in ("ncc", "features"), "one of ncc, features"),
    "features.channel_order": (lambda v: v in ("rgb", "bgr"), "one of rgb, bgr"),
    "features.scale": (lambda v: v > 0, "a number > 0"),
    "features.mean": (lambda v: len(v) in (1, 3), "a list of 1 or 3 numbers"),
    "features.std": (lambda v: len(v) in (1, 3) and all(s > 0 for s in v), "a list of 1 or 3 numbers > 0"),
    "aggregation.t_max": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "aggregation.finest_t_max": (lambda v: v is None or 0 <= v <= 64, "an integer in [0, 64] or null"),
    "aggregation.level_t_max": (lambda v: all(0 <= t <= 64 for t in v), "a list of integers in [0, 64]"),
    "aggregation.sigma_space": (lambda v: v > 0, "a number > 0"),
    "aggregation.sigma_color": (lambda v: v > 0, "a number > 0"),
    "aggregation.kappa_a": (lambda v: 0 <= v <= 32, "an integer in [0, 32]"),
    "aggregation.bf_sigma_space": (lambda v: v is None or v > 0, "a number > 0 (pixels) or null"),
    "aggregation.sgm_p1": (lambda v: v >= 0, "a number >= 0"),
    "aggregation.sgm_p2": (lambda v: v >= 0, "a number >= 0 (0: off)"),
    "seeds.pkrn_min": (lambda v: v >= 1.0, "a number >= 1"),
    "seeds.epsilon": (lambda v: v >= 0, "a number >= 0"),
    "seeds.lr_tolerance": (lambda v: v >= 0, "an integer >= 0"),
    "seeds.pkrn_exclusion": (lambda v: v >= 0, "an integer >= 0"),
    "diffusion.tau": (lambda v: 0 <= v <= 16, "an integer in [0, 16]"),
    "diffusion.kappa_d": (lambda v: 1 <= v <= 8, "an integer in [1, 8]"),
    "diffusion.max_sweeps": (lambda v: v >= 1, "an integer >= 1"),
    "diffusion.max_gap": (lambda v: v >= 0 or v == -1, "a number >= 0, or -1 for off"),
    "inheritance.dfm_pkrn_min": (lambda v: v >= 1.0, "a number >= 1"),
    "inheritance.candidates": (lambda v: v in ("symmetric", "paper"), "one of symmetric, paper"),
    "pt.margin": (lambda v: 1 <= v <= 256, "an integer in [1, 256]"),
    "pt.slack": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "pt.min_inlier_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "pt.inlier_threshold": (lambda v: v > 0, "a number > 0"),
    "pt.iterations": (lambda v: 1 <= v <= 100, "an integer in [1, 100]"),
    "pt.max_band_end_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "pt.fallback_config": (lambda v: v == "" or v in _bundled_names(), "\"\" or the name of a bundled config"),
    "refine.smooth_kernel": (lambda v: v in ("gaussian", "box"), "one of gaussian, box"),
    "refine.subpixel_fit": (lambda v: v in ("auto", "parabola", "equiangular"), "one of auto, parabola, equiangular"),
    "refine.speckle_size": (lambda v: 0 <= v <= 100000, "an integer in [0, 100000]"),
    "refine.speckle_range": (lambda v: 0 < v <= 64, "a number in (0, 64]"),
    "refine.smooth_radius": (lambda v: 0 <= v <= 64, "an integer in [0, 64]"),
    "refine.smooth_sigma": (lambda v: v > 0, "a number > 0 (pixels)"),
    "camera.f": (lambda v: v is None or v > 0, "a positive number (pixels) or null"),
    "camera.baseline": (lambda v: v is None or v > 0, "a positive number (metres) or null"),
    "camera.min_depth_m": (lambda v: v >= 0, "a number >= 0 (metres)"),
    "camera.max_depth_m": (lambda v: v > 0, "a number > 0 (metres)"),
    "peers.elas_preset": (lambda v: v in ("middlebury", "robotics"), "one of middlebury, robotics"),
    "peers.pandora_p1": (lambda v: v >= 0, "a number >= 0"),
    "peers.pandora_p2": (lambda v: v >= 0, "a number >= 0"),
    "road.min_depth_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.min_height_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.min_area_m2": (lambda v: v >= 0, "a number >= 0 (m^2)"),
    "road.sigma_disparity": (lambda v: v > 0, "a number > 0 (pixels)"),
    "road.ring_px": (lambda v: 2 <= v <= 100, "an integer in [2, 100]"),
    "road.min_decided_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "road.colour_range_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.split_prominence_mm": (lambda v: v > 0, "a number > 0 (mm)"),
    "road.split_neck": (lambda v: 0 < v <= 1, "a number in (0, 1] (1: no split at necks)"),
    "road.split_min_area_m2": (lambda v: v >= 0, "a number >= 0 (m^2)"),
    "road.min_region_decided_share": (lambda v: 0 <= v <= 1, "a number in [0, 1]"),
    "road.frame_spacing_m": (lambda v: v >= 0, "a number >= 0 (metres; 0: unknown)"),
    "sgbm.block_size": (lambda v: v >= 1 and v % 2 == 1 and v <= 31, "an odd integer in [1, 31]"),
    "sgbm.mode": (lambda v: v in ("sgbm", "hh", "3way", "hh4"), "one of sgbm, hh, 3way, hh4"),
    # 100 kills the process: OpenCV's 3-way SGBM divides by (100 - uniquenessRatio) (SIGFPE).
    "sgbm.uniqueness_ratio": (lambda v: 0 <= v <= 99, "an integer in [0, 99]"),
    "sgbm.speckle_window": (lambda v: v >= 0, "an integer >= 0"),
    "sgbm.speckle_range": (lambda v: v >= 0, "an integer >= 0"),
    "sgbm.disp12_max_diff": (lambda v: v >= -1, "an integer >= -1"),
}


def _bundled_names() -> list[str]:
    """Names of the bundled configs."""
    return list(bundled_configs())


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
                f"fix the value of {key} (see d3cli/configs/default.yaml)"
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
        f"fix the value of {key} (see d3cli/configs/default.yaml)"
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
