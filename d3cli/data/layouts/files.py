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
            # A folder is scanned several times (layout detection, then its pairs): one
            # warning per bad entry, not one per scan.
            if entry.path not in _WARNED:
                _WARNED.add(entry.path)
                log.warning("%s: skipped (%s); fix or remove the link", entry.path, exc.strerror or exc)
    return kept


#: Entries already warned about in this process (see :func:`_entries`).
_WARNED: set[str] = set()


def _files_by_lower_name(folder: Path) -> dict[str, Path]:
    """The file entries of ``folder`` by lower-case name.

    Besides regular files: FIFOs, devices, links to them and folders named like a file
    (``left.png/``), so that a view, a ground truth or a calib.txt that is no regular file
    is found and then refused by its reader naming what it is, rather than taken for
    missing (and its pair silently run without it).
    """
    return {path.name.lower(): path for path in _entries(folder, _is_file_like)}


#: Suffixes of the files a layout looks up by name: a folder with one of them is a
#: mistake to report, not a subfolder.
_FILE_SUFFIXES = frozenset((*formats.IMAGE_EXTENSIONS, *formats.DISPARITY_EXTENSIONS, ".txt"))


def _is_file_like(entry: os.DirEntry) -> bool:
    if entry.is_dir():
        return os.path.splitext(entry.name)[1].lower() in _FILE_SUFFIXES
    return entry.is_file() or os.path.exists(entry.path)  # exists: a FIFO or device, not a broken link


def _present(path: Path) -> bool:
    """``path`` is a file or something a reader must refuse by name (a FIFO, a device):
    an optional file (ground truth, calib.txt) that is no regular file is not dropped."""
    return path.is_file() or formats.special_file_kind(path) is not None


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
