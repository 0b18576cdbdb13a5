"""The paper scenarios as system files: each scenario's folder holds the file that defines it.

:func:`paper_scenario` reads a scenario's system file and adds what only the paper knows -- its
summary against the independent reference, its figure, its sweep measure, its claim -- so that
``obsfmu run SCENARIO`` and ``obsfmu run --config <(obsfmu show SCENARIO)`` build the same FMUs and
write the same CSV, bit for bit (``tests/fmus/system/test_paper_files.py``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .load import load_system

__all__ = ["paper_scenario"]


def paper_scenario(path: Path | str, name: str, **paper):
    """The scenario ``name`` of the system file ``path``, with the paper's own parts.

    Parameters
    ----------
    path : Path or str
        The scenario's system file (beside its ``__init__.py``).
    name : str
        The scenario's name (``ltv-ls-bounded``; the file's own ``name`` is an identifier).
    **paper
        Fields of :class:`~fmus.scenarios.Scenario` only the paper gives: ``summarize``, ``plot``,
        ``measure``, ``claim``, ``not_adaptive``, ``adaptive_floor``.  Nothing that changes the run:
        that is all in the file.

    Returns
    -------
    fmus.scenarios.Scenario
    """
    numerics = {"definitions", "components", "connections", "stop_time", "step", "order", "coupling",
                "output_interval", "tolerance", "ramp", "time_unit"}
    changed = numerics & set(paper)
    if changed:
        raise ValueError(f"{name}: {sorted(changed)} belong in the system file {path}, not in Python")
    return replace(load_system(path).scenario(), name=name, **paper)
