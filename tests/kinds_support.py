"""What the tests of the source, noise and expression kinds share: build FMUs, simulate one, read messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from fmus.builder import build_fmu


def build_all(definitions, directory: Path) -> dict[str, Path]:
    """``model name -> FMU`` of ``definitions``, each checked by fmpy's validation."""
    paths = {}
    for definition in definitions:
        path = build_fmu(definition, directory)
        assert validate_fmu(str(path)) == [], definition.model_name
        paths[definition.model_name] = path
    return paths


def simulate(path: Path, stop_time: float, step: float, messages: list | None = None, **start) -> np.ndarray:
    """fmpy's fixed-step run (one row per communication point); ``messages`` collects the FMU's log."""
    logger = None
    if messages is not None:
        def logger(environment, instance, status, category, message):
            messages.append(message.decode() if isinstance(message, bytes) else str(message))
    return simulate_fmu(str(path), stop_time=stop_time, step_size=step, output_interval=step,
                        start_values=start, logger=logger, debug_logging=False)
