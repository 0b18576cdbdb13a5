"""The FMU runtime (``fmus/runtime/``) is self-contained and is exactly what an FMU bundles of ``fmus``.

The import graph is read from the source with :mod:`ast` (every ``import`` and ``from ... import``,
at any depth of a module, relative ones resolved), so a lazy import inside a function counts too.
"""

from __future__ import annotations

import ast
from pathlib import Path

from obsfmu.fmus import builder

ROOT = Path(__file__).resolve().parents[2]
RUNTIME = "fmus.runtime"
PROJECT = "obsfmu."   # the installed package of the folders: obsfmu.fmus is the folder fmus/


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, imported module) of every import of ``source`` (the module ``module``), relative ones resolved;
    ``from a import b`` gives ``a.b`` too (``b`` may be a module)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name.removeprefix(PROJECT)) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = module.split(".") if is_package else module.split(".")[:-1]
                base = package[:len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module.removeprefix(PROJECT)
            found.append((node.lineno, target))
            found += [(node.lineno, f"{target}.{alias.name}") for alias in node.names if alias.name != "*"]
    return found


def outside_imports(files, root: Path = ROOT) -> list[str]:
    """``"<file>:<line> imports <module>"`` for every import of a ``fmus`` module outside the runtime."""
    offending = []
    for path in files:
        module = module_name(path, root)
        for line, target in imports(path.read_text(), module, path.name == "__init__.py"):
            if target.split(".")[0] != "fmus" or target in ("fmus", RUNTIME) or target.startswith(RUNTIME + "."):
                continue
            offending.append(f"{path.relative_to(root).as_posix()}:{line} imports {target}")
    return offending


def runtime_files() -> list[Path]:
    return sorted(p for p in (ROOT / "fmus" / "runtime").rglob("*.py") if "__pycache__" not in p.parts)


def test_the_runtime_imports_nothing_of_the_host_side():
    """No module of fmus/runtime imports master, CLI, builder, campaign, report, scenarios, export, ..."""
    assert len(runtime_files()) > 10
    assert outside_imports(runtime_files()) == []


def test_the_check_names_every_form_of_import_of_the_host_side(tmp_path):
    """The check fails, naming the file, line and module, for each way a runtime module could reach the host:
    relative from a package and from a module, absolute, inside a function, ``from fmus import x``."""
    package = tmp_path / "fmus" / "runtime" / "slave"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("from ..kinds import create_block\nfrom ... import master\n")
    (package / "step.py").write_text("import numpy\nfrom ..definition import Port\nfrom . import state\n\n"
                                     "def f():\n    from ...campaign.runner import run\n"
                                     "    import fmus.cli as cli\n    from fmus import report\n")
    assert outside_imports(sorted(package.glob("*.py")), tmp_path) == [
        "fmus/runtime/slave/__init__.py:2 imports fmus.master",
        "fmus/runtime/slave/step.py:6 imports fmus.campaign.runner",
        "fmus/runtime/slave/step.py:6 imports fmus.campaign.runner.run",
        "fmus/runtime/slave/step.py:7 imports fmus.cli",
        "fmus/runtime/slave/step.py:8 imports fmus.report"]


def test_the_builder_bundles_fmus_init_and_the_runtime_whole():
    """Of ``fmus``: its ``__init__.py`` and every .py file of fmus/runtime, nothing else; observers, plants and
    pythonfmu as they are."""
    import pythonfmu

    bundled = {relative for relative, _ in builder._sources(())}

    def tree(folder: Path, prefix: str) -> set[str]:
        return {f"{prefix}/{p.relative_to(folder).as_posix()}" for p in folder.rglob("*.py")
                if "__pycache__" not in p.parts}

    expected = {"fmus/__init__.py"} | tree(ROOT / "fmus" / "runtime", "fmus/runtime") \
        | tree(ROOT / "observers", "observers") | tree(ROOT / "plants", "plants") \
        | {f"pythonfmu/{p.name}" for p in Path(pythonfmu.__file__).parent.glob("*.py")}
    assert sorted(bundled - expected) == [] and sorted(expected - bundled) == []
    assert "fmus/runtime/slave/__init__.py" in bundled and not any(name.startswith("fmus/master/") for name in bundled)


def test_fmus_init_stays_tiny():
    """Every FMU bundles ``fmus/__init__.py``: it imports nothing."""
    tree = ast.parse((ROOT / "fmus" / "__init__.py").read_text())
    assert [node for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))] == []
