"""Full-order (Luenberger) observer -- paper 002, eqs. (2)-(3).

    x_hat' = A x_hat + B u + N (y - C x_hat - D u)
           = H x_hat + (B - N D) u + N y,        H = A - N C          (paper 002, eq. (3))

The observer is LTI in its inputs ``(u, y)``, so a step is integrated
exactly (:class:`~observers.integrators.LinearPropagator`) for inputs that
are held or linear over the step.  The estimation error ``e = x - x_hat``
obeys ``e' = H e``: it decays as the poles of ``H`` say.

For a discrete plant (sample time ``T``) the observer is the predictor

    x_hat[k+1] = A x_hat[k] + B u[k] + N (y[k] - C x_hat[k] - D u[k]),    e[k+1] = (A - N C) e[k]

updated at the instants ``k T`` a communication step contains (:class:`~observers.sampling.SampledBlock`),
``A - N C`` Schur-stable (every eigenvalue inside the unit circle).

An observer designed from a linearisation at an operating point (:mod:`observers.linearise`) has the affine
terms of the model ``x' ~ f_0 + A (x - x_0) + B (u - u_0)``, ``y ~ y_0 + C (x - x_0) + D (u - u_0)``:
``x_hat' = A x_hat + B u + N (y - y_hat) + c``, ``y_hat = C x_hat + D u + e`` with the constants
``c = f_0 - A x_0 - B u_0`` (``offset``) and ``e = y_0 - C x_0 - D u_0`` (``output_offset``).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from .kernel_forms import AffineForm, output_map
from .block import Segment
from .checks import ParameterError, as_matrix, as_vector, require_hurwitz
from .integrators import DEFAULT_SUBSTEP_BUDGET, LinearPropagator, require_budget
from .lti_model import StateSpace
from .sampling import SampledBlock

__all__ = ["LuenbergerObserver"]


class LuenbergerObserver(SampledBlock):
    """Luenberger observer of ``x' = A x + B u, y = C x + D u`` (or of the discrete ``x[k+1] = A x[k] + B u[k]``).

    Parameters
    ----------
    A, B, C, D : array_like
        Plant model, ``(n, n)``, ``(n, m)``, ``(p, n)``, ``(p, m)``; ``B``/``D`` may be omitted.  ``A`` may be a
        :class:`~observers.lti_model.StateSpace` (a discrete one: the predictor of the module docstring).
    N : (n, p) array_like
        Observer gain; ``H = A - N C`` must be Hurwitz (discrete: Schur, every ``|eigenvalue| < 1``).
    x_hat0 : (n,) array_like, optional
        Initial estimate (default zero).
    substep_budget : int
        Discrete: most sample instants one communication step may contain.
    offset, output_offset : array_like, optional
        ``c`` (n) and ``e`` (p) of a model linearised at an operating point (module docstring; default zero).

    Ports: inputs ``u`` (m), ``y`` (p); outputs ``x_hat`` (n), ``y_hat`` (p).
    """

    not_state = ("model", "N", "H", "_propagator", "substep_budget", "offset", "output_offset", "_affine")

    def __init__(self, A, B=None, C=None, N=None, x_hat0=None, D=None, substep_budget=DEFAULT_SUBSTEP_BUDGET,
                 offset=None, output_offset=None):
        model = A if isinstance(A, StateSpace) else StateSpace.checked(A, B, C, D)
        if N is None:
            raise ParameterError("N: the observer gain is required (see observers.modal.design_observer)")
        self.model = model
        self.N = as_matrix("N", N, shape=(model.n, model.p))
        self.H = _require_stable("N", model.A - self.N @ model.C, model.discrete)
        self.x_hat = np.zeros(model.n) if x_hat0 is None else as_vector("x_hat0", x_hat0, model.n)
        self.feedthrough = bool(np.any(model.D))
        self.input_sizes = {"u": model.m, "y": model.p}
        self.output_sizes = {"x_hat": model.n, "y_hat": model.p}
        self.substep_budget = require_budget(substep_budget)
        self.offset = np.zeros(model.n) if offset is None else as_vector("offset", offset, model.n)
        self.output_offset = np.zeros(model.p) if output_offset is None else \
            as_vector("output_offset", output_offset, model.p)
        # the affine terms as a constant input: x_hat' = H x_hat + [B - N D, N, c - N e] [u; y; 1] (none: the
        # linear observer, its matrices as they always were)
        self._affine = bool(np.any(self.offset) or np.any(self.output_offset))
        inputs = [model.B - self.N @ model.D, self.N] + \
            ([(self.offset - self.N @ self.output_offset)[:, None]] if self._affine else [])
        self._propagator = None if model.discrete else LinearPropagator(self.H, np.hstack(inputs))
        if model.discrete:
            self._init_sampling(self.input_sizes)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y_hat = self.model.C @ self.x_hat + self.output_offset
        if self.feedthrough:
            y_hat = y_hat + self.model.D @ inputs["u"]
        return {"x_hat": self.x_hat.copy(), "y_hat": y_hat}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        if self._propagator is None:
            super().advance(t, h, inputs)            # discrete: the samples k T of the step
            return
        u, y = inputs["u"], inputs["y"]
        start = np.concatenate([u.start, y.start] + ([[1.0]] if self._affine else []))
        slope = np.concatenate([u.slope, y.slope] + ([[0.0]] if self._affine else []))
        self.x_hat = self._propagator.step(self.x_hat, h, start, slope)

    def kernel_form(self) -> AffineForm | None:
        """The compiled kernel's form of this observer (continuous only; the discrete predictor steps in Python):
        ``w = [u; y]`` (and 1 with the offsets), the outputs ``x_hat = x`` and ``y_hat = C x + D u + e``."""
        if self._propagator is None:
            return None
        m = self.model
        inputs = m.m + m.p
        return AffineForm("x_hat", m.n, ("u", "y"), self._affine, self._propagator.matrices,
                          {"x_hat": output_map(np.eye(m.n), inputs=inputs),
                           "y_hat": output_map(m.C, np.hstack([m.D, np.zeros((m.p, m.p))]), self.output_offset,
                                               inputs)})

    def sample_period(self) -> float:
        return self.model.dt

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        """``x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u)`` from ``u[k]``, ``y[k]``."""
        m = self.model
        innovation = inputs["y"] - m.C @ self.x_hat - m.D @ inputs["u"] - self.output_offset
        self.x_hat = m.A @ self.x_hat + m.B @ inputs["u"] + self.N @ innovation + self.offset


def _require_stable(name: str, H: np.ndarray, discrete: bool) -> np.ndarray:
    """``H`` Hurwitz, or for a discrete observer Schur (every ``|eigenvalue| < 1``), else refused naming ``name``."""
    if not discrete:
        return require_hurwitz(name, H)
    radius = float(np.max(np.abs(np.linalg.eigvals(H)))) if H.size else 0.0
    if not radius < 1.0:
        raise ParameterError(f"{name}: A - N C has an eigenvalue of magnitude {radius:.6g} >= 1; a discrete "
                             "observer's error e[k+1] = (A - N C) e[k] decays only inside the unit circle")
    return H
