"""Reading YAML safely: bounded files, strict keys, YAML 1.2 scalars, ``--set`` values.

Config files and dataset manifests are read here: only small regular files, UTF-8 text,
no duplicate or non-scalar keys, no alias bombs, no deep nesting; every problem is an
error naming the file and the line.
"""

from __future__ import annotations

import os
import re
import stat
from typing import Any

import yaml

from ..errors import ConfigError
from .checks import quote, shorten

#: Largest config or manifest file read (bytes): a YAML file bigger than this is a mistake.
MAX_YAML_BYTES = 1_000_000
#: Largest YAML document, counted in nodes after expanding every alias: a few hundred
#: bytes of nested aliases ("billion laughs") would otherwise expand to gigabytes.
MAX_YAML_NODES = 100_000
#: Deepest nesting of lists/mappings in a config or manifest (a config needs 3 levels;
#: thousands of "[" would otherwise end in a RecursionError traceback).
MAX_YAML_DEPTH = 100


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that rejects duplicate and non-scalar keys (a silent override or an
    unhashable key is a user error) and reads plain scalars as YAML 1.2's core schema.

    PyYAML implements YAML 1.1: ``010`` is 8 (octal), ``1:30`` is 90 (sexagesimal),
    ``yes``/``on`` are true, ``1_000`` is 1000, ``2001-12-14`` a date, and ``1e-3`` (no
    dot) a string.  YAML 1.2, which the configuration reference promises, reads ``010``
    as 10 and the others as strings (then refused as the wrong type, naming the key).
    """


#: YAML 1.2 core schema: (tag, pattern, first characters).  Integers before floats:
#: ``10`` matches both.
_CORE_SCHEMA = (
    ("tag:yaml.org,2002:null", r"^(?:~|null|Null|NULL|)$", ["~", "n", "N", ""]),
    ("tag:yaml.org,2002:bool", r"^(?:true|True|TRUE|false|False|FALSE)$", list("tTfF")),
    ("tag:yaml.org,2002:int", r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$", list("-+0123456789")),
    ("tag:yaml.org,2002:float",
     r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$",
     list("-+0123456789.")),
    ("tag:yaml.org,2002:merge", r"^<<$", ["<"]),  # anchors merged into mappings, as SafeLoader does
)

_UniqueKeyLoader.yaml_implicit_resolvers = {}
for _tag, _pattern, _first in _CORE_SCHEMA:
    _UniqueKeyLoader.add_implicit_resolver(_tag, re.compile(_pattern), _first)


def _construct_int(loader, node):
    """A YAML 1.2 integer: decimal (leading zeros allowed: ``010`` is 10), ``0o``, ``0x``."""
    text = loader.construct_scalar(node)
    return int(text, 0) if text[:2] in ("0o", "0x") else int(text, 10)


_UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", _construct_int)


def _construct_mapping(loader, node, deep=False):
    seen = {}
    for key_node, _ in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            kind = "list" if isinstance(key_node, yaml.SequenceNode) else "mapping"
            raise ConfigError(
                f"{loader.name}:{key_node.start_mark.line + 1}: a {kind} used as a key; "
                "keys must be plain names (e.g. tau:)"
            )
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise ConfigError(
                f"{loader.name}:{key_node.start_mark.line + 1}: duplicate key {quote(key)} "
                f"(first at line {seen[key]}); keep only one"
            )
        seen[key] = key_node.start_mark.line + 1
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_UniqueKeyLoader.add_constructor(
    yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping
)


def read_yaml(path: str | os.PathLike) -> Any:
    """Parse a YAML file, raising ConfigError with file and line on any problem."""
    return read_yaml_lines(path)[0]


def _key_lines(node, loader) -> dict[tuple, int]:
    """1-based lines of the top two levels of mapping keys of a composed YAML node, and of
    the items of top-level lists."""
    lines: dict[tuple, int] = {(): node.start_mark.line + 1}
    if not isinstance(node, yaml.MappingNode):
        return lines
    for key_node, value_node in node.value:
        if not isinstance(key_node, yaml.ScalarNode):
            continue
        section = loader.construct_object(key_node)
        lines[(section,)] = key_node.start_mark.line + 1
        if isinstance(value_node, yaml.SequenceNode):  # a manifest's pairs: (section, index) -> line
            for index, item in enumerate(value_node.value):
                lines[(section, index)] = item.start_mark.line + 1
        if isinstance(value_node, yaml.MappingNode):
            for sub_key, _ in value_node.value:
                if isinstance(sub_key, yaml.ScalarNode):
                    lines[(section, loader.construct_object(sub_key))] = sub_key.start_mark.line + 1
    return lines


def read_yaml_lines(path: str | os.PathLike) -> tuple[Any, dict[tuple, int]]:
    """Parse a YAML file; return the data and the line of every section and key.

    Returns
    -------
    data : Any
        The parsed document (None for an empty file).
    lines : dict
        ``()`` -> line of the document, ``(section,)`` and ``(section, key)`` -> the
        1-based line where that key is written; ``(section, index)`` -> the line of
        item ``index`` of a top-level list.

    Raises
    ------
    ConfigError
        Missing or unreadable file, not UTF-8, invalid YAML or duplicate keys, naming the
        file and the line.
    """
    path = os.fspath(path)
    raw = read_bounded(path, what="config file", missing_fix="check the path given to -c", error=ConfigError)
    return parse_yaml(raw, path, what="config file", error=ConfigError)


def read_bounded(path: str, *, what: str, missing_fix: str, error: type = ConfigError) -> bytes:
    """The bytes of a small regular file, refusing FIFOs, devices and huge files.

    ``-c`` on a FIFO would block forever and ``-c /dev/zero`` would read without end:
    only regular files of at most :data:`MAX_YAML_BYTES` are read.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"{path}: {what} not found; {missing_fix}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc}); give a readable UTF-8 YAML file") from None
    if not stat.S_ISREG(info.st_mode):
        kind = "a folder" if stat.S_ISDIR(info.st_mode) else "not a regular file (a FIFO, socket or device)"
        raise error(f"{path}: cannot read {what}: {kind}; give a YAML file")
    if info.st_size > MAX_YAML_BYTES:
        raise error(
            f"{path}: {what} of {info.st_size} bytes is larger than {MAX_YAML_BYTES} bytes; "
            "give the YAML file itself (is this the right file?)"
        )
    try:
        with open(path, "rb") as fh:
            return fh.read(MAX_YAML_BYTES + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror or exc}); give a readable UTF-8 YAML file") from None


def _expanded_nodes(node, seen: dict, stack: set, name: str, error: type) -> int:
    """Number of nodes of ``node`` with every alias expanded (memoised, cycle-checked,
    at most :data:`MAX_YAML_DEPTH` levels deep)."""
    key = id(node)
    if key in seen:
        return seen[key]
    if key in stack:
        raise error(f"{name}:{node.start_mark.line + 1}: a recursive YAML alias; write the value out instead")
    if len(stack) >= MAX_YAML_DEPTH:
        raise _too_deep(name, error, node.start_mark.line + 1)
    stack.add(key)
    if isinstance(node, yaml.SequenceNode):
        children = node.value
    elif isinstance(node, yaml.MappingNode):
        children = [n for pair in node.value for n in pair]
    else:
        children = []
    total = 1
    for child in children:
        total += _expanded_nodes(child, seen, stack, name, error)
        if total > MAX_YAML_NODES:
            break
    stack.discard(key)
    seen[key] = total
    return total


def _too_deep(name: str, error: type, line: int | None = None):
    where = f"{name}:{line}" if line is not None else name
    return error(f"{where}: YAML nested more than {MAX_YAML_DEPTH} levels deep; "
                 "write a flat config or manifest (a config needs 3 levels)")


def parse_yaml(raw: bytes, path: str, *, what: str = "config file", error: type = ConfigError):
    """Parse YAML bytes safely; return ``(data, lines)`` as :func:`read_yaml_lines` does.

    Refuses non-UTF-8 text, NUL bytes, invalid YAML, duplicate or non-scalar keys,
    recursive aliases and documents that expand beyond :data:`MAX_YAML_NODES` nodes,
    each with ``error`` naming the file and the line.
    """
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise error(
            f"{path}:{line}: cannot read {what} (not UTF-8 text: byte 0x{raw[exc.start]:02x} at offset "
            f"{exc.start}; is it a YAML file?); give a readable UTF-8 YAML file"
        ) from None
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise error(
            f"{path}:{line}: cannot read {what} (a NUL byte: binary data, not YAML); "
            "give a readable UTF-8 YAML file"
        )
    try:
        loader = _UniqueKeyLoader(text)
        loader.name = path
        try:
            node = loader.get_single_node()
            if node is None:
                return None, {}
            if _expanded_nodes(node, {}, set(), path, error) > MAX_YAML_NODES:
                raise error(
                    f"{path}: YAML aliases expand to more than {MAX_YAML_NODES} values (an alias bomb?); "
                    "write the values out instead of nesting aliases"
                )
            data = loader.construct_document(node)
            lines = _key_lines(node, loader)
        finally:
            loader.dispose()
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = f":{mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}{line}: not valid YAML ({problem}); fix the syntax") from None
    except ConfigError as exc:  # the loader's key checks raise ConfigError
        if isinstance(exc, error):
            raise
        raise error(str(exc)) from None
    except RecursionError:  # PyYAML's composer recurses once per level, before our depth check
        raise _too_deep(path, error) from None
    return data, lines


def parse_override(text: str) -> tuple[str, str, Any]:
    """Split ``section.key=value`` into (section, key, YAML-parsed value)."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise ConfigError(
            f"--set {shorten(text)}: expected section.key=value (e.g. diffusion.tau=2); fix the option"
        )
    dotted, raw = text.split("=", 1)
    section, key = dotted.strip().split(".", 1)
    try:
        value = yaml.load(raw, Loader=_UniqueKeyLoader) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    except RecursionError:
        raise _too_deep(f"--set {shorten(text)}", ConfigError) from None
    return section, key, value
