"""The package layout: rooms by concern, imports pointing one way, no circles, no private
reach-ins, the backend contract kept.

The rule (README "Architecture"): cli -> batch -> method / baselines / evaluation / road
-> kernels / data -> config / errors.  Every import inside ``d3cli`` (module level or
inside a function) is checked against it, so a new module cannot quietly pull a higher
room into a lower one; the modules' imports form no circle; a module's private names are
used only inside its own package; :mod:`d3cli.method` and :mod:`d3cli.baselines` reach
the kernels only through the backend object and the host facade.
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
    "survey": {"road", "data", "config", "errors"},
    "batch": {"method", "baselines", "evaluation", "road", "survey", "kernels", "data", "config", "errors",
              "package"},
    "cli": {"batch", "method", "baselines", "evaluation", "road", "survey", "kernels", "data", "config", "errors",
            "package"},
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
    assert {"method", "kernels", "baselines", "data", "evaluation", "batch", "road", "survey"} <= rooms


@pytest.mark.parametrize("room", ["method", "kernels", "baselines", "data", "evaluation", "batch", "road", "survey"])
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
KERNEL_STEPS = ("cost", "aggregation", "sgm", "decisive", "subpixel", "perspective", "finishing", "pyramid")
KERNEL_SHARED = {"pixel", "road_model", "volume", "compile_cache", "intrinsics", "cpu_common", "cuda_launch",
                 "device_counts", "pool"}
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


# ----------------------------------------------------------------------------- no circles
def _module_names() -> dict[str, Path]:
    return {_module_name(p): p for p in _sources()}


def _import_edges(path: Path, modules) -> set[str]:
    """The d3cli modules ``path`` imports (module level or inside a function).

    ``from A import n`` counts as an import of the module ``A.n`` where there is one, else
    of ``A``; ``import A.B`` of ``A.B``.  The packages above an imported module, which
    Python runs first, are not counted: a package's ``__init__`` that names its own
    modules would otherwise close a circle with each of them.
    """
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name.split(".")[0] == "d3cli"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "d3cli":
                continue
            for alias in node.names:
                found.add(f"{target}.{alias.name}" if f"{target}.{alias.name}" in modules else target)
    return {m for m in found if m in modules and m != name}


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def test_the_import_graph_of_the_package_has_no_circle():
    """No module imports, directly or through others, a module that imports it back:
    each concept has one home below its users (imports inside functions count too)."""
    modules = _module_names()
    graph = {name: _import_edges(path, modules) for name, path in modules.items()}
    assert _circles(graph) == []


def test_the_circle_finder_finds_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


# ----------------------------------------------------------------------------- private names
def _package_of(module: str, modules) -> str:
    """The package a module belongs to: itself for a package, else its parent."""
    return module if modules[module].name == "__init__.py" else module.rpartition(".")[0]


def _private_uses(path: Path, modules, own_package: str | None, allowed=frozenset()) -> list[str]:
    """``line: module._name`` for every private attribute read of a d3cli module, bound by
    an import in ``path``, whose package is not ``own_package`` (modules in ``allowed`` aside)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    name = _module_name(path) if own_package is not None else ""
    package = (name if path.name == "__init__.py" else name.rpartition(".")[0]) if name else ""
    bound: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules:
                    bound[alias.asname or alias.name.split(".")[0]] = alias.name if alias.asname else "d3cli"
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                if f"{target}.{alias.name}" in modules:
                    bound[alias.asname or alias.name] = f"{target}.{alias.name}"
    bad = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
            continue
        chain, value = [], node.value
        while isinstance(value, ast.Attribute):
            chain.append(value.attr)
            value = value.value
        if not isinstance(value, ast.Name) or value.id not in bound:
            continue
        module = ".".join([bound[value.id]] + chain[::-1]) if bound[value.id] != "d3cli" else ".".join(
            [value.id] + chain[::-1])
        if module in modules and _package_of(module, modules) != own_package and module not in allowed:
            bad.append(f"{node.lineno}: {module}.{node.attr}")
    return bad


#: Modules whose private helpers tests may read: none (a step a test checks on its own is
#: public where it lives).
PRIVATE_READS_ALLOWED: set = set()


def test_no_module_reads_a_private_name_of_a_module_of_another_package():
    """``module._name`` of a d3cli module is read only inside that module's package: a
    name another package (or a test) needs is public where it lives, not re-exported."""
    modules = _module_names()
    bad = []
    for path in _sources():
        name = _module_name(path)
        own = name if path.name == "__init__.py" else name.rpartition(".")[0]
        bad += [f"{path.relative_to(PACKAGE.parent)}:{use}" for use in _private_uses(path, modules, own)]
    for path in sorted(TESTS.rglob("*.py")):
        bad += [f"tests/{path.relative_to(TESTS)}:{use}"
                for use in _private_uses(path, modules, None, PRIVATE_READS_ALLOWED)]
    assert bad == []


def test_the_private_name_check_sees_an_aliased_module(tmp_path):
    probe = tmp_path / "probe.py"
    secret, hidden = "_" + "secret", "_" + "hidden"  # spelt apart: this file is scanned too
    probe.write_text(f"from d3cli.kernels import cpu_common as c\nimport d3cli.kernels.volume\n"
                     f"c.{secret}(1)\nd3cli.kernels.volume.{hidden}\nc.public\n", encoding="utf-8")
    assert sorted(_private_uses(probe, _module_names(), None)) == [
        f"3: d3cli.kernels.cpu_common.{secret}", f"4: d3cli.kernels.volume.{hidden}"]


# ----------------------------------------------------------------------------- the backend contract
#: What method/ and baselines/ may import of the kernels: the package (get_backend), the
#: contract (the backend object's type) and the facade of the host-only kernels.
KERNEL_ENTRIES = {"d3cli.kernels", "d3cli.kernels.backend", "d3cli.kernels.host"}


@pytest.mark.parametrize("room", ["method", "baselines"])
def test_the_pipeline_reaches_the_kernels_through_the_backend_and_the_host_facade(room):
    """d3cli/method and d3cli/baselines never import kernels.cpu, kernels.cuda or a step's
    modules: they compute through the backend object (``backend: Backend``) and the host
    facade (:mod:`d3cli.kernels.host`), so both backends serve them alike."""
    modules = _module_names()
    bad = []
    for path in sorted((PACKAGE / room).rglob("*.py")):
        for target in sorted(_import_edges(path, modules)):
            if target.startswith("d3cli.kernels") and target not in KERNEL_ENTRIES:
                bad.append(f"{path.relative_to(PACKAGE.parent)}: imports {target}")
    assert bad == []


@pytest.mark.parametrize("backend", ["cpu", "cuda"])
def test_each_backend_names_exactly_the_contract(backend):
    """kernels/cpu.py and kernels/cuda.py define or import every method of
    :class:`d3cli.kernels.backend.Backend` and no other public function or private name."""
    contract = {n for n in vars(__import__("d3cli.kernels.backend", fromlist=["Backend"]).Backend)
                if not n.startswith("_")}
    tree = ast.parse((PACKAGE / "kernels" / f"{backend}.py").read_text(encoding="utf-8"))
    named = set()
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level:
            named |= {alias.asname or alias.name for alias in node.names}
        elif isinstance(node, ast.FunctionDef):
            named.add(node.name)
    functions = {n for n in named if not n.startswith("_") and not n.isupper()}
    assert functions == contract
    assert {n for n in named if n.startswith("_")} <= {"_compile_cache"}  # imported for its side effect
