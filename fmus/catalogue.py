"""The scenarios' names, descriptions and defaults, read from their system files alone.

``obsfmu list`` and ``obsfmu run --help`` need only these; the registry (:data:`fmus.scenarios.SCENARIOS`)
imports every scenario with numpy, fmpy and the master (about a second).  Each scenario is the
``system.toml`` of its folder ``fmus/scenarios/<name with _>/``, named with ``-`` (as
:func:`fmus.scenarios.ltv_common.scenario` names them); a folder without one is no scenario.  The
defaults of absent fields are those of :data:`fmus.system.load.EXPERIMENT_FIELDS` and ``TOP_FIELDS``;
tests/fmus/cli/test_startup.py checks that every entry equals the registry's scenario.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["Entry", "entries"]

SCENARIO_FOLDER = Path(__file__).parent / "scenarios"


@dataclass(frozen=True)
class Entry:
    """What ``obsfmu list`` prints of a scenario (the fields of :class:`fmus.scenarios.Scenario`)."""

    name: str
    description: str
    stop_time: float
    step: float
    order: str
    coupling: str
    time_unit: str


def _entry(path: Path) -> Entry:
    with open(path, "rb") as file:
        data = tomllib.load(file)
    experiment = data["experiment"]
    return Entry(path.parent.name.replace("_", "-"), data.get("description", ""), float(experiment["stop_time"]),
                 float(experiment["step"]), experiment.get("master", "gauss-seidel"),
                 experiment.get("coupling", "linear"), data.get("time_unit", "s"))


def entries() -> dict[str, Entry]:
    """Every scenario by name, in the registry's order (by folder name)."""
    files = sorted(SCENARIO_FOLDER.glob("*/system.toml"), key=lambda p: p.parent.name)
    return {entry.name: entry for entry in map(_entry, files)}
