"""Sourceless bytecode: the .pyc an FMU carries instead of its sources (standalone and win64 runtimes)."""

from __future__ import annotations

import importlib.util
import marshal

__all__ = ["sourceless"]


def sourceless(data: bytes, name: str) -> bytes:
    """The source ``data`` compiled by this interpreter into a sourceless, unchecked hash-based .pyc (PEP 552):
    valid wherever it lies, on any platform's Python of this minor version."""
    code = compile(data, name, "exec", dont_inherit=True)
    return importlib.util.MAGIC_NUMBER + (1).to_bytes(4, "little") + importlib.util.source_hash(data) + marshal.dumps(code)
