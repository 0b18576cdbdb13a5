"""Linear time-invariant plant ``x' = A x + B u`` (or ``x[k+1] = A x[k] + B u[k]``), ``y = C x + D u``.

The true state is an output too, so estimation errors ``x - x_hat`` can be
computed.  A continuous step is integrated exactly for an input that is held or linear
over the step (:class:`~observers.integrators.LinearPropagator`); a discrete plant (sample
time ``dt``) is updated at the instants ``t_k = k dt`` a step contains, ``u[k]`` the input at ``t_k``
(:class:`~observers.sampling.SampledBlock`: any communication step).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.kernel_forms import AffineForm, output_map
from obsfmu.observers.block import Segment
from obsfmu.observers.checks import as_vector
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, LinearPropagator, require_budget
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.sampling import SampledBlock

__all__ = ["LTIPlant"]


class LTIPlant(SampledBlock):
    """LTI plant with initial state ``x0``.

    Ports: input ``u`` (m); outputs ``y`` (p) and ``x`` (n).  ``A`` may be a whole system
    (:meth:`observers.lti_model.StateSpace.of`: a ``control.StateSpace``, continuous or discrete).
    """

    not_state = ("model", "_propagator", "substep_budget")

    def __init__(self, A, B=None, C=None, D=None, x0=None, substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        is_system = B is None and C is None and D is None and not isinstance(A, (list, np.ndarray))
        self.model = StateSpace.of(A) if is_system else StateSpace.checked(A, B, C, D)
        self.substep_budget = require_budget(substep_budget)
        self.x = np.zeros(self.model.n) if x0 is None else as_vector("x0", x0, self.model.n)
        self.feedthrough = bool(np.any(self.model.D))
        self.input_sizes = {"u": self.model.m}
        self.output_sizes = {"y": self.model.p, "x": self.model.n}
        self._propagator = None if self.model.discrete else LinearPropagator(self.model.A, self.model.B)
        if self.model.discrete:
            self._init_sampling(self.input_sizes)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y = self.model.C @ self.x
        if self.feedthrough:
            y = y + self.model.D @ inputs["u"]
        return {"y": y, "x": self.x.copy()}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        u = inputs["u"]
        if self._propagator is not None:
            self.x = self._propagator.step(self.x, h, u.start, u.slope)
            return
        super().advance(t, h, inputs)

    def kernel_form(self) -> AffineForm | None:
        """The compiled kernel's form of this plant (continuous only; a discrete one steps in Python)."""
        if self._propagator is None:
            return None
        m = self.model
        return AffineForm("x", m.n, ("u",), False, self._propagator.matrices,
                          {"y": output_map(m.C, m.D, inputs=m.m), "x": output_map(np.eye(m.n), inputs=m.m)})

    def sample_period(self) -> float:
        return self.model.dt

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        self.x = self.model.A @ self.x + self.model.B @ inputs["u"]
