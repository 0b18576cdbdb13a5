"""The numpy an FMU was built and tested with, against the one of the Python that runs it.

The builder records it in ``resources/build_info.json`` (:func:`running`; a win64 FMU also the numpy of the
Windows runtime it carries, ``built_with_win64``); at instantiation the slave compares it with the running one
(:func:`note`) and, when they differ, logs one line at Warning level, once per process and FMU: results may
then differ in the last digits (an FMU of numpy 2.4 run on numpy 1.26 gave ltv outputs 1e-6 apart).  scipy is
not compared: no FMU imports it at run time (the design code that does runs when the FMU is built).
"""

from __future__ import annotations

import json
import sys
from importlib import metadata
from pathlib import Path

__all__ = ["BUILD_INFO", "LIBRARIES", "running", "note"]

BUILD_INFO = "build_info.json"
LIBRARIES = ("numpy",)
_noted: set[tuple] = set()               # (model, source hash, recorded versions) already logged


def running() -> dict[str, str]:
    """``{"numpy": "2.4.6"}`` of this Python (``"none"``: not installed)."""
    found = {}
    for name in LIBRARIES:
        module = sys.modules.get(name)
        try:
            found[name] = getattr(module, "__version__", None) or metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "none"
    return found


def note(resources: Path, model: str) -> str | None:
    """The line to log when the versions recorded in ``resources`` differ from the running ones, the first
    time in this process for this FMU; otherwise (or for an FMU without a record) None."""
    try:
        info = json.loads((Path(resources) / BUILD_INFO).read_text())
        built_with = info.get("built_with_win64") if sys.platform == "win32" else None
        recorded = {name: str((built_with or info["built_with"])[name]) for name in LIBRARIES}
    except (OSError, ValueError, KeyError, TypeError):
        return None
    now = running()
    key = (model, info.get("source_hash"), tuple(recorded.values()))
    if recorded == now or key in _noted:
        return None
    _noted.add(key)
    return (f"{model} was built and tested with {_words(recorded)}; this Python runs {_words(now)}: "
            f"results may differ in the last digits")


def _words(versions: dict[str, str]) -> str:
    return ", ".join(f"{name} {version}" for name, version in versions.items())
