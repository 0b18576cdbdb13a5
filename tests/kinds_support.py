"""What the tests of the source, noise and expression kinds share: build FMUs, simulate one, read messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu

from obsfmu.fmus.builder import build_fmu


def build_all(definitions, directory: Path) -> dict[str, Path]:
    """``model name -> FMU`` of ``definitions``, each checked by fmpy's validation."""
    paths = {}
    for definition in definitions:
        path = build_fmu(definition, directory)
        assert validate_fmu(str(path)) == [], definition.model_name
        paths[definition.model_name] = path
    return paths


def simulate(path: Path, stop_time: float, step: float, **start) -> np.ndarray:
    """fmpy's fixed-step run (one row per communication point).  (No ``logger``: fmpy's logger proxy keeps
    the last one process-wide and calls it after it is gone; tests/faults_support.Probe collects messages.)"""
    return simulate_fmu(str(path), stop_time=stop_time, step_size=step, output_interval=step, start_values=start)


def started(path: Path, name: str, **start) -> tuple[FMU2Slave, dict[str, int]]:
    """An instance of the FMU in step mode (``start``: values set before initialization) and its
    value references by name; the caller terminates and frees it."""
    description = read_model_description(str(path))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)), instanceName=name,
                      modelIdentifier=description.coSimulation.modelIdentifier)
    references = {v.name: v.valueReference for v in description.modelVariables}
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    if start:
        slave.setReal([references[k] for k in start], list(start.values()))
    slave.exitInitializationMode()
    return slave, references
