"""A package's import graph from its source (``ast``), its circles, and its upward imports.

Every import statement counts wherever it stands: at module level, inside a function
(a lazy import hides a circle from Python's start-up, it does not remove the dependency)
and under ``if TYPE_CHECKING:`` (a type named from a higher layer ties the lower one to
it as firmly as a call does, and mypy follows it). Importing ``a.b.c`` is counted as
importing ``a.b.c`` only, not its parent packages: their ``__init__`` runs first, but
the importer uses nothing of theirs.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from pathlib import Path

#: Each module (dotted name) -> the package's modules it imports -> the first line doing so.
Graph = dict[str, dict[str, int]]
#: Layers, highest first: each maps a module's first name below the package ("" for the
#: package's own ``__init__``) to its unit. A unit imports within itself or a lower layer.
Layers = Iterable[Mapping[str, str]]


def _modules(package_dir: Path) -> dict[str, Path]:
    """Every module of the package by its dotted name: ``pkg``, ``pkg.sub``, ``pkg.sub.mod``."""
    found: dict[str, Path] = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = path.relative_to(package_dir.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(parts)] = path
    return found


def _known(name: str, modules: Mapping[str, Path]) -> str | None:
    """The longest prefix of ``name`` that is a module (``pkg.mod.attr`` -> ``pkg.mod``)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def _targets(
    node: ast.AST, module: str, is_package: bool, modules: Mapping[str, Path]
) -> list[str]:
    """The modules one import statement loads, relative imports resolved."""
    if isinstance(node, ast.Import):
        return [found for alias in node.names if (found := _known(alias.name, modules))]
    if not isinstance(node, ast.ImportFrom):
        return []
    base = node.module or ""
    if node.level:
        package = module if is_package else module.rpartition(".")[0]
        parts = package.split(".")
        anchor = ".".join(parts[: len(parts) - (node.level - 1)])
        base = f"{anchor}.{base}" if base else anchor
    targets = []
    for alias in node.names:
        submodule = f"{base}.{alias.name}"
        found = submodule if submodule in modules else _known(base, modules)
        if found:
            targets.append(found)
    return targets


def import_graph(package_dir: Path) -> Graph:
    """Which of the package's modules each module imports, anywhere in its text."""
    modules = _modules(package_dir)
    graph: Graph = {}
    for module, path in modules.items():
        edges = graph.setdefault(module, {})
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            for target in _targets(node, module, is_package, modules):
                if target != module:
                    line = getattr(node, "lineno", 0)
                    edges[target] = min(edges.get(target, line), line)
    return graph


def circles(graph: Graph) -> list[list[str]]:
    """Every set of modules that import each other round (strongly connected), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(module: str) -> None:  # Tarjan's algorithm; the graph is small
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for target in graph.get(module, {}):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in on_stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return sorted(found)


def _place(module: str, layers: list[Mapping[str, str]]) -> tuple[int, str] | None:
    """The layer (0 highest) and unit of ``module``, None when no layer names it."""
    first = module.partition(".")[2].partition(".")[0]
    for level, units in enumerate(layers):
        if first in units:
            return level, units[first]
    return None


def unplaced(graph: Graph, layers: Layers) -> list[str]:
    """The modules no layer names: each must be given a place before its imports are judged."""
    ordered = list(layers)
    return sorted(module for module in graph if _place(module, ordered) is None)


def upward_imports(graph: Graph, layers: Layers) -> list[str]:
    """Every import that is neither within a unit nor into a lower layer, as a line saying so."""
    ordered = list(layers)
    found = []
    for module, edges in sorted(graph.items()):
        here = _place(module, ordered)
        for target, line in sorted(edges.items()):
            there = _place(target, ordered)
            if here is None or there is None or here[1] == there[1] or there[0] > here[0]:
                continue
            if there[0] == here[0]:
                why = f"{there[1]} is beside {here[1]}, in one layer"
            else:
                why = f"{there[1]} is above {here[1]}"
            found.append(f"{module}:{line} imports {target}: {why}")
    return found
