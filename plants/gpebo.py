r"""Paper 000's discrete plant (1)-(2): a shift system with generator-driven coefficients.

.. math::
    x(k+1) = A x(k) + e_n \beta(k) u(k) + \theta(k) \circ f(y(k)) + \delta(k)
           = A x(k) + D(u(k), y(k))\, \xi(k), \qquad y(k) = x_1(k), \qquad
    \xi(k+1) = \Gamma \xi(k),

for any ``n`` and generator sizes ``l, m, r`` (structure in
:class:`observers.gpebo.model.GeneratorModel`).  The plant is updated at
the instants ``t_k = k Ts`` a communication step contains (any step:
:class:`~observers.sampling.SampledBlock`), with ``u(k) = u(t_k)`` (the input at the
step start when ``t_k`` is a communication point; its DefaultExperiment steps one ``Ts``).

Paper example (``n = 2``, ``delta = 0``): ``x1(k+1) = x2(k) + theta1(k) sin x1(k)``,
``x2(k+1) = beta(k) u(k)`` (``h_theta = [[1, 0], [0, 0]]`` makes ``theta2 = 0``),
``Gamma_beta = [[0, 1], [gamma_beta, 0]]``, ``Gamma_theta = [[0, 1], [gamma_theta, 0]]``,
``gamma_beta = -1``, ``gamma_theta = 1``.  The paper gives no initial states;
:data:`EXAMPLE` uses ``xi_beta(0) = [1, 0.5]``, ``xi_theta(0) = [0.5, -0.4]``,
``x(0) = [0.3, -0.2]``.

Boundedness.  ``eig(Gamma_beta) = +-i`` and ``eig(Gamma_theta) = +-1``: both
generators are marginally stable with simple eigenvalues, so ``beta`` is
4-periodic (``1, 0.5, -1, -0.5, ...``) and ``theta1`` 2-periodic.  Then
``|x2(k+1)| <= max|beta| |u(k)|`` and ``|x1(k+1)| <= |x2(k)| + max|theta1|``:
the paper's example is bounded for every bounded input, no bounded variant
is needed.  ``|gamma| > 1`` makes a generator (and the plant) grow
geometrically; ``0 < |gamma| < 1`` makes it decay.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.checks import as_vector, finite_signal, require_positive
from obsfmu.observers.gpebo.model import GeneratorModel, shift_matrix
from obsfmu.observers.sampling import SampledBlock

__all__ = ["GeneratorPlant", "sine", "example_model", "EXAMPLE"]


def sine(y):
    """``f_i(y) = sin y`` for every ``i`` (paper 000's example uses ``f1 = sin x1``)."""
    return np.sin(y)


#: paper 000's example (initial states are ours: the paper does not give them)
EXAMPLE = dict(
    gamma_beta=[0.0, -1.0],
    gamma_theta=[0.0, 1.0],
    xi_beta0=[1.0, 0.5],
    xi_theta0=[0.5, -0.4],
    x0=[0.3, -0.2],
    h_beta=[1.0, 0.0],
    H_theta=[[1.0, 0.0], [0.0, 0.0]],
)


def example_model(f=sine) -> GeneratorModel:
    """Known structure of the example: ``n = 2``, ``h_beta = [1, 0]``, ``H_theta = [[1, 0], [0, 0]]``, no delta."""
    return GeneratorModel.checked(2, EXAMPLE["h_beta"], EXAMPLE["H_theta"], None, f)


class GeneratorPlant(SampledBlock):
    """The discrete plant (1)-(2), updated at the instants ``k Ts``.

    Parameters
    ----------
    model : GeneratorModel
        Known structure (``n``, ``h_beta``, ``H_theta``, ``H_delta``, ``f``).
    gamma_beta, gamma_theta, gamma_delta : array_like, shapes (l,), (m,), (r,)
        Generator coefficients, ``Gamma = Gamma0 + gamma e_1^T``.
    xi_beta0, xi_theta0, xi_delta0 : array_like
        Generator initial states.
    x0 : array_like, shape (n,)
        Initial state.
    Ts : float
        Sample period (s).

    Ports: input ``u``; outputs ``y``, ``x`` (n), ``beta``, ``theta`` (n) and,
    when ``r > 0``, ``delta`` (n).
    """

    not_state = ("model", "Ts", "A", "Gamma")

    def __init__(self, model: GeneratorModel, gamma_beta, gamma_theta, xi_beta0, xi_theta0, x0, Ts,
                 gamma_delta=(), xi_delta0=()):
        self.model = model
        l, m, r = model.sizes
        self.Ts = require_positive("Ts", Ts)
        self.A = shift_matrix(model.n)
        self.Gamma = model.transition(gamma_beta, gamma_theta, gamma_delta)
        self.xi = np.concatenate([as_vector("xi_beta0", xi_beta0, l), as_vector("xi_theta0", xi_theta0, m),
                                  as_vector("xi_delta0", xi_delta0, r)])
        self.x = as_vector("x0", x0, model.n)
        self.input_sizes = {"u": 1}
        self.output_sizes = {"y": 1, "x": model.n, "beta": 1, "theta": model.n}
        if r:
            self.output_sizes["delta"] = model.n
        self._init_sampling(self.input_sizes)

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        beta, theta, delta = self.model.coefficients(self.xi)
        out = {"y": self.x[:1].copy(), "x": self.x.copy(), "beta": np.array([beta]), "theta": theta}
        if "delta" in self.output_sizes:
            out["delta"] = delta
        return out

    def sample_period(self) -> float:
        return self.Ts

    def sample(self, t_k: float, inputs: Mapping[str, np.ndarray]) -> None:
        """``x(k+1) = A x(k) + D(u(k), y(k)) xi(k)``, ``xi(k+1) = Gamma xi(k)`` with ``u(k) = u(t_k)``."""
        u = float(finite_signal("u", inputs["u"])[0])
        x_next = self.A @ self.x + self.model.input_matrix(u, self.x[0]) @ self.xi
        self.x, self.xi = x_next, self.Gamma @ self.xi
