r"""The known generator of the feedback parameters (paper 003, Assumption 3, eq. (13)).

``theta = H xi``, ``xi' = Gamma xi`` with ``H``, ``Gamma`` known and ``xi(0)`` unknown, so

.. math:: \theta(t) = H e^{\Gamma t} \xi(0), \qquad
          \theta^T x = \bigl(e^{\Gamma^T t} H^T x\bigr)^T \xi(0),

and stage 2 keeps its unknowns ``xi(0)``: only its regressor becomes ``e^{Gamma^T t} H^T x``
(:mod:`~observers.uio.regressions`).  The observer needs ``e^{Gamma t}`` bounded -- every eigenvalue
with ``Re <= 0``, those on the imaginary axis semisimple (a rotation ``[[0, w], [-w, 0]]`` is the
typical case): an unbounded ``theta`` makes the plant's signals grow without bound.

:class:`GeneratorFlow` evaluates ``e^{Gamma t}`` from ``t`` itself (no state, nothing accumulates
over the steps): for a diagonalisable ``Gamma`` with a well-conditioned eigenbasis (a rotation: a
unitary one) ``V e^{Lambda t} V^-1`` (a few microseconds), otherwise the matrix exponential
(:func:`observers.integrators.expm`, ~0.1 ms).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError, as_matrix, unbounded_mode
from obsfmu.observers.integrators import expm

__all__ = ["GeneratorFlow", "check_generator"]

_MAX_CONDITION = 1e6    # eigenbasis conditioning above which e^{Gamma t} is computed by expm


def _text(value: complex) -> str:
    return f"{value.real:.6g}" if abs(value.imag) < 1e-12 else f"{value.real:.6g}{value.imag:+.6g}j"


def check_generator(Gamma, m: int, name: str = "Gamma") -> np.ndarray:
    """``Gamma`` as an ``(m, m)`` matrix whose flow ``e^{Gamma t}`` is bounded for ``t >= 0``.

    Refused (naming ``name``): another shape, an eigenvalue with ``Re > 0``, or one on the imaginary
    axis whose geometric multiplicity is below its algebraic one (a Jordan block: ``t^k`` growth).
    """
    Gamma = as_matrix(name, Gamma, shape=(m, m))
    mode = unbounded_mode(Gamma)
    if mode is not None and mode.growing:
        raise ParameterError(f"{name}: eigenvalue {_text(mode.value)} has Re > 0, e^({name} t) and theta grow "
                             "without bound; the observer needs a bounded generator (Re <= 0, those on the "
                             "imaginary axis semisimple)")
    if mode is not None:
        raise ParameterError(f"{name}: eigenvalue {_text(mode.value)} on the imaginary axis is not semisimple "
                             f"(multiplicity {mode.algebraic}, {mode.geometric} eigenvector(s)): e^({name} t) grows "
                             f"like t^{mode.algebraic - mode.geometric}; the observer needs a bounded generator")
    return Gamma


class GeneratorFlow:
    """``t -> e^{Gamma t}`` for a fixed ``Gamma`` (checked by :func:`check_generator` beforehand)."""

    def __init__(self, Gamma: np.ndarray):
        self.Gamma = np.asarray(Gamma, dtype=float)
        values, vectors = np.linalg.eig(self.Gamma)
        self._spectral = np.linalg.cond(vectors) <= _MAX_CONDITION
        if self._spectral:
            self._values, self._vectors, self._inverse = values, vectors, np.linalg.inv(vectors)
            self._real = not np.iscomplexobj(values)

    def __call__(self, t: float) -> np.ndarray:
        if not self._spectral:
            return expm(self.Gamma * t)
        flow = (self._vectors * np.exp(self._values * t)) @ self._inverse
        return flow if self._real else flow.real

    @property
    def slowest_decay(self) -> float:
        """``min Re eig(Gamma)`` (<= 0): the modulated filters ``lambda + Gamma^T`` decay at ``lambda`` plus it."""
        return float(np.min(np.linalg.eigvals(self.Gamma).real))
