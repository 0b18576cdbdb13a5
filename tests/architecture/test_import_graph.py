"""The architecture, checked from the import graph of the source (tests/architecture/import_graph.py):
no import cycle, no import of another module's private name.  The FMU runtime's isolation:
test_runtime_isolation.py."""

from __future__ import annotations

import ast

import pytest

from import_graph import Import, cycles, imports, is_ancestor_or_self, module_files  # noqa: I001

@pytest.fixture(scope="module")
def edges() -> list[Import]:
    return imports()


def test_the_graph_is_read():
    """The reader finds the project's modules and the imports everybody knows are there."""
    edges = imports()
    assert len(module_files()) > 50
    assert any(e.importer == "obsfmu.fmus.cli.commands" and e.target.startswith("obsfmu.fmus.scenarios") for e in edges)
    assert cycles([Import("a", "b", 1), Import("b", "c", 1), Import("c", "a", 1), Import("c", "d", 1)]) \
        == [["a", "b", "c"]]


def test_no_import_cycle(edges):
    found = cycles(edges)
    described = []
    for component in found:
        members = set(component)
        links = sorted({f"{e.importer} -> {e.target} (line {e.line})" for e in edges
                        if e.importer in members and e.target in members and e.importer != e.target})
        described.append(", ".join(links))
    assert not found, "import cycles: " + " | ".join(described)


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def test_no_import_of_another_modules_private_names(edges):
    offenders = []
    for edge in edges:
        if edge.target == edge.importer:
            continue
        offenders += [f"{edge.importer}:{edge.line} takes {edge.target}.{name}" for name in edge.names if _private(name)]
        *package, last = edge.target.split(".")
        if _private(last) and not is_ancestor_or_self(".".join(package), edge.importer):
            offenders.append(f"{edge.importer}:{edge.line} imports the private module {edge.target}")
    assert not offenders, "private names imported across modules: " + "; ".join(offenders)


def test_every_import_of_the_project_goes_through_obsfmu():
    """The folders fmus/, observers/ and plants/ are installed as obsfmu.fmus, ... only: an ``import fmus``
    works in a checkout (the folder is on sys.path) but loads a second copy of the module there and fails
    where obsfmu is installed."""
    from import_graph import PROJECT, ROOT
    bare = {"fmus", "observers", "plants"}
    found = []
    for folder in ("fmus", "observers", "plants", PROJECT, "tests", "benchmarks", "examples"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
            for node in ast.walk(tree):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else []
                found += [f"{path.relative_to(ROOT)}:{node.lineno}: {name}" for name in names
                          if name.split(".")[0] in bare]
    assert not found, "imports outside obsfmu: " + "; ".join(found)
