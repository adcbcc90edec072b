"""Checks on the structure of the source tree (docs/architecture.md, "Packages").

Every `.py` file of the installed folders is parsed (never imported) and checked for: the
allowed import directions between layers, import cycles, private names crossing modules, the
function size limit, the old bare import names, the package list of pyproject.toml and
`__all__`. Modules are sized by topic (a file format's reader and writer are one module),
not by a line count.
An import is any `import`/`from ... import` anywhere in the file (module level, inside
functions, under ``if TYPE_CHECKING:``) and any string literal that is exactly the name of a
project module (``importlib.import_module("mavsysid.cli.plan")``).
"""

from __future__ import annotations

import ast
import functools
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
PACKAGE_DIR: dict[str, str] = PYPROJECT["tool"]["setuptools"]["package-dir"]

MAX_FUNCTION_LINES = 80

# Layer of a module: the longest matching prefix of its import name.
LAYER_OF_PREFIX = {
    "mavsysid": "root",  # mavsysid/__init__: imported by every `mavsysid.*` import
    "mavsysid.errors": "root",
    "mavsysid.compiled_cache": "root",
    "mavsysid.cli": "cli",
    "mavsysid.__main__": "cli",
    "mavsysid.vehicle": "vehicle",
    "mavsysid.formats": "formats",
    "mavsysid.planner": "planner",
    "mavsysid.flight": "flight",  # the shared utilities directly in flight/
    "mavsysid.flight.offline": "flight.offline",
    "mavsysid.flight.simvehicle": "flight.simvehicle",
    "mavsysid.flight.ground": "flight.ground",
    "mavsysid.estimation": "estimation",
    "mavsysid.discrepancy": "discrepancy",
    "mavsysid.pipeline": "pipeline",
    "mavsysid.experiments": "experiments",
}

# The one table of allowed directions: layer -> the layers it may import (itself included).
# planner, flight and estimation never import each other; the discrepancy workflow builds on
# estimation only; the pipeline (what the commands run) strings the stages together; the
# paper's evaluation builds on the pipeline; nothing below cli imports cli.
_BASE = {"root"}
_FLIGHT = {"flight", "flight.offline", "flight.simvehicle", "flight.ground"}
_STAGES = {"vehicle", "formats", "planner", *_FLIGHT, "estimation", "discrepancy"}
ALLOWED_IMPORTS: dict[str, set[str]] = {
    "root": _BASE,
    "vehicle": _BASE | {"vehicle"},
    "formats": _BASE | {"vehicle", "formats"},
    "planner": _BASE | {"vehicle", "formats", "planner"},
    "flight": _BASE | {"vehicle", "formats", "flight"},
    "flight.offline": _BASE | {"vehicle", "formats", "flight", "flight.offline"},
    "flight.simvehicle": _BASE | {"vehicle", "formats", "flight", "flight.offline",
                                  "flight.simvehicle"},
    "flight.ground": _BASE | {"vehicle", "formats", "flight", "flight.ground"},
    "estimation": _BASE | {"vehicle", "formats", "estimation"},
    "discrepancy": _BASE | {"vehicle", "formats", "estimation", "discrepancy"},
    "pipeline": _BASE | _STAGES | {"pipeline"},
    "experiments": _BASE | _STAGES | {"pipeline", "experiments"},
    "cli": set(LAYER_OF_PREFIX.values()),
}

# The top-level names the packages had before they moved under `mavsysid`.
OLD_TOP_LEVEL_NAMES = frozenset(
    name.split(".")[1] for name in PACKAGE_DIR if name.count(".") == 1
) | {"cli"}


@dataclass(frozen=True)
class Module:
    """One parsed source file: its import name, path relative to the checkout and tree."""

    name: str
    path: Path
    tree: ast.Module
    n_lines: int


@dataclass(frozen=True)
class Import:
    """One import in a module: the line and the project module (or outside name) imported."""

    line: int
    target: str
    names: tuple[str, ...]  # names after `from ... import`, empty for `import x`


def _parse(name: str, path: Path) -> Module:
    text = path.read_text(encoding="utf-8")
    return Module(name, path.relative_to(ROOT), ast.parse(text, str(path)),
                  len(text.splitlines()))


def _module_name(path: Path, base: Path, base_name: str) -> str:
    parts = [base_name, *path.relative_to(base).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(p for p in parts if p)


@functools.cache
def source_modules() -> dict[str, Module]:
    """The installed modules by import name, mapped from folders as pyproject's package-dir."""
    modules = {}
    for import_name, folder in PACKAGE_DIR.items():
        base = ROOT / folder
        for path in sorted(base.rglob("*.py")):
            if "__pycache__" not in path.parts:
                name = _module_name(path, base, import_name)
                modules.setdefault(name, _parse(name, path))
    return modules


@functools.cache
def all_modules() -> dict[str, Module]:
    """The source modules plus the modules of `tests/` and `bench/` (named by path)."""
    modules = dict(source_modules())
    for folder in ("tests", "bench"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            name = _module_name(path, ROOT / folder, folder)
            modules[name] = _parse(name, path)
    return modules


def _package_of(module: Module) -> str:
    is_package = module.path.name == "__init__.py"
    return module.name if is_package else module.name.rpartition(".")[0]


def _from_base(module: Module, node: ast.ImportFrom) -> str:
    """The absolute module name of a `from ... import` (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    package = _package_of(module).split(".")
    package = package[: len(package) - (node.level - 1)]
    return ".".join([*package, node.module] if node.module else package)


@functools.cache
def imports_of(module: Module) -> tuple[Import, ...]:
    """Every import of `module`, resolved to the most specific project module it names."""
    known = all_modules()
    found = []
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Import):
            found += [Import(node.lineno, alias.name, ()) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _from_base(module, node)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                target = sub if sub in known else base
                found.append(Import(node.lineno, target, (alias.name,)))
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and node.value in known and node.value.startswith("mavsysid.")):
            found.append(Import(node.lineno, node.value, ()))
    return tuple(sorted(found, key=lambda imp: imp.line))


def layer_of(name: str) -> str | None:
    """The layer of a project module's import name (None outside the project)."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        layer = LAYER_OF_PREFIX.get(".".join(parts[:n]))
        if layer is not None:
            return layer
    return None


def _is_private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


SOURCE = sorted(source_modules())
EVERYTHING = sorted(all_modules())


@pytest.mark.parametrize("name", SOURCE)
def test_imports_follow_allowed_directions(name: str) -> None:
    """A module imports only from its own layer and the layers allowed below it."""
    module = source_modules()[name]
    layer = layer_of(name)
    assert layer is not None, f"{module.path}: no layer for {name} in LAYER_OF_PREFIX"
    bad = [
        f"  {module.path}:{imp.line} imports {imp.target} (layer {layer_of(imp.target)})"
        for imp in imports_of(module)
        if (target := layer_of(imp.target)) is not None and target not in ALLOWED_IMPORTS[layer]
    ]
    assert not bad, (f"{name} (layer {layer}) may import only "
                     f"{sorted(ALLOWED_IMPORTS[layer])}:\n" + "\n".join(bad))


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of `graph`, iterative (no recursion limit)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return components


def test_no_import_cycles() -> None:
    """The module import graph of the source folders has no cycle."""
    modules = source_modules()
    graph = {name: {imp.target for imp in imports_of(module) if imp.target in modules}
             for name, module in modules.items()}
    cycles = [c for c in _strongly_connected(graph) if len(c) > 1 or c[0] in graph[c[0]]]
    lines = []
    for cycle in cycles:
        lines.append("  cycle: " + ", ".join(cycle))
        members = set(cycle)
        for name in cycle:
            lines += sorted({f"    {modules[name].path}:{imp.line} imports {imp.target}"
                             for imp in imports_of(modules[name]) if imp.target in members})
    assert not cycles, "import cycles between modules:\n" + "\n".join(lines)


def test_layer_table_is_one_way() -> None:
    """No two layers may import each other, directly or around a loop of layers."""
    graph = {layer: allowed - {layer} for layer, allowed in ALLOWED_IMPORTS.items()}
    loops = [c for c in _strongly_connected(graph) if len(c) > 1]
    assert not loops, f"layers allowed to import each other: {loops}"


def _project_module_aliases(module: Module) -> dict[str, str]:
    """Local names bound to project modules by the imports of `module` (alias -> module)."""
    known = all_modules()
    aliases = {}
    for node in ast.walk(module.tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in known and alias.asname:
                    aliases[alias.asname] = alias.name
        elif isinstance(node, ast.ImportFrom):
            base = _from_base(module, node)
            for alias in node.names:
                if f"{base}.{alias.name}" in known:
                    aliases[alias.asname or alias.name] = f"{base}.{alias.name}"
    return aliases


@pytest.mark.parametrize("name", EVERYTHING)
def test_no_private_names_cross_modules(name: str) -> None:
    """No module imports (or reaches through a module) another project module's private name."""
    module = all_modules()[name]
    known = all_modules()
    bad = [f"  {module.path}:{imp.line} imports {imp.names[0]} from {imp.target}"
           for imp in imports_of(module)
           if imp.names and _is_private(imp.names[0])
           and not imp.target.endswith("." + imp.names[0])  # a module: checked below
           and (imp.target in known or layer_of(imp.target) is not None)]
    # A private module is private to its package: only its siblings may import it.
    bad += [f"  {module.path}:{imp.line} imports private module {imp.target}"
            for imp in imports_of(module)
            if imp.target in known and any(map(_is_private, imp.target.split(".")))
            and imp.target.rpartition(".")[0] != _package_of(module)]
    aliases = _project_module_aliases(module)
    bad += [f"  {module.path}:{node.lineno} uses {node.value.id}.{node.attr} "
            f"({aliases[node.value.id]})"
            for node in ast.walk(module.tree)
            if isinstance(node, ast.Attribute) and _is_private(node.attr)
            and isinstance(node.value, ast.Name) and node.value.id in aliases]
    assert not bad, f"{name} uses private names of other modules:\n" + "\n".join(bad)


@pytest.mark.parametrize("name", SOURCE)
def test_function_size(name: str) -> None:
    """Every function and method has at most 80 lines, def line to last line."""
    module = source_modules()[name]
    bad = [f"  {module.path}:{node.lineno} {node.name}: "
           f"{node.end_lineno - node.lineno + 1} lines"
           for node in ast.walk(module.tree)
           if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
           and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES]
    assert not bad, (f"{name} has functions over {MAX_FUNCTION_LINES} lines:\n"
                     + "\n".join(bad))


@pytest.mark.parametrize("name", EVERYTHING)
def test_no_bare_old_import_names(name: str) -> None:
    """Project code is imported as `mavsysid.*`, never by the old top-level names."""
    module = all_modules()[name]
    bad = [f"  {module.path}:{node.lineno} imports {target}"
           for node in ast.walk(module.tree)
           for target in (
               [a.name for a in node.names] if isinstance(node, ast.Import)
               else [node.module] if isinstance(node, ast.ImportFrom) and not node.level
               else [])
           if target and target.split(".")[0] in OLD_TOP_LEVEL_NAMES]
    assert not bad, f"{name} uses old import names:\n" + "\n".join(bad)


def _package_folders() -> dict[str, Path]:
    """Import name -> folder of every folder with `__init__.py` under the package-dir roots."""
    return {_module_name(init, ROOT / folder, import_name): init.parent.relative_to(ROOT)
            for import_name, folder in PACKAGE_DIR.items()
            for init in (ROOT / folder).rglob("__init__.py")}


def test_pyproject_packages_match_folders() -> None:
    """pyproject's `[tool.setuptools] packages` lists exactly the folders with `__init__.py`."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = set(_package_folders())
    assert listed == found, (f"missing from pyproject: {sorted(found - listed)}; "
                             f"listed without a package folder: {sorted(listed - found)}")


def test_source_folders_are_packages() -> None:
    """Every folder holding source files has an `__init__.py` (so it is installed)."""
    folders = {path.parent for folder in PACKAGE_DIR.values()
               for path in (ROOT / folder).rglob("*.py") if "__pycache__" not in path.parts}
    bad = sorted(str(f.relative_to(ROOT)) for f in folders if not (f / "__init__.py").exists())
    assert not bad, f"folders with source files but no __init__.py: {bad}"


@pytest.mark.parametrize("name", [n for n in SOURCE if not n.endswith(".__main__")])
def test_module_declares_all(name: str) -> None:
    """Every source module (but `__main__`) assigns `__all__` at module level."""
    module = source_modules()[name]
    declared = any(
        isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign)
        and "__all__" in {t.id for t in getattr(node, "targets", [getattr(node, "target", None)])
                          if isinstance(t, ast.Name)}
        for node in module.tree.body)
    assert declared, f"{module.path} has no module-level __all__"
