"""The code an FMU bundles, relocated under one package per code version -- never on ``sys.path``.

Every FMU carries the code it runs on: the project packages (``fmus``, ``observers``,
``plants``), pythonfmu's slave base class and the user's extra modules.  The builder puts them
under a package named after the hash of that code, ``resources/_obsfmu_<hash>/``, and rewrites
their absolute imports of the bundled top-level names (:func:`relocate`: the exact import nodes
of the syntax tree, layout and line numbers kept)::

    from obsfmu.observers.block import Block  ->  from _obsfmu_3f2a....observers.block import Block

so FMUs built from different code never share a module, and an FMU never runs the host's own
``fmus`` (or a checkout's).  FMUs built from the same code share the package.

At run time the FMU maps project module names onto its own package with
:mod:`fmus.runtime.bundled` (bundled; this module, the relocation, is not).
"""

from __future__ import annotations

import ast
import re

from .runtime.bundled import NAMES

__all__ = ["relocate", "package_init", "RelocationError", "PROJECT"]

#: the installed package the project's code lives under (``obsfmu.fmus``, ``obsfmu.observers``, ``obsfmu.plants``):
#: inside an FMU its place is taken by the FMU's own package
PROJECT = "obsfmu"


class RelocationError(ValueError):
    """A bundled source uses an import the builder cannot relocate; the message says how to write it."""


def package_init(names) -> str:
    """Source of the relocated package's ``__init__.py``."""
    return ('"""Code bundled in an obsfmu FMU, relocated under one package per code version (fmus/bundle.py)."""\n'
            f"{NAMES} = {tuple(sorted(names))!r}\n")


_FROM = re.compile(rb"from(?:\s|\\\r?\n)+([A-Za-z_]\w*(?:\s*\.\s*[A-Za-z_]\w*)*)")


def relocate(source: bytes, package: str, names, filename: str = "<bundled>") -> bytes:
    """``source`` with its absolute imports of the top-level ``names`` moved under ``package``.

    Handles ``from X.y import z``, ``import X`` (-> ``import P.X as X``) and ``import X.y as z``;
    ``import X.y`` without ``as`` binds ``X`` itself and is refused with a
    :class:`RelocationError` naming the file and line.  Relative imports are left alone.
    """
    names = set(names)

    def moved(module: str) -> str:
        top = module.split(".")[0]
        return package + module[len(PROJECT):] if top == PROJECT else f"{package}.{module}"

    tree = ast.parse(source, filename)
    lines = source.splitlines(keepends=True)
    starts = [0]
    for line in lines:
        starts.append(starts[-1] + len(line))

    def offset(line: int, column: int) -> int:  # ast columns are UTF-8 byte offsets
        return starts[line - 1] + column

    edits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module.split(".")[0] in names | {PROJECT}:
            begin = offset(node.lineno, node.col_offset)
            match = _FROM.match(source, begin)
            if not match or re.sub(rb"\s", b"", match.group(1)).decode() != node.module:
                raise RelocationError(f"{filename}:{node.lineno}: cannot locate the module name of this import")
            edits.append((match.start(1), match.end(1), moved(node.module)))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] not in names | {PROJECT}:
                    continue
                if alias.asname is None and "." in alias.name:
                    raise RelocationError(f"{filename}:{node.lineno}: 'import {alias.name}' binds "
                                          f"{alias.name.split('.')[0]!r} and cannot be bundled; write "
                                          f"'from {alias.name.rpartition('.')[0]} import {alias.name.rpartition('.')[2]}'"
                                          f" or 'import {alias.name} as ...'")
                bound = alias.asname or alias.name
                edits.append((offset(alias.lineno, alias.col_offset), offset(alias.end_lineno, alias.end_col_offset),
                              f"{moved(alias.name)} as {bound}"))
    for begin, end, text in sorted(edits, reverse=True):
        source = source[:begin] + text.encode() + source[end:]
    return source
