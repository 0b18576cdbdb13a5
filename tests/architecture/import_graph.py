"""The project's import graph, read from the source with :mod:`ast` (nothing is imported).

A module's imports are every ``import`` and ``from ... import`` in it -- at the top and inside functions
alike (a lazy import closes a cycle as surely as a top-level one) -- except those under
``if TYPE_CHECKING:``, which never run.  Only imports of the project's own packages are kept.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: the installed package the other folders of :data:`PACKAGES` live under (pyproject.toml: obsfmu.fmus, ...);
#: its own folder holds the public Python API
PROJECT = "obsfmu"
PACKAGES = ("fmus", "observers", "plants", PROJECT)


@dataclass(frozen=True)
class Import:
    """``importer`` imports ``target`` (a project module) at ``line``; ``names``: the names taken from it."""
    importer: str
    target: str
    line: int
    names: tuple[str, ...] = ()


def module_files(packages=PACKAGES, root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``packages``."""
    modules = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            prefix = [] if package == PROJECT else [PROJECT]
            modules[".".join(prefix + parts)] = path
    return modules


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _statements(tree: ast.AST):
    """Every import statement of ``tree`` outside ``if TYPE_CHECKING:`` blocks."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def _base(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` reads from."""
    if node.level == 0:
        return node.module or ""
    parts = module.split(".")
    if not is_package:
        parts.pop()
    parts = parts[:len(parts) - (node.level - 1)]
    return ".".join(parts + ([node.module] if node.module else []))


def imports(modules: dict[str, Path] | None = None) -> list[Import]:
    """Every import of a project module by a project module."""
    modules = module_files() if modules is None else modules
    found = []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in _statements(tree):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    target = _project_module(alias.name, modules)
                    if target:
                        found.append(Import(module, target, node.lineno))
                continue
            base = _base(module, is_package, node)
            plain = []
            for alias in node.names:
                submodule = f"{base}.{alias.name}"
                if submodule in modules:       # from package import submodule
                    found.append(Import(module, submodule, node.lineno))
                else:
                    plain.append(alias.name)
            target = _project_module(base, modules)
            if target and (plain or base in modules and not node.names):
                found.append(Import(module, target, node.lineno, tuple(plain)))
    return found


def _project_module(name: str, modules) -> str | None:
    """``name`` or its closest enclosing project module (``a.b.c`` with only ``a.b`` a module)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def cycles(edges: list[Import]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    graph: dict[str, set[str]] = {}
    for edge in edges:
        if edge.target != edge.importer:
            graph.setdefault(edge.importer, set()).add(edge.target)
            graph.setdefault(edge.target, set())
    index, low, on_stack, stack, found = {}, {}, set(), [], []

    def visit(node: str) -> None:               # iterative would be longer; the graph is ~200 modules
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for successor in graph[node]:
            if successor not in index:
                visit(successor)
                low[node] = min(low[node], low[successor])
            elif successor in on_stack:
                low[node] = min(low[node], index[successor])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def is_ancestor_or_self(package: str, module: str) -> bool:
    return module == package or module.startswith(package + ".")
