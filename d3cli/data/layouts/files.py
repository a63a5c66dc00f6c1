"""Folder scanning shared by the layouts: entries of a folder (links and unreadable
entries named as such), views by stem, case-insensitive file lookup.
"""

from __future__ import annotations

import errno
import logging
import os
from pathlib import Path
from typing import Iterable

from ...errors import InputError, where_what_fix
from .. import formats

log = logging.getLogger(__name__)


def _missing_why(path: Path) -> tuple[str, str]:
    """(what, fix) for an input that does not exist: a symlink loop and a broken link are
    named as such (a bare 'not found' would send the user looking for a typo), anything else is a wrong path."""
    if path.is_symlink():
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                return "a symlink loop (the link leads back to itself)", "point it at the data or remove it"
        return f"a broken symlink (to {os.readlink(path)}, which does not exist)", "fix the link or the path"
    return "no such file or folder", "check the path"


def _entries(folder: Path, keep) -> list[Path]:
    """Entries of ``folder`` for which ``keep(entry)`` holds, skipping broken ones.

    An entry that cannot be examined (a symlink loop, a dangling or forbidden link) is
    skipped with a warning naming that entry: one bad link must not hide the rest of a
    dataset (nor be blamed on the root folder).
    """
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        raise InputError(where_what_fix(str(folder), f"cannot list folder ({exc.strerror})", "check permissions")) from None
    kept = []
    for entry in entries:
        try:
            if keep(entry):
                kept.append(Path(entry.path))
        except OSError as exc:
            log.warning("%s: skipped (%s); fix or remove the link", entry.path, exc.strerror or exc)
    return kept


def _files_by_lower_name(folder: Path) -> dict[str, Path]:
    return {path.name.lower(): path for path in _entries(folder, lambda entry: entry.is_file())}


def _subfolders(folder: Path) -> list[Path]:
    return sorted(_entries(folder, lambda entry: not entry.name.startswith(".") and _is_folder(entry)))


def _is_folder(entry: os.DirEntry) -> bool:
    if entry.is_symlink():
        os.stat(entry.path)  # raises ELOOP for a symlink loop (is_dir() would say False)
    return entry.is_dir()


def _find_view(files: dict[str, Path], stem: str) -> Path | None:
    """The image file named ``stem.<image extension>`` among ``files`` (lower-case keys)."""
    for ext in formats.IMAGE_EXTENSIONS:
        if f"{stem}{ext}" in files:
            return files[f"{stem}{ext}"]
    return None


def _first(files: dict[str, Path], names: Iterable[str]) -> Path | None:
    for name in names:
        if name in files:
            return files[name]
    return None


def _is_image(path: Path) -> bool:
    return path.suffix.lower() in formats.IMAGE_EXTENSIONS


def _subfolder_map(folder: Path) -> dict[str, Path]:
    return {sub.name.lower(): sub for sub in _subfolders(folder)}
