"""Checks by an in-memory run of a system file's own experiment, before any FMU exists (issue 36).

An adaptive observer can be well posed and still unable to identify its plant in the experiment the file
describes (unknowns that cannot be separated, too little excitation where the regression is exact).  The
families check it by running the blocks the FMUs would run -- the same factories, in memory -- along the
file's experiment.  What is shared lives here:

* :func:`block_of`, :func:`component_block`: the block of a definition, of a component named in a field;
* :func:`drive`: a source driving a plant and an observer of both, as a Gauss-Seidel master with linear
  coupling would;
* :func:`check_key`: what a verdict depends on (the inputs and the sources of the code), for
  :func:`fmus.caches.remembered` -- a run costs seconds, a cached verdict milliseconds;
* :func:`refuse_or_warn`: the file's choice (field ``check``): refused in one line naming the field, or
  built anyway with the finding printed and logged by the FMU at every instantiation.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError

from ..runtime.definition import FmuDefinition
from ..runtime.kinds import create_block
from .schema import TYPES, Context, Field

__all__ = ["CHECK_FIELD", "block_of", "check_key", "component_block", "drive", "refuse_or_warn"]

#: the field of every observer that checks its file by an in-memory run
CHECK_FIELD = Field("check", "boolean", "check before the build, by an in-memory run of the file's experiment, that "
                    "the observer can identify its unknowns there; false: build anyway, the finding logged by the FMU "
                    "as a warning", True, example="false")

_ROOT = Path(__file__).resolve().parents[2]


def block_of(definition: FmuDefinition):
    """The block an FMU of ``definition`` runs, built in memory (the same factory)."""
    return create_block(definition.kind, {p.name: p.array(p.value) for p in definition.parameters},
                        definition.options)


def component_block(name: str, context: Context):
    """The block of the component ``name`` defined before the one of ``context`` (its first FMU's)."""
    kind, values = context.others[name]
    sub = Context(prefix=f"components.{name}.", name=context.name, others=context.others, folder=context.folder,
                  stop_time=context.stop_time, step=context.step)
    return block_of(TYPES[kind].define("check", {**values, "given": set()}, sub)[0])


def drive(source, plant, observer, stop_time: float, step: float) -> tuple[dict, dict, float]:
    """``source`` (no input, output ``y``) drives ``plant`` (input ``u``, output ``y``) and ``observer`` (inputs
    ``u``, ``y``) over ``[0, stop_time]`` at ``step``, the plant first, the inputs linear across each step.
    Returns the outputs of the plant and the observer at the end and the largest ``excitation`` output of the
    observer over the run.  The blocks advance (pass copies to keep them)."""
    steps = max(1, int(round(stop_time / step)))
    h, largest = stop_time / steps, 0.0
    u0, y0 = source.outputs(0.0, {})["y"], plant.outputs(0.0, {})["y"]
    for k in range(steps):
        t = k * h
        source.advance(t, h, {})
        u1 = source.outputs(t + h, {})["y"]
        u = Segment.between(u0, u1, h)
        plant.advance(t, h, {"u": u})
        y1 = plant.outputs(t + h, {})["y"]
        observer.advance(t, h, {"u": u, "y": Segment.between(y0, y1, h)})
        largest = max(largest, float(observer.outputs(t + h, {})["excitation"][0]))
        u0, y0 = u1, y1
    return plant.outputs(stop_time, {}), observer.outputs(stop_time, {}), largest


def check_key(inputs: dict, sources: tuple[str, ...]) -> str:
    """Everything a verdict depends on: ``inputs`` (JSON with arrays as lists) and the files or folders
    ``sources`` of the repository (the code that computes it; a few ms to hash)."""
    files = sorted(f for name in sources for f in ((_ROOT / name).rglob("*.py") if (_ROOT / name).is_dir()
                                                   else [_ROOT / name]))
    text = json.dumps(inputs, sort_keys=True, default=lambda o: sorted(o) if isinstance(o, set) else np.asarray(o).tolist())
    return text + "".join(hashlib.sha256(f.read_bytes()).hexdigest() for f in files)


def refuse_or_warn(finding: tuple[str, str] | list[str] | None, values: dict, context: Context,
                   definition: FmuDefinition) -> None:
    """``finding = (field, text)``: refused naming ``context.prefix + field``, or with ``check = false`` kept
    in ``definition.warnings`` (the FMU logs it) and printed with the build's notes."""
    if finding is None:
        return
    field, text = finding
    if values["check"]:
        raise ParameterError(f"{context.prefix}{field}: {text}; or set check = false to build anyway")
    definition.warnings.append(f"{context.prefix}{field}: {text}")
    context.notes.append(f"{context.prefix.rstrip('.')}: WARNING, built anyway (check = false): {field}: {text}")
