"""The numba cache of the kernels: an edit of any per-pixel module drops the caches of
every module that inlines per-pixel functions, and only then."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from d3cli.kernels import cache


@pytest.fixture
def tree(tmp_path):
    """A copy of the kernels' per-pixel and CPU driver modules, with fake cache files."""
    root = tmp_path / "kernels"
    for pattern in cache.INLINING_MODULES:
        for path in cache.HERE.glob(pattern):
            target = root / path.relative_to(cache.HERE)
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(path, target)
    return root


def _fake_caches(root: Path, cache_dir):
    made = []
    for pattern in cache.INLINING_MODULES:
        for module in root.glob(pattern):
            folder = _folder(module, cache_dir)
            folder.mkdir(parents=True, exist_ok=True)
            for suffix in ("nbi", "nbc"):
                f = folder / f"{module.stem}.f-10.py313.{suffix}"
                f.write_text("stale")
                made.append(f)
    return made


def _folder(module: Path, cache_dir):
    if cache_dir:
        from numba.core.caching import UserProvidedCacheLocator

        return Path(cache_dir) / UserProvidedCacheLocator.get_suitable_cache_subpath(str(module))
    return module.parent / "__pycache__"


@pytest.mark.parametrize("use_cache_dir", [False, True])
@pytest.mark.parametrize("edited", ["pixel.py", "decisive/pixel_seeds.py", "sgm/pixel.py", "cost/pixel.py"])
def test_an_edit_of_any_per_pixel_module_drops_every_inlining_cache(tree, tmp_path, edited, use_cache_dir):
    cache_dir = str(tmp_path / "numba") if use_cache_dir else None
    assert cache.drop_stale(tree, cache_dir)  # no stamp yet
    stamp = _folder(tree / "pixel.py", cache_dir) / cache.STAMP
    assert stamp.read_text() == cache.pixel_digest(tree)
    made = _fake_caches(tree, cache_dir)
    assert any("decisive" in str(f) and "cpu_seeds" in f.name for f in made)
    assert any("aggregation" in str(f) and "cpu_vector" in f.name for f in made)
    assert not cache.drop_stale(tree, cache_dir)  # unchanged: the caches stay
    assert all(f.exists() for f in made)
    before = stamp.read_text()
    with open(tree / edited, "a") as f:
        f.write("# an edit\n")
    assert cache.drop_stale(tree, cache_dir)
    assert not any(f.exists() for f in made)
    assert stamp.read_text() == cache.pixel_digest(tree) != before


def test_other_modules_keep_their_cache(tree):
    cache.drop_stale(tree)
    other = tree / "__pycache__" / "finishing.f-10.py313.nbi"
    other.write_text("kept")
    with open(tree / "pixel.py", "a") as f:
        f.write("# an edit\n")
    assert cache.drop_stale(tree)
    assert other.exists()


def test_every_per_pixel_module_is_hashed():
    hashed = {p.relative_to(cache.HERE).as_posix() for pattern in cache.PIXEL_MODULES for p in cache.HERE.glob(pattern)}
    assert {"pixel.py", "cost/pixel.py", "aggregation/pixel.py", "sgm/pixel.py", "perspective/pixel.py",
            "decisive/pixel_seeds.py", "decisive/pixel_diffusion.py", "decisive/pixel_inheritance.py",
            "decisive/pixel_subpixel.py"} <= hashed
