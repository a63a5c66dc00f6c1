"""The numba cache of the kernels: where it lives, and dropping what an edit made stale.

Numba keys a cached function on its own source file only.  The per-pixel functions are
compiled (and inlined) into the CPU drivers of other files, and a step's per-pixel module
inlines the shared helpers of ``pixel.py``; after an edit of any per-pixel module those
caches would keep stale copies.  :func:`drop_stale` therefore hashes every per-pixel
module (:data:`PIXEL_MODULES`) and deletes the cache of every module that inlines them
(:data:`INLINING_MODULES`) when the hash changed.

Imported (and :func:`prepare` run) by every kernels module that compiles with
``cache=True``, before its first decorator: numba picks a function's cache folder when the
decorator runs.  May import: numba and the standard library only.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from .cachedir import choose_cache_dir, module_cache_folder

#: The kernels package folder.
HERE = Path(__file__).resolve().parent
#: Glob patterns (relative to the kernels folder) of the per-pixel modules.
PIXEL_MODULES = ("pixel.py", "*/pixel.py", "*/pixel_*.py",
                 # finishing's inlined helpers: smoothing inlines exp.numpy_expf, range_box
                 # inlines smoothing.at_least_zero
                 "finishing/exp.py", "finishing/smoothing.py")
#: Glob patterns of the modules whose cached functions inline per-pixel functions: the
#: per-pixel modules themselves and every CPU and CUDA driver module (``cpu*.py``,
#: ``cuda*.py``: the CUDA kernels are cached too, with the device functions linked in).
INLINING_MODULES = PIXEL_MODULES + ("cpu*.py", "*/cpu*.py", "cuda*.py", "*/cuda*.py", "finishing/range_box.py")
#: Name of the file, in the kernels folder's cache, holding the hash of the per-pixel modules.
STAMP = "pixel.sha256"

_prepared = False


def pixel_digest(root: Path = HERE) -> str:
    """SHA-256 over the paths and contents of every per-pixel module under ``root``."""
    digest = hashlib.sha256()
    files = sorted({p for pattern in PIXEL_MODULES for p in root.glob(pattern)})
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(path.read_bytes())
    return digest.hexdigest()


def drop_stale(root: Path = HERE, cache_dir: str = "") -> bool:
    """Delete the cached functions of every inlining module when a per-pixel module changed.

    Parameters
    ----------
    root : Path
        The kernels folder.
    cache_dir : str
        numba's ``NUMBA_CACHE_DIR`` (empty: the ``__pycache__`` beside each module).

    Returns
    -------
    bool
        Whether the caches were dropped (the stamp was missing or held another hash); the
        stamp then holds the new hash.
    """
    digest = pixel_digest(root)
    stamp = module_cache_folder(root / "pixel.py", cache_dir) / STAMP
    if stamp.exists() and stamp.read_text() == digest:
        return False
    modules = sorted({p for pattern in INLINING_MODULES for p in root.glob(pattern)})
    for module in modules:
        folder = module_cache_folder(module, cache_dir)
        for f in list(folder.glob(f"{module.stem}.*.nbi")) + list(folder.glob(f"{module.stem}.*.nbc")):
            f.unlink()
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest)
    return True


def prepare() -> None:
    """Pick a writable numba cache folder, then :func:`drop_stale` (once per process).

    When the package's ``__pycache__`` cannot be written (a read-only install, a shared
    site-packages), ``NUMBA_CACHE_DIR`` is set to ``$XDG_CACHE_HOME/d3stereo/numba``
    (default ``~/.cache/d3stereo/numba``) before anything is compiled, so every process
    (each ``--workers`` process too) loads the kernels from one cache instead of compiling
    them again; a ``NUMBA_CACHE_DIR`` the user set is kept.
    """
    global _prepared
    if _prepared:
        return
    _prepared = True
    from numba import config as numba_config

    chosen = numba_config.CACHE_DIR or choose_cache_dir(HERE)  # the same choice the CLI's notice made
    if chosen != numba_config.CACHE_DIR:
        os.environ["NUMBA_CACHE_DIR"] = chosen
        numba_config.CACHE_DIR = chosen  # numba read the variable at import already
    try:
        drop_stale(HERE, numba_config.CACHE_DIR)
    except OSError:  # no writable cache anywhere: numba then compiles in every process
        pass


prepare()
