"""Linear time-invariant plant ``x' = A x + B u``, ``y = C x + D u``.

The true state is an output too, so estimation errors ``x - x_hat`` can be
computed.  A step is integrated exactly for an input that is held or linear
over the step (:class:`~observers.integrators.LinearPropagator`).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from observers.block import Block, Segment
from observers.checks import as_vector
from observers.integrators import LinearPropagator
from observers.lti_model import StateSpace

__all__ = ["LTIPlant"]


class LTIPlant(Block):
    """LTI plant with initial state ``x0``.

    Ports: input ``u`` (m); outputs ``y`` (p) and ``x`` (n).
    """

    not_state = ("model", "_propagator")

    def __init__(self, A, B=None, C=None, D=None, x0=None):
        self.model = StateSpace.checked(A, B, C, D)
        self.x = np.zeros(self.model.n) if x0 is None else as_vector("x0", x0, self.model.n)
        self.feedthrough = bool(np.any(self.model.D))
        self.input_sizes = {"u": self.model.m}
        self.output_sizes = {"y": self.model.p, "x": self.model.n}
        self._propagator = LinearPropagator(self.model.A, self.model.B)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y = self.model.C @ self.x
        if self.feedthrough:
            y = y + self.model.D @ inputs["u"]
        return {"y": y, "x": self.x.copy()}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        u = inputs["u"]
        self.x = self._propagator.step(self.x, h, u.start, u.slope)
