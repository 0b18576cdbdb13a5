r"""The user's model for paper 004: the map to the state-affine form and the algebraic relation.

Paper 004 (Bespalov, Vedyakov 2023) considers plants (1) ``x' = f(x, u, theta_p)``,
``y = h(x, u)`` for which the user knows

* an injective map ``chi = phi(x)`` to the state-affine form (2) (Assumption 1)

  .. math:: \dot\chi = \Lambda(y, u)\,\chi + \Psi(y, u)\,\theta_p + w(y, u),
            \qquad \chi \in \mathbb R^q,\ \theta_p \in \mathbb R^p ;

* an algebraic relation (3) between ``chi`` and measured signals (Assumption 2)

  .. math:: \phi_l(y, u)^\top \theta_l + \phi_\chi(y, u)^\top \chi = c(y, u),
            \qquad \phi = \operatorname{col}(\phi_l, \phi_\chi) \in \mathbb R^{l + q} ;

* a left inverse ``x = phi_L(chi)`` (Statement 3).

:class:`StateAffineModel` holds these as Python callables (inside an FMU they are
``"module:function"`` references, see :mod:`fmus.runtime.callables`) and checks every value they
return against the declared dimensions, so a model that does not match is refused with a
message naming the function.  ``Lambda`` is either

* a callable ``Lambda(y, u)`` -- the time-varying case of Statement 1, or
* a constant matrix -- Statement 2, which also needs ``y = C chi`` (Assumption 5), an
  observable pair ``(Lambda, C)`` (Assumption 6) and the injection gain ``L``; the filters
  then run with ``Lambda_L = Lambda - L C``.

Interpretations (see ``docs/paper004.md``):

* ``phi_L`` receives the estimate ``theta_hat = col(theta_l, theta_p)`` as a second argument,
  because useful maps depend on unknown parameters (the pendulum's ``chi_2 = omega + b phi``
  with unknown friction ``b``).  ``phi_L(chi, theta)`` must be Lipschitz in ``chi``; once
  ``theta_hat`` is exact (finite time) Statement 3's argument is unchanged.
* Statement 2 does not say how to choose ``L``.  Statement 3 needs ``Delta`` not square
  integrable, which the regression of the initial error ``e(0)`` only gives if
  ``exp(Lambda_L t)`` does not decay: choose ``Lambda_L`` with simple eigenvalues on the
  imaginary axis (as paper 001 does with ``A0 = [[0, 1], [-9, 0]]``).  A Hurwitz
  ``Lambda_L`` is accepted too (``Delta`` then decays: finite-time estimation still works
  under interval excitation, the state error then relies on condition (9)).  Eigenvalues
  with a positive real part, or a repeated eigenvalue on the axis with a Jordan block, make
  the filters grow and are refused.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from obsfmu.observers.checks import ParameterError, SignalError, as_matrix, require_square
from obsfmu.observers.modal import observability_matrix

__all__ = ["Terms", "StateAffineModel", "require_bounded_filter"]


@dataclass(frozen=True)
class Terms:
    """The model's functions evaluated at one ``(y, u)``."""

    Lambda: np.ndarray  #: (q, q) of (2) (the plant's, also in the constant case)
    Psi: np.ndarray     #: (q, p)
    w: np.ndarray       #: (q,)
    phi: np.ndarray     #: (l + q,) = col(phi_l, phi_chi) of (3)
    c: float            #: right-hand side of (3)


def _dimension(name: str, value, minimum: int) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ParameterError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return int(value)


def _name(function) -> str:
    module = getattr(function, "__module__", "")
    return f"{module}:{getattr(function, '__qualname__', function)}" if module else repr(function)


def require_bounded_filter(name: str, F: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """Raise unless every solution of ``z' = F z`` is bounded (Assumption 4 for a constant ``F``).

    Eigenvalues must have real part <= 0; those on the imaginary axis must be semisimple
    (no Jordan block, which would grow like ``t``).
    """
    scale = max(1.0, float(np.linalg.norm(F, 2)))
    eigenvalues = np.linalg.eigvals(F)
    worst = eigenvalues[np.argmax(eigenvalues.real)]
    if worst.real > tolerance * scale:
        raise ParameterError(
            f"{name}: eigenvalue {worst:.6g} has a positive real part, the filters z' = {name} z + ... "
            f"would diverge (eigenvalues {np.round(eigenvalues, 6).tolist()})")
    n = F.shape[0]
    for value in eigenvalues[np.abs(eigenvalues.real) <= tolerance * scale]:
        multiplicity = int(np.sum(np.abs(eigenvalues - value) <= 1e-6 * scale))
        if multiplicity > 1:
            singular = np.linalg.svd(F - value * np.eye(n), compute_uv=False)
            if int(np.sum(singular <= 1e-6 * scale)) < multiplicity:
                raise ParameterError(
                    f"{name}: eigenvalue {value:.6g} on the imaginary axis is repeated with a Jordan block, "
                    f"the filters z' = {name} z + ... grow like t; choose distinct eigenvalues")
    return F


class StateAffineModel:
    r"""The map to the state-affine form (2), the relation (3) and the left inverse of a plant.

    Parameters
    ----------
    q, p, l : int
        Dimensions of ``chi`` (>= 1), ``theta_p`` and ``theta_l`` (>= 0).
    n : int
        Dimension of the plant state ``x`` returned by ``phi_L``.
    ny, nu : int
        Dimensions of the measured output ``y`` and of the input ``u``.
    Lambda : callable or array_like
        ``Lambda(y, u) -> (q, q)`` (Statement 1) or a constant ``(q, q)`` matrix (Statement 2).
    Psi : callable or None
        ``Psi(y, u) -> (q, p)``; ``None`` when ``p = 0``.
    w : callable
        ``w(y, u) -> (q,)``.
    phi : callable
        ``phi(y, u) -> (l + q,)``: the coefficients ``col(phi_l, phi_chi)`` of relation (3).
    c : callable
        ``c(y, u) -> float``: the right-hand side of (3).
    phi_L : callable
        ``phi_L(chi, theta) -> (n,)`` with ``theta = col(theta_l, theta_p)``.
    C, L : array_like, optional
        Statement 2 only: ``y = C chi`` (``(ny, q)``) and the gain ``L`` (``(q, ny)``).
    probe : tuple of array_like, optional
        ``(y, u)`` at which every function is evaluated once to check its shape
        (default ``y = 0.5``, ``u = 0.5`` element-wise).

    Raises
    ------
    ParameterError
        A dimension is invalid, a function returns a wrongly shaped or non-finite value at
        the probe point, ``(Lambda, C)`` is not observable, or ``Lambda - L C`` has growing
        solutions.
    """

    def __init__(self, *, q: int, p: int, l: int, n: int, ny: int, nu: int,
                 Lambda, Psi: Callable | None, w: Callable, phi: Callable, c: Callable,
                 phi_L: Callable, C=None, L=None, probe=None):
        self.q = _dimension("q", q, 1)
        self.p = _dimension("p", p, 0)
        self.l = _dimension("l", l, 0)
        self.n = _dimension("n", n, 1)
        self.ny = _dimension("ny", ny, 1)
        self.nu = _dimension("nu", nu, 1)
        for name, function in (("w", w), ("phi", phi), ("c", c), ("phi_L", phi_L)):
            if not callable(function):
                raise ParameterError(f"{name}: expected a function, got {function!r}")
        if self.p > 0 and not callable(Psi):
            raise ParameterError(f"Psi: expected a function Psi(y, u) -> ({self.q}, {self.p}), got {Psi!r}")
        self._Psi, self._w, self._phi, self._c, self._phi_L = Psi, w, phi, c, phi_L
        self.constant = not callable(Lambda)
        if self.constant:
            self._init_constant(Lambda, C, L)
        else:
            if C is not None or L is not None:
                raise ParameterError("C, L: only for a constant Lambda (Statement 2); Lambda is a function here")
            self._Lambda = Lambda
        y0, u0 = probe if probe is not None else (np.full(self.ny, 0.5), np.full(self.nu, 0.5))
        try:
            self.evaluate(np.asarray(y0, float).reshape(self.ny), np.asarray(u0, float).reshape(self.nu))
            self.inverse(np.zeros(self.q), np.zeros(self.l + self.p))
        except SignalError as exc:
            raise ParameterError(f"{exc} (at the probe point y = {y0}, u = {u0})") from None

    def _init_constant(self, Lambda, C, L) -> None:
        q = self.q
        self.Lambda = require_square("Lambda", Lambda)
        if self.Lambda.shape != (q, q):
            raise ParameterError(f"Lambda: expected shape ({q}, {q}) (q x q), got {self.Lambda.shape}")
        if C is None or L is None:
            raise ParameterError("C, L: a constant Lambda (Statement 2) needs y = C chi and the gain L")
        self.C = as_matrix("C", C, shape=(self.ny, q))
        self.L = as_matrix("L", L, shape=(q, self.ny))
        rank = np.linalg.matrix_rank(observability_matrix(self.Lambda, self.C))
        if rank < q:
            raise ParameterError(
                f"C: the pair (Lambda, C) is not observable (rank of the observability matrix {rank} < q = {q}); "
                "Statement 2 (Assumption 6) needs it")
        self.Lambda_L = require_bounded_filter("Lambda - L C", self.Lambda - self.L @ self.C)

    # ------------------------------------------------------------------ evaluation
    @staticmethod
    def _checked(name: str, function, value, shape: tuple[int, ...], what: str) -> np.ndarray:
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ParameterError(f"{name}: {_name(function)} returned {value!r}, expected numbers "
                                 f"of shape {shape} ({what})") from None
        if array.shape != shape:
            if array.size == int(np.prod(shape)) and (len(shape) < 2 or min(shape) == 1):
                array = array.reshape(shape)      # a vector given as a row or a column
            else:
                raise ParameterError(f"{name}: {_name(function)} returned shape {array.shape}, "
                                     f"expected {shape} ({what})")
        if not np.all(np.isfinite(array)):
            raise SignalError(f"{name}: {_name(function)} returned a non-finite value {array.tolist()}")
        return array

    def evaluate(self, y: np.ndarray, u: np.ndarray) -> Terms:
        """``Lambda, Psi, w, phi, c`` at ``(y, u)``; raise on a wrong shape or a non-finite value."""
        q, p, l = self.q, self.p, self.l
        Lambda = self.Lambda if self.constant else self._checked(
            "Lambda", self._Lambda, self._Lambda(y, u), (q, q), "q x q")
        Psi = (self._checked("Psi", self._Psi, self._Psi(y, u), (q, p), "q x p") if p
               else np.zeros((q, 0)))
        w = self._checked("w", self._w, self._w(y, u), (q,), "q entries")
        phi = self._checked("phi", self._phi, self._phi(y, u), (l + q,), "l + q entries: col(phi_l, phi_chi)")
        c = float(self._checked("c", self._c, self._c(y, u), (), "a number"))
        return Terms(Lambda, Psi, w, phi, c)

    def inverse(self, chi: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``x = phi_L(chi, theta)`` (Statement 3)."""
        return self._checked("phi_L", self._phi_L, self._phi_L(chi, theta), (self.n,), "n entries")
