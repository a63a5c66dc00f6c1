"""Manifest YAMLs: a root, an optional layout, a list of pairs and defaults
(see ``data_manifests/README.md``).
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any

from ...config import MAX_CONFIG_INT, parse_yaml, quote, read_bounded
from ...errors import InputError, where_what_fix
from .. import formats
from .detect import expand_layout
from .folders import _canonical_invalid
from .pair import DEFAULT_KEYS, LAYOUTS, MANIFEST_KEYS, PAIR_KEYS, Pair, _SAFE_NAME, _abs, family_from_name


def _read_manifest_yaml(path: Path) -> tuple[Any, dict]:
    """The parsed manifest and its lines (see :func:`d3cli.config.parse_yaml`): a bounded
    regular file, safe YAML (no alias bombs, no duplicate keys), every problem an
    InputError naming the file and the line."""
    raw = read_bounded(str(path), what="manifest file", missing_fix="check the path", error=InputError)
    return parse_yaml(raw, str(path), what="manifest file", error=InputError)


def _check_unique_names(pairs: list[Pair], lines: dict, path: Path) -> None:
    """Two entries of ``pairs:`` with one name: name both entries and their lines (the
    generic message would suggest naming the pairs in a manifest, which they are)."""
    first: dict[str, int] = {}
    for index, pair in enumerate(pairs):
        if pair.name in first:
            earlier = first[pair.name]
            raise InputError(where_what_fix(
                str(path), f"pair name {pair.name!r} is used twice (pairs[{earlier}] at line "
                           f"{lines.get(('pairs', earlier), '?')} and pairs[{index}] at line "
                           f"{lines.get(('pairs', index), '?')})", "give each pair its own name"))
        first[pair.name] = index


def _check_value(key: str, value: Any, where: str) -> Any:
    """Validate and normalise one manifest value (pair entry or top-level default)."""
    if key in ("name", "left", "right", "gt", "nocc", "calib", "family"):
        if value is None and key in ("gt", "nocc", "calib"):
            return None
        if not isinstance(value, str) or (key != "family" and not value.strip()):
            raise InputError(where_what_fix(where, f"{key} must be a string, got {value!r}", f"write {key}: <text>"))
        if key == "name" and not _SAFE_NAME.match(value):
            raise InputError(
                where_what_fix(
                    where, f"name {value!r} is not filesystem-safe", "use letters, digits, '.', '_' and '-' only"
                )
            )
        return value
    if key == "gt_scale":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
            raise InputError(where_what_fix(where, f"gt_scale must be a number > 0, got {value!r}", "e.g. gt_scale: 256"))
        return float(value)
    if key == "gt_invalid":
        return _canonical_invalid(value, where)
    if key == "bit_depth":
        if value is None:
            return None
        number = _whole_number(value)
        if number is None or not 1 <= number <= 16:
            raise InputError(
                where_what_fix(where, f"bit_depth must be an integer in [1, 16], got {quote(value)}", "e.g. bit_depth: 12")
            )
        return number
    if key == "max_disparity":
        if value is None:
            return None
        number = _whole_number(value)
        if number is None or not 1 <= number <= MAX_CONFIG_INT:
            raise InputError(where_what_fix(
                where, f"max_disparity must be a positive integer of at most {MAX_CONFIG_INT}, got {quote(value)}",
                "e.g. max_disparity: 64"))
        return number
    raise KeyError(key)  # pragma: no cover - callers check the key first


def _whole_number(value) -> int | None:
    """``value`` as an int when it is a whole number (``64``, ``64.0``, ``1e2`` as YAML 1.2
    reads it), else None; as the config reads integer keys, so a manifest and a config accept the same numbers."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        return int(value)
    return None


def _manifest_path(root: Path, value: str, key: str, where: str) -> Path:
    path = _abs(root / os.path.expanduser(value))
    kind = "a folder" if path.is_dir() else formats.special_file_kind(path)
    if kind is not None:
        raise InputError(where_what_fix(where, f"{key} is not a regular file ({kind}): {path}", "give the file itself"))
    if not path.is_file():
        raise InputError(
            where_what_fix(where, f"{key} file not found: {path}", f"fix the path (relative to root {root})")
        )
    return path


def _manifest_pair(entry: Any, index: int, root: Path, defaults: dict, manifest: Path) -> Pair:
    where = f"{manifest} pairs[{index}]"
    if not isinstance(entry, dict):
        raise InputError(where_what_fix(where, f"expected a mapping, got {type(entry).__name__}", "write - name: ..."))
    if isinstance(entry.get("name"), str):
        where += f" ({entry['name']})"
    unknown = sorted(set(map(str, entry)) - set(PAIR_KEYS))
    if unknown:
        raise InputError(
            where_what_fix(where, f"unknown key {unknown[0]!r}", f"valid keys are {', '.join(PAIR_KEYS)}")
        )
    for key in ("name", "left", "right"):
        if key not in entry:
            raise InputError(where_what_fix(where, f"missing key {key!r}", "every pair needs name, left and right"))
    values = {**defaults, **{key: _check_value(key, value, where) for key, value in entry.items()}}
    fields = {key: values[key] for key in ("name", "gt_scale", "gt_invalid", "max_disparity", "family", "bit_depth")
              if key in values}
    for key in ("left", "right", "gt", "nocc", "calib"):
        if values.get(key) is not None:
            fields[key] = _manifest_path(root, values[key], key, where)
    if "family" not in fields:
        fields["family"] = family_from_name(fields["name"])
    return Pair(**fields)


def load_manifest(path: str | os.PathLike) -> list[Pair]:
    """Read a manifest YAML (format in ``data_manifests/README.md``) into pairs.

    Parameters
    ----------
    path : str or os.PathLike
        The manifest file; its ``root:`` is relative to the file's folder.

    Raises
    ------
    InputError
        Missing file, invalid YAML, unknown or missing keys, files that do not exist,
        duplicate names; messages name the manifest and the pair index.
    """
    path = _abs(path)
    doc, lines = _read_manifest_yaml(path)
    if not isinstance(doc, dict):
        raise InputError(
            where_what_fix(str(path), "a manifest must be a mapping with root: and pairs: (or layout:)", "see data_manifests/README.md")
        )
    unknown = sorted(set(map(str, doc)) - set(MANIFEST_KEYS))
    if unknown:
        raise InputError(
            where_what_fix(str(path), f"unknown key {unknown[0]!r}", f"valid top-level keys are {', '.join(MANIFEST_KEYS)}")
        )
    if "pairs" not in doc and "layout" not in doc:
        raise InputError(where_what_fix(str(path), "missing key 'pairs' (and no 'layout')", "list the pairs or name a layout"))
    root_value = doc.get("root", ".")
    if not isinstance(root_value, str):
        raise InputError(where_what_fix(str(path), f"root must be a path string, got {root_value!r}", "write root: <folder>"))
    root = _abs(path.parent / os.path.expanduser(root_value))
    if not root.is_dir():
        raise InputError(
            where_what_fix(
                str(path), f"root folder not found: {root}", "root: is relative to the manifest file; download the data there or fix root:"
            )
        )
    defaults = {key: _check_value(key, doc[key], str(path)) for key in DEFAULT_KEYS if key in doc}
    pairs: list[Pair] = []
    if doc.get("layout") is not None:
        layout = doc["layout"]
        if layout != "auto" and layout not in LAYOUTS:
            raise InputError(
                where_what_fix(str(path), f"unknown layout {layout!r}", f"use one of auto, {', '.join(LAYOUTS)}")
            )
        pairs += [dataclasses.replace(pair, **defaults) for pair in expand_layout(root, layout)]
    entries = doc.get("pairs") or []
    if not isinstance(entries, list):
        raise InputError(where_what_fix(str(path), "pairs must be a list", "write pairs: then '- name: ...' entries"))
    listed = [_manifest_pair(entry, index, root, defaults, path) for index, entry in enumerate(entries)]
    _check_unique_names(listed, lines, path)
    pairs += listed
    if not pairs:
        raise InputError(where_what_fix(str(path), "the manifest lists no pairs", "add entries under pairs:"))
    return pairs
