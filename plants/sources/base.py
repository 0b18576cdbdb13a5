"""What every source shares: the base block, interval boundaries, scalar parameters."""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, as_vector
from obsfmu.observers.kernel_forms import ExpressionForm

__all__ = ["BOUNDARY_TOLERANCE", "interval_index", "scalar_parameter", "integer_parameter", "Source",
           "PiecewiseConstant"]

#: fraction of an interval within which a time counts as on the next boundary
BOUNDARY_TOLERANCE = 1e-9


def interval_index(t, dt: float):
    """Index ``k`` of the interval ``[k dt, (k + 1) dt)`` holding ``t``; negative times give 0
    (and indices are capped at ``2^62``, far beyond any run, so a huge time cannot overflow)."""
    k = np.floor(np.asarray(t, dtype=float) / dt + BOUNDARY_TOLERANCE)
    return np.clip(np.nan_to_num(k, nan=0.0), 0, 2.0 ** 62).astype(np.int64)


def scalar_parameter(name: str, value) -> float:
    """``value`` as one finite float; :class:`ParameterError` naming ``name`` otherwise."""
    return float(as_vector(name, value, 1)[0])


def integer_parameter(name: str, value, low: int, high: int | None = None, expected: str | None = None) -> int:
    """``value`` as an int in ``[low, high]`` (an integral float such as an FMU's 7.0 is accepted, a bool
    is not); :class:`ParameterError` naming ``name`` and saying ``expected`` (by default: "an integer >=
    low") otherwise."""
    integral = (isinstance(value, (int, np.integer)) or (isinstance(value, (float, np.floating))
                                                         and math.isfinite(value) and value == int(value))) \
        and not isinstance(value, bool)
    if not integral or value < low or (high is not None and value > high):
        raise ParameterError(f"{name}: expected {expected or f'an integer >= {low}'}, got {value!r}")
    return int(value)


class Source(Block):
    """Base of every source: no inputs, ``y = [value(t)]``, nothing to integrate.

    A subclass sets its parameters in ``__init__`` (after ``super().__init__()``), lists them in
    ``not_state`` and implements ``value(t)`` and ``derivative(t)``.
    """

    stateless = True

    def __init__(self):
        self.input_sizes = {}
        self.output_sizes = {"y": 1}

    def value(self, t):
        raise NotImplementedError

    def derivative(self, t):
        raise NotImplementedError

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {"y": np.array([float(self.value(t))])}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        """Nothing to integrate: the output is a function of time."""

    def expression(self) -> str | None:
        """``value(t)`` in the expression language (:mod:`observers.expressions`) of ``t`` and ``p`` =
        :meth:`parameters`, the same operations in the same order: compiled to C when the FMU is built, the
        compiled step kernel's output (issue 39).  None: this source steps in Python."""
        return None

    def parameters(self) -> np.ndarray:
        """The vector ``p`` that :meth:`expression` reads."""
        return np.zeros(0)

    def kernel_form(self) -> ExpressionForm | None:
        """The compiled kernel's form: no state, the output :meth:`expression` (None without one)."""
        if self.expression() is None:
            return None
        return ExpressionForm("", 0, (), self.parameters(), (math.inf, 1.0, 1.0, 1.0), outputs=("y",))


class PiecewiseConstant(Source):
    """A source that only jumps: ``derivative(t) = 0`` (from the right at a jump too)."""

    def derivative(self, t):
        return 0.0 * np.asarray(t, dtype=float)
