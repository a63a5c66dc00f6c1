"""The package layout: rooms by concern, imports pointing one way, no private reach-ins.

The rule (README "Architecture"): cli -> batch -> method / baselines / evaluation / road
-> kernels / data -> config / errors.  Every import inside ``d3cli`` (module level or
inside a function) is checked against it, so a new module cannot quietly pull a higher
room into a lower one.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import d3cli

PACKAGE = Path(d3cli.__file__).resolve().parent
TESTS = Path(__file__).resolve().parent

#: room -> the rooms it may import (besides itself).
ALLOWED = {
    "errors": set(),
    "config": {"errors"},
    "kernels": {"errors"},
    "data": {"config", "errors"},
    "method": {"kernels", "data", "config", "errors"},
    "baselines": {"method", "kernels", "data", "config", "errors"},
    "evaluation": {"data", "config", "errors"},
    "road": {"method", "data", "config", "errors"},
    "batch": {"method", "baselines", "evaluation", "road", "kernels", "data", "config", "errors", "package"},
    "cli": {"batch", "method", "baselines", "evaluation", "road", "kernels", "data", "config", "errors", "package"},
    "main": {"cli"},
    "package": {"config", "errors", "method"},
}


def _room(module: str) -> str:
    """'d3cli.method.cost' -> 'method'; 'd3cli' -> 'package'; 'd3cli.__main__' -> 'main'."""
    parts = module.split(".")
    if len(parts) == 1 or not ((PACKAGE / parts[1]).is_dir() or (PACKAGE / f"{parts[1]}.py").is_file()):
        return "package"  # d3cli itself, or a name defined in d3cli/__init__.py
    return "main" if parts[1] == "__main__" else parts[1]


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute d3cli module) of every import in ``path``, nested ones included."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names if alias.name.split(".")[0] == "d3cli"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "d3cli":
                continue
            if node.module is None or target in ("d3cli",):
                # "from . import x" / "from d3cli import x": x may be a submodule
                found += [(node.lineno, f"{target}.{alias.name}") for alias in node.names]
            else:
                found.append((node.lineno, target))
    return found


def _sources() -> list[Path]:
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def test_at_most_six_top_level_modules_and_at_least_four_rooms():
    top = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(top) <= 6, top
    rooms = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    assert {"method", "kernels", "baselines", "data", "evaluation", "batch", "road"} <= rooms


@pytest.mark.parametrize("room", ["method", "kernels", "baselines", "data", "evaluation", "batch", "road"])
def test_every_room_says_what_lives_there_and_what_it_may_import(room):
    doc = ast.get_docstring(ast.parse((PACKAGE / room / "__init__.py").read_text(encoding="utf-8")))
    assert doc and len(doc.splitlines()) >= 2
    if room != "kernels":
        assert "May import" in doc or "may import" in doc


def test_imports_point_one_way():
    bad = []
    for path in _sources():
        room = _room(_module_name(path))
        for line, target in _imports(path):
            other = _room(target)
            if other != room and other not in ALLOWED[room]:
                bad.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {room} imports {target}")
    assert bad == []


def test_kernels_never_import_config_data_or_click():
    for path in (PACKAGE / "kernels").rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"^\s*(import|from)\s+(click|yaml)\b", text, re.M), path
        assert all(_room(t) in ("kernels", "errors") for _, t in _imports(path)), path


#: The kernels' step packages and the kernels' shared modules they may import.
KERNEL_STEPS = ("cost", "aggregation", "sgm", "decisive", "perspective", "finishing", "pyramid")
KERNEL_SHARED = {"pixel", "volume", "cache", "intrinsics", "cpu_common", "cuda_launch", "device_counts", "pool"}
#: Outside d3cli, what a step module may import.
KERNEL_STEP_LIBRARIES = {"__future__", "logging", "math", "platform", "types", "typing", "numba", "numpy", "llvmlite"}


@pytest.mark.parametrize("step", KERNEL_STEPS)
def test_kernel_steps_import_only_the_shared_kernel_modules(step):
    """A step package (kernels/cost/, ...) imports its own modules, the kernels' shared
    modules, errors, numba, numpy and llvmlite: never another step package, never a
    backend facade (kernels/cpu.py, kernels/cuda.py)."""
    folder = PACKAGE / "kernels" / step
    assert (folder / "__init__.py").is_file()
    bad = []
    for path in sorted(folder.rglob("*.py")):
        for line, target in _imports(path):
            parts = target.split(".")
            if parts[:3] == ["d3cli", "kernels", step] or target == "d3cli.errors":
                continue
            if parts[:2] == ["d3cli", "kernels"] and len(parts) == 3 and parts[2] in KERNEL_SHARED:
                continue
            bad.append(f"{path.relative_to(PACKAGE.parent)}:{line}: imports {target}")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) and not node.level else [])
            bad += [f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: imports {n}" for n in names
                    if n.split(".")[0] not in KERNEL_STEP_LIBRARIES | {"d3cli"}]
    assert bad == []


def test_tests_use_no_private_name_of_the_package():
    pattern = re.compile(r"\bd3cli(?:\.\w+)*\._[a-z]\w*|from d3cli[\w.]* import [^\n]*\b_[a-z]\w*")
    bad = []
    for path in sorted(TESTS.rglob("*.py")):
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if pattern.search(line):
                bad.append(f"{path.relative_to(TESTS)}:{number}: {line.strip()}")
    assert bad == []


def test_the_tests_mirror_the_package():
    rooms = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()} - {"samples"}
    mirrored = {p.name for p in TESTS.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    assert rooms <= mirrored, rooms - mirrored
