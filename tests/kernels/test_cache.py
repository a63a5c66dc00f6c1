"""The numba cache of the kernels: an edit of a kernels module drops the caches of that
module and of every module that imports it (directly or through others), and only those."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from d3cli.kernels import compile_cache


@pytest.fixture
def tree(tmp_path):
    """A copy of the kernels package's modules."""
    root = tmp_path / "kernels"
    for path in compile_cache.kernel_modules(compile_cache.HERE):
        target = root / path.relative_to(compile_cache.HERE)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(path, target)
    return root


def _folder(module: Path, cache_dir: str) -> Path:
    if cache_dir:
        from numba.core.caching import UserProvidedCacheLocator

        return Path(cache_dir) / UserProvidedCacheLocator.get_suitable_cache_subpath(str(module))
    return module.parent / "__pycache__"


def _fake_caches(root: Path, cache_dir: str) -> dict[str, Path]:
    """One fake cached function per module, keyed by the module's relative path."""
    made = {}
    for module in compile_cache.kernel_modules(root):
        folder = _folder(module, cache_dir)
        folder.mkdir(parents=True, exist_ok=True)
        f = folder / f"{module.stem}.f-10.py313.nbi"
        f.write_text("cached")
        made[module.relative_to(root).as_posix()] = f
    return made


def _dropped(made: dict[str, Path]) -> set[str]:
    return {name for name, f in made.items() if not f.exists()}


@pytest.mark.parametrize("use_cache_dir", [False, True])
@pytest.mark.parametrize("edited", ["pixel.py", "decisive/pixel_seeds.py", "subpixel/pixel.py", "cost/pixel.py"])
def test_an_edit_of_a_per_pixel_module_drops_every_driver_that_inlines_it(tree, tmp_path, edited, use_cache_dir):
    cache_dir = str(tmp_path / "numba") if use_cache_dir else ""
    assert compile_cache.drop_stale(tree, cache_dir)  # no stamp yet
    stamp = _folder(tree / "pixel.py", cache_dir) / compile_cache.STAMP
    assert json.loads(stamp.read_text()) == compile_cache.module_digests(tree)
    made = _fake_caches(tree, cache_dir)
    assert not compile_cache.drop_stale(tree, cache_dir)  # unchanged: the caches stay
    assert _dropped(made) == set()
    with open(tree / edited, "a") as f:
        f.write("# an edit\n")
    assert compile_cache.drop_stale(tree, cache_dir)
    dropped = _dropped(made)
    assert {edited, "decisive/cpu_seeds.py", "decisive/cpu_diffusion.py", "aggregation/cpu.py", "sgm/cpu.py",
            "cost/cpu.py", "perspective/cpu.py", "decisive/cuda_diffusion.py", "sgm/cuda.py"} <= dropped
    assert "finishing/fill.py" not in dropped  # compiles none of the per-pixel functions
    assert json.loads(stamp.read_text()) == compile_cache.module_digests(tree)


def test_an_edit_of_a_helper_module_drops_its_importers_cache(tree):
    """aggregation/cpu.py inlines cpu_vector.py's row kernels: numba keys the cache on
    cpu.py's source only, so an edit of cpu_vector.py alone used to leave it stale."""
    compile_cache.drop_stale(tree)
    made = _fake_caches(tree, "")
    with open(tree / "aggregation" / "cpu_vector.py", "a") as f:
        f.write("# an edit\n")
    assert compile_cache.drop_stale(tree)
    dropped = _dropped(made)
    assert {"aggregation/cpu_vector.py", "aggregation/cpu.py"} <= dropped
    assert not dropped & {"sgm/cpu.py", "decisive/cpu_seeds.py", "cost/cpu.py", "pixel.py"}


def test_an_edit_of_a_driver_drops_only_that_driver_and_the_facades(tree):
    compile_cache.drop_stale(tree)
    made = _fake_caches(tree, "")
    with open(tree / "sgm" / "cpu.py", "a") as f:
        f.write("# an edit\n")
    assert compile_cache.drop_stale(tree)
    assert _dropped(made) == {"sgm/cpu.py", "cpu.py", "__init__.py"}


def test_a_stamp_of_an_older_version_drops_everything(tree):
    made = _fake_caches(tree, "")
    stamp = _folder(tree / "pixel.py", "") / compile_cache.STAMP
    stamp.write_text("0f" * 32)  # not JSON: an older stamp format
    assert compile_cache.drop_stale(tree)
    assert _dropped(made) == set(made)


def test_relative_imports_are_read_from_the_sources():
    here = compile_cache.HERE
    assert compile_cache.local_imports(here / "aggregation" / "cpu.py") >= {
        here / "aggregation" / "cpu_vector.py", here / "aggregation" / "cpu_rows.py", here / "cpu_common.py",
        here / "intrinsics.py"}
    assert here / "compile_cache.py" not in compile_cache.local_imports(here / "aggregation" / "cpu.py")  # compiles nothing
