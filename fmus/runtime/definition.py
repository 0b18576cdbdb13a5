"""What an FMU is made of, as data: the JSON file bundled in every FMU.

An :class:`FmuDefinition` names a *kind* (a block factory registered in
:mod:`fmus.runtime.kinds`), the start values of its parameters and the ports of the
block.  The builder writes it next to a two-line slave module; the generic
slave (:mod:`fmus.runtime.slave`) reads it back when the FMU is instantiated.

Naming (Modelica arrays, fixed when the FMU is built):

* a vector ``x`` of size n is ``x[1] .. x[n]``; a matrix ``A`` is ``A[i,j]``;
* a signal dimension of size one is dropped: for a single-input,
  single-output plant ``u``/``y`` are scalars, ``B`` (n x 1) is ``B[i]``,
  ``C`` (1 x n) is ``C[j]``, ``N`` (n x 1) is ``N[i]``, ``K`` (1 x n) is ``K[j]``.
  State dimensions are never dropped: ``x[1]`` even when n = 1.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from itertools import product
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Port", "Parameter", "FmuDefinition", "element_names", "element_unit", "valid_identifier", "experiment"]

Unit = str | list[str] | None  #: one unit for every element, or one per element

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def valid_identifier(name: str) -> bool:
    return bool(_IDENTIFIER.fullmatch(name))  # not match + "$": "$" accepts a trailing newline


def experiment(stop_time: float, step: float, start_time: float = 0.0) -> dict[str, float]:
    """An FMU's ``DefaultExperiment`` (``FmuDefinition.default_experiment``): the run it was made for.

    No ``tolerance``: the FMUs are co-simulation slaves that integrate over a step with their own
    settings (``max_substep``, exact steps), so no solver tolerance of the importer applies to them.
    """
    return {"start_time": float(start_time), "stop_time": float(stop_time), "step_size": float(step)}


def element_unit(unit: Unit, index: int) -> str | None:
    """Unit of element ``index`` (flat) of an array whose unit is ``unit``."""
    return unit[index] if isinstance(unit, list) else unit


def element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    """Scalar FMI names of an array, row-major: ``A[1,1], A[1,2], ...``."""
    if len(shape) == 0:
        return [name]
    return [f"{name}[{','.join(str(i + 1) for i in index)}]"
            for index in product(*(range(s) for s in shape))]


@dataclass
class Port:
    """An input or output of a block: a 1-D signal of ``size`` entries."""

    name: str
    size: int
    description: str
    unit: Unit = None
    scalar: bool = False  #: named without index (requires size 1)
    labels: list[str] | None = None  #: a name per element (``state_names`` of a plant): descriptions, summaries, plots

    @property
    def naming_shape(self) -> tuple[int, ...]:
        return () if self.scalar else (self.size,)

    @property
    def element_names(self) -> list[str]:
        return element_names(self.name, self.naming_shape)

    def element_description(self, index: int) -> str:
        """The description of element ``index``: the port's, with the element's name when it has one."""
        return self.description if not self.labels else f"{self.description}: {self.labels[index]}"


@dataclass
class Parameter:
    """A parameter array; every element becomes one FMI parameter."""

    name: str
    value: list  #: flat, row-major
    shape: list[int]  #: shape handed to the block factory
    naming_shape: list[int]  #: shape used for the FMI names (signal singletons dropped)
    description: str
    unit: Unit = None

    @classmethod
    def of(cls, name: str, value, description: str, unit: Unit = None,
           drop_axes: tuple[int, ...] = ()) -> "Parameter":
        """Parameter from an array; ``drop_axes`` lists signal axes dropped from names when of size 1."""
        array = np.asarray(value, dtype=float)
        naming = [s for axis, s in enumerate(array.shape) if not (axis in drop_axes and s == 1)]
        return cls(name, array.ravel().tolist(), list(array.shape), naming, description, unit)

    @classmethod
    def scalar(cls, name: str, value, description: str, unit: Unit = None) -> "Parameter":
        """A single number, named without index."""
        return cls.of(name, np.array(float(value)), description, unit)

    @classmethod
    def substep_budget(cls, value=None) -> "Parameter":
        """``substep_budget`` of a block that sub-steps (:func:`observers.integrators.substep_count`)."""
        from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET
        return cls.scalar("substep_budget", DEFAULT_SUBSTEP_BUDGET if value is None else value,
                          "most sub-steps one communication step may take; a step needing more is refused "
                          "(fmi2Discard) before any work")

    @property
    def element_names(self) -> list[str]:
        return element_names(self.name, tuple(self.naming_shape))

    def array(self, flat_values) -> np.ndarray:
        return np.asarray(flat_values, dtype=float).reshape(self.shape)


@dataclass
class FmuDefinition:
    """Everything the generic slave needs to expose a block as an FMU."""

    model_name: str
    kind: str
    description: str
    parameters: list[Parameter]
    inputs: list[Port]
    outputs: list[Port]
    feedthrough: bool = False  #: outputs depend on the current inputs
    kind_module: str = ""  #: module registering ``kind`` (filled in by the builder)
    options: dict[str, Any] = field(default_factory=dict)
    #: ``DefaultExperiment`` (:func:`experiment`): start, stop, step of the FMU's scenario or design, so that
    #: importers run without options (None: the scenario fills in its own, ``fmus.scenarios``)
    default_experiment: dict[str, float] | None = None
    #: canHandleVariableCommunicationStepSize: False for blocks that accept one step length only
    variable_step: bool = True
    #: maxOutputDerivativeOrder = 1: the block's ``derivative(t)`` is the time derivative of its one output
    #: port (the sources), read by fmi2GetRealOutputDerivatives
    output_derivatives: bool = False
    #: what a check found and the file chose to build anyway (``check = false``): logged by the FMU as a
    #: warning at every instantiation, so the importer's log keeps it
    warnings: list[str] = field(default_factory=list)
    #: ``"c"``: steps in the compiled kernel when the block has one (linear blocks: fmus/runtime/slave/kernel.py);
    #: ``"python"``: always in Python (``obsfmu build --kernels python``)
    kernels: str = "c"

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1)

    @classmethod
    def from_json(cls, text: str) -> "FmuDefinition":
        data = json.loads(text)
        data["parameters"] = [Parameter(**p) for p in data["parameters"]]
        data["inputs"] = [Port(**p) for p in data["inputs"]]
        data["outputs"] = [Port(**p) for p in data["outputs"]]
        return cls(**data)

    @classmethod
    def load(cls, path: Path) -> "FmuDefinition":
        return cls.from_json(Path(path).read_text())


def column_labels(instances) -> dict[str, str]:
    """Column -> the name a plant gave the entry (``state_names`` ...), over ``(instance, definition)`` pairs:
    ``{"plant.x[1]": "current", "observer.x_hat[1]": "current"}`` (columns without a name are left out)."""
    found = {}
    for instance, definition in instances:
        for port in definition.outputs:
            if port.labels:
                found.update({f"{instance}.{name}": label for name, label in zip(port.element_names, port.labels)})
    return found
