r"""Plant of paper 003, eq. (1): LTV state feedback with unknown parameters and a sinusoidal disturbance.

.. math::
    \dot x = A x + B\,[\theta^T(t)\, x + f(t)], \qquad y = C x + v(t),

    \theta = H \xi, \quad \dot\xi = \Gamma \xi \quad \text{(Assumption 3)}, \qquad
    f(t) = \sum_k a_k \sin(\omega_k t + \varphi_k),

single input (``B`` is ``n x 1``), single output, ``v`` an optional
sample-and-hold measurement noise (:class:`plants.signals.SampledNoise`).
The true ``x``, ``theta``, ``xi`` and ``f`` are outputs, so estimates can be
compared with them.

Integration over a step ``h``: ``xi`` exactly (``expm(Gamma h)``), ``x`` with
classical RK4 on sub-steps short enough that ``h_sub * rho <= 0.01`` (``rho``
bounds the rates of ``A + B theta^T`` and of ``f``): the global error is about
``T rho (h_sub rho)^4 / 120`` relative, below 1e-9 for the paper's example at
``h = 1e-3``.  There are no inputs.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from obsfmu.observers.block import Block, Segment
from obsfmu.observers.checks import ParameterError, as_matrix, as_vector, require_square
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET, expm, require_budget, rk4_step, substep_count

from .signals import SampledNoise

__all__ = ["DisturbedLTVPlant", "sum_of_sines"]

_RATE_STEP = 0.01  # max (sub-step x rate) of the RK4 sub-steps


def sum_of_sines(t: float, amplitude: np.ndarray, omega: np.ndarray, phase: np.ndarray) -> float:
    """``sum_k amplitude_k sin(omega_k t + phase_k)``."""
    return float(np.sum(amplitude * np.sin(omega * t + phase)))


class DisturbedLTVPlant(Block):
    """Paper 003's plant (1) with ``theta = H xi``, ``xi' = Gamma xi`` and ``f`` a sum of sines.

    Parameters
    ----------
    A : (n, n) array_like
    B, C : (n,) array_like
        Input and output vectors (single input, single output).
    H : (n, m) array_like
    Gamma : (m, m) array_like
    xi0 : (m,) array_like
        ``xi(0)`` (unknown to the observer).
    x0 : (n,) array_like
        ``x(0)``.
    amplitude, omega, phase : (N,) array_like
        The sinusoids of ``f``.
    noise : SampledNoise, optional
        Measurement noise added to ``y``.
    substep_budget : int, optional
        Most RK4 sub-steps one communication step may take (a longer step is refused).

    Ports: no inputs; outputs ``y`` (1), ``x`` (n), ``theta`` (n), ``xi`` (m), ``f`` (1) and
    ``f_omega`` (N, the frequencies of ``f``, constant: the reference for estimates).
    """

    not_state = ("A", "B", "C", "H", "Gamma", "amplitude", "omega", "phase", "noise", "substep_budget", "_xi_step",
                 "_rate", "_input_norm")

    def __init__(self, A, B, C, H, Gamma, xi0, x0, amplitude, omega, phase, noise: SampledNoise | None = None,
                 substep_budget: int = DEFAULT_SUBSTEP_BUDGET):
        self.A = require_square("A", A)
        n = self.A.shape[0]
        self.B = as_vector("B", B, n)
        self.C = as_vector("C", C, n)
        self.H = as_matrix("H", H, shape=(n, None))
        m = self.H.shape[1]
        self.Gamma = as_matrix("Gamma", Gamma, shape=(m, m))
        self.xi = as_vector("xi0", xi0, m)
        self.x = as_vector("x0", x0, n)
        self.amplitude = as_vector("amplitude", amplitude)
        self.omega = as_vector("omega", omega, self.amplitude.size)
        self.phase = as_vector("phase", phase, self.amplitude.size)
        if np.any(self.omega < 0):
            raise ParameterError(f"omega: frequencies must be >= 0, got {self.omega.tolist()}")
        self.noise = noise
        self.substep_budget = require_budget(substep_budget)
        self._xi_step: dict[tuple[float, float], np.ndarray] = {}   # a cache, not state
        self._rate = np.linalg.norm(self.A) + np.linalg.norm(self.Gamma) + float(np.max(self.omega, initial=0))
        self._input_norm = np.linalg.norm(self.B) * np.linalg.norm(self.H)
        self.input_sizes = {}
        self.output_sizes = {"y": 1, "x": n, "theta": n, "xi": m, "f": 1, "f_omega": self.omega.size}

    def disturbance(self, t: float) -> float:
        """``f(t)``."""
        return sum_of_sines(t, self.amplitude, self.omega, self.phase)

    def _xi_transition(self, h: float, fraction: float = 1.0) -> np.ndarray:
        """``expm(Gamma fraction h)``, cached per step length and fraction (the RK4 stages of every
        step ask for the same few fractions: one ``expm`` each instead of one per stage)."""
        key = (h, round(fraction, 9))
        if key not in self._xi_step:
            if len(self._xi_step) >= 512:
                self._xi_step.clear()
            self._xi_step[key] = expm(self.Gamma * (key[1] * h))
        return self._xi_step[key]

    def outputs(self, t: float, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        y = self.C @ self.x
        if self.noise is not None:
            y = y + self.noise(t)[0]
        return {"y": np.array([y]), "x": self.x.copy(), "theta": self.H @ self.xi, "xi": self.xi.copy(),
                "f": np.array([self.disturbance(t)]), "f_omega": self.omega.copy()}

    def advance(self, t: float, h: float, inputs: Mapping[str, Segment]) -> None:
        xi0 = self.xi
        Gamma = self.Gamma
        rate = self._rate + self._input_norm * np.linalg.norm(xi0)     # bounds |eig| of the dynamics
        substeps = substep_count(h, rate=rate, max_change=_RATE_STEP, budget=self.substep_budget)

        def rhs(s, x):
            xi = xi0 if not Gamma.any() else self._xi_transition(h, (s - t) / h) @ xi0
            return self.A @ x + self.B * ((self.H @ xi) @ x + self.disturbance(s))

        x = rk4_step(rhs, t, self.x, h, substeps)
        xi = self._xi_transition(h) @ xi0
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(xi))):
            raise FloatingPointError(f"x: the plant state is no longer finite at t = {t + h:g}")
        self.x, self.xi = x, xi
