"""The numba cache of the kernels: where it lives, and dropping what an edit made stale.

Numba keys a cached function on its own source file only.  But a kernel inlines the
functions it calls from other modules: the per-pixel functions are compiled into the CPU
drivers of other files, a step's per-pixel module inlines the shared helpers of
``pixel.py``, a driver inlines the vector helpers of a sibling (``aggregation/cpu.py``
those of ``cpu_vector.py``).  After an edit of such a module numba would keep serving the
importers' stale copies.  :func:`drop_stale` therefore keeps a hash of every kernels
module and, for each module that changed, deletes the cache of every module that imports
it, directly or through others (:func:`importers`, from the relative imports of the
sources).

A damaged cache entry (an index or data file truncated or overwritten: a full disk, a
killed copy, a stray write) would make numba's unpickling fail on every run; numba's cache
loading is therefore wrapped (:func:`tolerate_damage`) so that such an entry of a kernels
module is removed and compiled again, with one warning per process.

Imported (and :func:`prepare` run) by every kernels module that compiles with
``cache=True``, before its first decorator: numba picks a function's cache folder when the
decorator runs.  May import: numba and the standard library only.
"""

from __future__ import annotations

import ast
import hashlib
import json
import logging
import os
from pathlib import Path

from .cache_location import choose_cache_dir, module_cache_folder

#: The kernels package folder.
HERE = Path(__file__).resolve().parent
#: Name of the file, in the kernels folder's cache, holding the hash of every kernels module.
STAMP = "modules.sha256.json"
#: Modules every kernels module imports that compile nothing (an edit of them must not drop
#: every cache).
NO_KERNELS = ("compile_cache.py", "cache_location.py")

_prepared = False
#: Whether this process has warned about a damaged cache entry (once; later ones at DEBUG).
_damage_reported = False

log = logging.getLogger(__name__)
#: Module names of d3stereo's own compiled functions (``d3cli.``).
_PACKAGE_PREFIX = __name__.split(".")[0] + "."


def kernel_modules(root: Path = HERE) -> list[Path]:
    """Every Python module under the kernels folder ``root``."""
    return sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts)


def module_digests(root: Path = HERE) -> dict[str, str]:
    """SHA-256 of each kernels module, keyed by its path relative to ``root``."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in kernel_modules(root)}


def _module_file(folder: Path, dotted: str) -> Path | None:
    """The module ``dotted`` (``a.b``) below ``folder``, as a file or a package ``__init__``."""
    base = folder.joinpath(*dotted.split(".")) if dotted else folder
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def local_imports(path: Path, root: Path = HERE) -> set[Path]:
    """The kernels modules ``path`` imports with relative imports (``from .x import f``,
    ``from .. import pixel``), :data:`NO_KERNELS` left out."""
    found = set()
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if not isinstance(node, ast.ImportFrom) or node.level == 0:
            continue
        folder = path.parent
        for _ in range(node.level - 1):
            folder = folder.parent
        if node.module:  # ``from .pixel import build``; ``from .finishing import fill`` names a module too
            targets = [_module_file(folder, node.module)]
            targets += [_module_file(folder, f"{node.module}.{a.name}") for a in node.names]
        else:  # ``from .. import pixel``: the named modules (a name of the package itself: its __init__)
            targets = [_module_file(folder, a.name) or _module_file(folder, "") for a in node.names]
        found.update(t for t in targets if t is not None and t.name not in NO_KERNELS
                     and root in t.parents and t != path)
    return found


def importers(root: Path = HERE) -> dict[Path, set[Path]]:
    """For each kernels module, the modules that import it directly or through others."""
    imported_by: dict[Path, set[Path]] = {}
    for module in kernel_modules(root):
        for target in local_imports(module, root):
            imported_by.setdefault(target, set()).add(module)
    closure = {}
    for module in kernel_modules(root):
        seen, todo = set(), [module]
        while todo:
            for user in imported_by.get(todo.pop(), ()):
                if user not in seen:
                    seen.add(user)
                    todo.append(user)
        closure[module] = seen
    return closure


def drop_stale(root: Path = HERE, cache_dir: str = "") -> bool:
    """Delete the cached functions of every module that changed or imports one that changed.

    Parameters
    ----------
    root : Path
        The kernels folder.
    cache_dir : str
        numba's ``NUMBA_CACHE_DIR`` (empty: the ``__pycache__`` beside each module).

    Returns
    -------
    bool
        Whether anything was dropped (no stamp yet, an unreadable one, or a module whose
        hash differs from the stamp's); the stamp then holds the new hashes.
    """
    digests = module_digests(root)
    stamp = module_cache_folder(root / "pixel.py", cache_dir) / STAMP
    try:
        recorded = json.loads(stamp.read_text())
    except (OSError, ValueError):
        recorded = {}
    if not isinstance(recorded, dict):
        recorded = {}
    changed = {root / rel for rel, digest in digests.items() if recorded.get(rel) != digest}
    if not changed:
        return False
    users = importers(root)
    stale = set(changed).union(*(users.get(module, set()) for module in changed))
    for module in sorted(stale):
        folder = module_cache_folder(module, cache_dir)
        for f in list(folder.glob(f"{module.stem}.*.nbi")) + list(folder.glob(f"{module.stem}.*.nbc")):
            f.unlink()
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.write_text(json.dumps(digests, indent=0, sort_keys=True), encoding="utf-8")
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
    tolerate_damage()


def _drop_damaged(cache, exc: Exception) -> None:
    """Remove the cache entry of ``cache`` (a numba ``Cache``: its index file and data
    files) that could not be loaded, and say so: one warning per process, the first
    entry's; the others at DEBUG (a damaged folder may hold dozens)."""
    global _damage_reported
    cache_file = cache._cache_file
    index = Path(cache_file._index_path)
    base = index.name[: -len(".nbi")]
    for path in [index, *index.parent.glob(f"{base}.*.nbc")]:
        try:
            path.unlink()
        except OSError:  # gone already (another process), or not ours to remove: saving replaces it
            pass
    reason = f"{type(exc).__name__}: {exc}"[:120]
    if _damage_reported:
        log.debug("damaged kernel cache entry %s (%s): removed and compiled again", index, reason)
        return
    _damage_reported = True
    log.warning("damaged kernel cache entry %s (%s): removed and compiled again", index, reason)


def tolerate_damage() -> None:
    """Make numba treat a damaged cache entry of a kernels module as a missing one.

    numba reads a function's index (``*.nbi``) and data (``*.nbc``) files with ``pickle``
    and lets any error out of them escape the call that compiles: an ``UnpicklingError``
    traceback on every run, since nothing removes the file.  ``Cache.load_overload`` is
    wrapped: for a function of d3stereo (the kernels, the synthetic renderer), an error
    other than ``OSError`` (which numba itself treats as a missing file) while reading or
    rebuilding the entry removes the entry (:func:`_drop_damaged`) and reports a cache
    miss, so numba compiles the function and saves a fresh entry (its save re-reads the
    index: gone now, so not the damaged one).  Functions of other packages keep numba's
    behaviour.  Once per process; a numba without ``Cache.load_overload`` is left alone.
    """
    from numba.core import caching

    load = getattr(caching.Cache, "load_overload", None)
    if load is None or getattr(load, "tolerates_damage", False):
        return

    def load_overload(self, sig, target_context):
        try:
            return load(self, sig, target_context)
        except OSError:
            raise
        except Exception as exc:  # noqa: BLE001 - any unpickling or rebuilding error: the entry is unusable
            if not getattr(self._py_func, "__module__", "").startswith(_PACKAGE_PREFIX):
                raise
            _drop_damaged(self, exc)
            return None

    load_overload.tolerates_damage = True
    load_overload.__doc__ = load.__doc__
    caching.Cache.load_overload = load_overload


prepare()
