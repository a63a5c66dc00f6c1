""":func:`discover`: folders, manifests or two image files -> one sorted list of pairs."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from ...errors import InputError, where_what_fix
from .. import formats
from .detect import expand_layout
from .files import _is_image, _missing_why
from .manifest import load_manifest
from .pair import MANIFEST_EXTENSIONS, Pair, _EXPECTED, _abs, family_from_name, safe_name


_GENERIC_LEFT_STEMS = {"left", "im0", "iml", "view1", "image_l", "l", "im2"}


def _add_input(item: Path, pairs: list[Pair], images: list[Path]) -> None:
    """Add the pairs of one input (a folder or a manifest) to ``pairs``, or the input to
    ``images`` when it is an image file."""
    if item.is_dir():
        pairs += expand_layout(item)
    elif item.is_file() and item.suffix.lower() in MANIFEST_EXTENSIONS:
        pairs += load_manifest(item)
    elif item.is_file() and _is_image(item):
        images.append(item)
    elif formats.special_file_kind(item) is not None:
        raise InputError(where_what_fix(str(item), f"not a regular file ({formats.special_file_kind(item)})",
                                        "give the file itself"))
    elif item.exists():
        raise InputError(
            where_what_fix(str(item), f"not a folder, manifest or image ({item.suffix or 'no extension'})", f"give {_EXPECTED}")
        )
    else:
        raise InputError(where_what_fix(str(item), *_missing_why(item)))


def _pair_from_two_files(left: Path, right: Path) -> Pair:
    stem = left.stem.lower()
    base = left.parent.name if stem in _GENERIC_LEFT_STEMS and left.parent.name else left.stem
    name = safe_name(base)
    return Pair(name=name, left=left, right=right, family=family_from_name(name))


def _unique(pairs: list[Pair]) -> list[Pair]:
    by_name: dict[str, Pair] = {}
    for pair in pairs:
        seen = by_name.get(pair.name)
        if seen is not None and seen != pair:
            raise InputError(
                where_what_fix(
                    pair.name,
                    f"two different pairs share this name ({seen.left} and {pair.left})",
                    "give the inputs in separate runs or name the pairs in a manifest",
                )
            )
        by_name[pair.name] = pair
    return sorted(by_name.values(), key=lambda pair: pair.name)


def discover(inputs: Sequence[str | os.PathLike] | str | os.PathLike) -> list[Pair]:
    """Find the stereo pairs of every input, auto-detecting each layout.

    Parameters
    ----------
    inputs : sequence of str or path-like (a single path is accepted too)
        Folders (any layout of the module docstring), manifest YAMLs, or exactly two
        image files (left, right).

    Returns
    -------
    list of Pair
        Sorted by name; the same pair reached twice is listed once.

    Raises
    ------
    InputError
        Missing paths, an unknown layout, a folder without pairs, an incomplete pair, a
        bad manifest, a number of image files other than two, or a path the system
        refuses to examine (longer than it allows, no permission).
    """
    inputs = [inputs] if isinstance(inputs, (str, os.PathLike)) else list(inputs)
    if not inputs:
        raise InputError(where_what_fix("discover", "no inputs given", f"give {_EXPECTED}"))
    pairs: list[Pair] = []
    images: list[Path] = []
    for given in inputs:
        item = _abs(given)
        try:
            _add_input(item, pairs, images)
        except OSError as exc:  # not "not found" (that is _add_input's own error): too long, no permission, I/O
            raise formats.unreadable(given, exc) from None
    if images:
        if len(images) != 2:
            raise InputError(
                where_what_fix(
                    ", ".join(str(image) for image in images),
                    f"got {len(images)} image files",
                    "give exactly two image files (left, right), or a folder",
                )
            )
        pairs.append(_pair_from_two_files(*images))
    return _unique(pairs)
