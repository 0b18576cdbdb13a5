r"""The plant class of paper 000: a discrete shift system driven by linear generators.

Plant (1)-(2), written componentwise as (7):

.. math::
    x(k+1) = A x(k) + e_n \beta(k) u(k) + \theta(k) \circ f(y(k)) + \delta(k), \qquad y(k) = x_1(k),

``A`` the shift matrix (ones on the superdiagonal), ``f = (f_1, ..., f_n)`` a
known function of the measured ``y = x_1``.  The unknown time-varying
coefficients are outputs of linear generators

.. math::
    \beta = h_\beta \xi_\beta,\; \theta = H_\theta \xi_\theta,\; \delta = H_\delta \xi_\delta,
    \qquad \xi_\bullet(k+1) = \Gamma_\bullet \xi_\bullet(k),
    \qquad \Gamma_\bullet = \Gamma_0 + \gamma_\bullet e_1^T .

Interpretation of ``Gamma = Gamma0 + gamma^T h``.  The paper multiplies the
unknown vector ``gamma`` by "the" row ``h`` of the generator; for ``beta``
that is ``h_beta``, for the matrix ``h_theta`` of the example the product
is only defined with its first row.  In the example both rows are
``e_1^T``, so we take ``Gamma = Gamma0 + gamma e_1^T`` for every generator:
the observer companion form, whose characteristic polynomial is
``z^d - gamma_1 z^(d-1) - ... - gamma_d``.  The example's
``Gamma = [[0, 1], [gamma_beta, 0]]`` is ``gamma = [0, gamma_beta]``.

Stacking ``xi = [xi_beta; xi_theta; xi_delta]`` (``N = l + m + r``
entries), the plant is ``x(k+1) = A x(k) + D(u(k), y(k)) xi(k)`` with the
known ``n x N`` matrix

.. math:: D(u, y) = \bigl[\, e_n h_\beta u \;\big|\; \operatorname{diag}(f(y)) H_\theta \;\big|\; H_\delta \,\bigr],

which is what the GPEBO filters of Statement 1 integrate
(:mod:`observers.gpebo.filters`).  :class:`GeneratorModel` holds this known
structure; the plant (:mod:`plants.gpebo`) and the observer share it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from obsfmu.observers.checks import ParameterError, SignalError, as_matrix, as_vector

__all__ = ["shift_matrix", "generator_matrix", "GeneratorModel", "require_sample_step"]


def shift_matrix(n: int) -> np.ndarray:
    """The ``n x n`` shift matrix ``A = [[0, I_(n-1)], [0, 0]]`` of eq. (1)."""
    return np.eye(n, k=1)


def generator_matrix(gamma) -> np.ndarray:
    """``Gamma = Gamma0 + gamma e_1^T`` (observer companion form) for a generator of size ``len(gamma)``."""
    gamma = np.asarray(gamma, dtype=float)
    Gamma = np.eye(gamma.size, k=1)
    Gamma[:, 0] += gamma
    return Gamma


def require_sample_step(h: float, Ts: float) -> None:
    """Refuse a communication step other than one sample period ``Ts`` (relative tolerance 1e-9)."""
    if not abs(h - Ts) <= 1e-9 * Ts:
        raise ParameterError(f"Ts: this discrete block advances exactly one sample per communication step, "
                             f"so the step must equal Ts = {Ts:.17g} s; got h = {h:.17g} s")


@dataclass(frozen=True)
class GeneratorModel:
    """Known structure of the plant (1)-(2): sizes, output maps of the generators, nonlinearity.

    Build it with :meth:`checked`.

    Attributes
    ----------
    n : int
        State dimension.
    h_beta : ndarray, shape (l,)
        ``beta = h_beta xi_beta``.
    H_theta : ndarray, shape (n, m)
        ``theta = H_theta xi_theta``.
    H_delta : ndarray, shape (n, r)
        ``delta = H_delta xi_delta`` (``r = 0``: no disturbance).
    f : callable
        ``f(y)`` -> ``n`` values ``f_i(y)`` (a scalar is used for every ``i``).
    """

    n: int
    h_beta: np.ndarray
    H_theta: np.ndarray
    H_delta: np.ndarray
    f: Callable

    @classmethod
    def checked(cls, n: int, h_beta, H_theta, H_delta=None, f: Callable = np.sin) -> "GeneratorModel":
        if isinstance(n, bool) or int(n) != n or n < 1:
            raise ParameterError(f"n: expected a positive integer state dimension, got {n!r}")
        n = int(n)
        h_beta = as_vector("h_beta", h_beta)
        H_theta = as_matrix("H_theta", H_theta, (n, None))
        H_delta = np.zeros((n, 0)) if H_delta is None or np.size(H_delta) == 0 else as_matrix(
            "H_delta", H_delta, (n, None))
        if not callable(f):
            raise ParameterError(f"f: expected a function of y, got {f!r}")
        return cls(n, h_beta, H_theta, H_delta, f)

    @property
    def sizes(self) -> tuple[int, int, int]:
        """``(l, m, r)``: sizes of ``xi_beta``, ``xi_theta``, ``xi_delta``."""
        return self.h_beta.size, self.H_theta.shape[1], self.H_delta.shape[1]

    @property
    def N(self) -> int:
        """Number of generator states ``l + m + r`` (the size of ``eta`` in (6))."""
        return sum(self.sizes)

    def nonlinearity(self, y: float) -> np.ndarray:
        """``f(y)`` as ``n`` finite values; :class:`SignalError` otherwise."""
        value = np.asarray(self.f(y), dtype=float)
        if value.ndim == 0:
            value = np.full(self.n, float(value))
        if value.shape != (self.n,):
            raise ParameterError(f"f: must return a scalar or {self.n} values, returned shape {value.shape}")
        if not np.all(np.isfinite(value)):
            raise SignalError(f"f: f(y = {y!r}) = {value.tolist()} is not finite; state unchanged")
        return value

    def input_matrix(self, u: float, y: float) -> np.ndarray:
        r"""``D(u, y) = [e_n h_beta u | diag(f(y)) H_theta | H_delta]``, so ``x(k+1) = A x + D xi``."""
        l, m, r = self.sizes
        D = np.zeros((self.n, l + m + r))
        D[-1, :l] = self.h_beta * u
        D[:, l:l + m] = self.nonlinearity(y)[:, None] * self.H_theta
        D[:, l + m:] = self.H_delta
        return D

    def transition(self, gamma_beta, gamma_theta, gamma_delta=()) -> np.ndarray:
        """Block-diagonal ``Gamma = diag(Gamma_beta, Gamma_theta, Gamma_delta)`` of the stacked generator."""
        l, m, r = self.sizes
        blocks = [generator_matrix(as_vector(name, gamma, size))
                  for name, gamma, size in (("gamma_beta", gamma_beta, l), ("gamma_theta", gamma_theta, m),
                                            ("gamma_delta", gamma_delta, r)) if size]
        size = sum(block.shape[0] for block in blocks)
        gamma = np.zeros((size, size))   # numpy, not scipy.linalg.block_diag: importing scipy costs ~0.15 s
        start = 0
        for block in blocks:
            end = start + block.shape[0]
            gamma[start:end, start:end] = block
            start = end
        return gamma

    def coefficients(self, xi) -> tuple[float, np.ndarray, np.ndarray]:
        """``(beta, theta, delta)`` from the stacked generator state ``xi``."""
        l, m, _ = self.sizes
        return (float(self.h_beta @ xi[:l]), self.H_theta @ xi[l:l + m], self.H_delta @ xi[l + m:])
