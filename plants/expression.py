"""A nonlinear plant written as expressions (:mod:`observers.expressions`): no code.

Continuous::

    dx/dt = f(t, x, u, p),    y = h(t, x, u, p)

integrated with RK4 over sub-steps of at most ``max_substep``, each under local error control
(:func:`~observers.integrators.rk4_controlled`: the estimate within ``atol + rtol |x|``, else taken
again shorter, up to ``substep_budget`` sub-steps), the input taken linear over the communication
step (``u(t + s) = start + s slope``), so a linearly coupled input is followed exactly and the
accuracy does not depend on the master's step.  A stiff plant (``f = -2700 x`` at ``max_substep``
1e-3, where plain RK4 ends at 1.6e-3 instead of 2e-59 after 0.05 s) is integrated to ``atol`` or
refused naming ``substep_budget``.

Discrete, sample time ``T``::

    x[k+1] = f(t_k, x[k], u[k], p),    y[k] = h(t_k, x[k], u[k], p)

a communication step covers a whole number of samples; ``u[k]`` is the input at ``t_k``.

Ports: input ``u`` (m, absent if m = 0); outputs ``y`` (q) and the true state ``x`` (n), so that an
observer's error ``x - x_hat`` can be formed.  Direct feedthrough exactly when ``h`` reads ``u``.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.block import Segment
from obsfmu.observers.kernel_forms import ExpressionForm
from obsfmu.observers.checks import ParameterError, as_vector, require_positive
from obsfmu.observers.expressions import VectorFunction
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, require_budget, rk4_controlled, substep_count
from obsfmu.observers.sampling import SampledBlock

__all__ = ["ExpressionPlant", "DEFAULT_RTOL", "DEFAULT_ATOL"]

#: default local error tolerances of a continuous expression plant's sub-steps
DEFAULT_RTOL, DEFAULT_ATOL = 1e-8, 1e-12


class ExpressionPlant(SampledBlock):
    """Plant ``x' = f(t, x, u, p)`` (or ``x[k+1] = f`` with ``sample_time``), ``y = h(t, x, u, p)``.

    Parameters
    ----------
    f, h : VectorFunction
        The compiled right-hand side (n components) and output map (q components).
    p : array_like
        The parameter vector the expressions read (named parameters are entries of it).
    x0 : array_like
        Initial state (n).
    inputs : int
        Size m of the input ``u``.
    sample_time : float, optional
        ``T`` of a discrete plant; None: continuous.
    max_substep : float
        Longest RK4 sub-step of a continuous plant.
    rtol, atol : float
        Local error tolerances of each sub-step (relative, and absolute in the state's units).
    substep_budget : int
        Most sub-steps (or samples) one communication step may take (refused beyond).
    """

    not_state = ("f", "h", "p", "sample_time", "max_substep", "rtol", "atol", "substep_budget",
                 "_no_input")

    def __init__(self, f: VectorFunction, h: VectorFunction, p, x0, inputs: int, *, sample_time: float | None = None,
                 max_substep: float = 1e-3, rtol: float = DEFAULT_RTOL, atol: float = DEFAULT_ATOL,
                 substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.x = as_vector("x0", x0, f.size)
        self.f, self.h = f, h
        self.p = as_vector("p", p) if np.size(p) else np.zeros(0)
        if inputs < 0 or int(inputs) != inputs:
            raise ParameterError(f"inputs: expected the size of u (an integer >= 0), got {inputs!r}")
        self.sample_time = None if sample_time is None else require_positive("sample_time", sample_time)
        self.max_substep = require_positive("max_substep", max_substep)
        self.rtol, self.atol = require_positive("rtol", rtol), require_positive("atol", atol)
        self.substep_budget = require_budget(substep_budget)
        self.feedthrough = "u" in h.uses
        self.input_sizes = {"u": int(inputs)} if inputs else {}
        self.output_sizes = {"y": h.size, "x": f.size}
        self._no_input = np.zeros(0)
        if self.sample_time is not None:
            self._init_sampling(self.input_sizes)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        u = inputs["u"] if self.input_sizes else self._no_input
        return {"y": self.h(t, self.x, u, self.p), "x": self.x.copy()}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        if self.sample_time is not None:
            super().advance(t, h, inputs)
            return
        self.x = self._integrate(t, h, inputs["u"] if self.input_sizes else Segment.hold(self._no_input))

    def _integrate(self, t: float, h: float, u: Segment) -> np.ndarray:
        count = substep_count(h, self.max_substep, budget=self.substep_budget)
        f, p, start, slope = self.f.of_lists, self.p.tolist(), u.start.tolist(), u.slope.tolist()

        def rhs(s: float, x: np.ndarray) -> np.ndarray:       # on Python floats: the per-step cost
            elapsed = s - t
            return f(s, x.tolist(), [a + elapsed * b for a, b in zip(start, slope)], p)
        return rk4_controlled(rhs, float(t), self.x, h, count, self.rtol, self.atol, self.substep_budget)

    def kernel_form(self) -> ExpressionForm | None:
        """The compiled kernel's form of a continuous plant (its expressions compiled to C when the FMU is built);
        a discrete one steps in Python."""
        if self.sample_time is not None:
            return None
        return ExpressionForm("x", self.f.size, tuple(self.input_sizes), self.p,
                              (self.max_substep, self.rtol, self.atol, float(self.substep_budget)))

    def sample_period(self) -> float:
        return self.sample_time

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        self.x = self.f(t_k, self.x, inputs["u"] if self.input_sizes else self._no_input, self.p)
