"""Full-order (Luenberger) observer -- paper 002, eqs. (2)-(3).

    x_hat' = A x_hat + B u + N (y - C x_hat - D u)
           = H x_hat + (B - N D) u + N y,        H = A - N C          (paper 002, eq. (3))

The observer is LTI in its inputs ``(u, y)``, so a step is integrated
exactly (:class:`~observers.integrators.LinearPropagator`) for inputs that
are held or linear over the step.  The estimation error ``e = x - x_hat``
obeys ``e' = H e``: it decays as the poles of ``H`` say.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .block import Block, Segment
from .checks import ParameterError, as_matrix, as_vector, require_hurwitz
from .integrators import LinearPropagator
from .lti_model import StateSpace

__all__ = ["LuenbergerObserver"]


class LuenbergerObserver(Block):
    """Luenberger observer of ``x' = A x + B u, y = C x + D u``.

    Parameters
    ----------
    A, B, C, D : array_like
        Plant model, ``(n, n)``, ``(n, m)``, ``(p, n)``, ``(p, m)``; ``B``/``D`` may be omitted.
    N : (n, p) array_like
        Observer gain; ``H = A - N C`` must be Hurwitz.
    x_hat0 : (n,) array_like, optional
        Initial estimate (default zero).

    Ports: inputs ``u`` (m), ``y`` (p); outputs ``x_hat`` (n), ``y_hat`` (p).
    """

    not_state = ("model", "N", "H", "_propagator")

    def __init__(self, A, B=None, C=None, N=None, x_hat0=None, D=None):
        model = StateSpace.checked(A, B, C, D)
        if N is None:
            raise ParameterError("N: the observer gain is required (see observers.modal.design_observer)")
        self.model = model
        self.N = as_matrix("N", N, shape=(model.n, model.p))
        self.H = require_hurwitz("N", model.A - self.N @ model.C)
        self.x_hat = np.zeros(model.n) if x_hat0 is None else as_vector("x_hat0", x_hat0, model.n)
        self.feedthrough = bool(np.any(model.D))
        self.input_sizes = {"u": model.m, "y": model.p}
        self.output_sizes = {"x_hat": model.n, "y_hat": model.p}
        self._propagator = LinearPropagator(self.H, np.hstack([model.B - self.N @ model.D, self.N]))

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y_hat = self.model.C @ self.x_hat
        if self.feedthrough:
            y_hat = y_hat + self.model.D @ inputs["u"]
        return {"x_hat": self.x_hat.copy(), "y_hat": y_hat}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        u, y = inputs["u"], inputs["y"]
        start = np.concatenate([u.start, y.start])
        slope = np.concatenate([u.slope, y.slope])
        self.x_hat = self._propagator.step(self.x_hat, h, start, slope)
