r"""Design of the unknown-input output observer of paper 003, eqs. (2)-(8).

Plant (1): ``x' = A x + B [u + f]``, ``y = C x`` (single input, single
output) with relative degree ``r``: ``C A^k B = 0`` for ``k < r - 1``.  The
observer (2)

.. math:: \dot{\hat x} = M \hat x + L C \tilde x + G y^{(r)}

needs ``G``, ``M`` with

.. math:: B - G C A^{r-1} B = 0 \quad (3), \qquad M = A - G C A^r \quad (4),

solvable iff ``rank(C A^{r-1} B) = rank B`` (then
``G = B [(C A^{r-1} B)^T C A^{r-1} B]^{-1} (C A^{r-1} B)^T``), and ``L``
with ``F = M - L C`` Hurwitz; then ``x_tilde' = F x_tilde`` (6) whatever the
unknown input ``u + f``.

Derivative-free form (7)-(8): the chain ``z_1, ..., z_r`` ends with

.. math:: \dot z_r = F z_r + (F^r G + L)\, y, \qquad
          \hat x = z_r + \sum_{i=0}^{r-1} G_i\, y^{(i)}, \quad G_i = F^{r-1-i} G,

(``z_{k+1} = z_k - F^k G y^{(r-1-k)}``, so ``z_r' = F (z_r + F^{r-1} G y) + L y``).
Because ``C A^k B = 0`` for ``k < r - 1``, ``C G_i = 0`` for ``i >= 1`` and
``C G_0 = C F^{r-1} G = 1``: the output equation of (9) contains no derivative
of ``y`` at all, which is why stage 1 is derivative-free.

Invariant zeros.  A single-input single-output plant of relative degree ``r`` has
``n - r`` invariant zeros; they are eigenvalues of ``M`` that no ``L`` moves and
that ``C`` does not see (the minimum-phase condition of unknown-input
observers: they must be stable).  The component of ``x_tilde(0)`` along
these modes cannot be found from (10) -- ``C e^{F t}`` annihilates it -- and
simply decays at the zeros' rates; stage 1 estimates the projection on the
observable subspace (basis ``V``).  For the paper's example ``r = n``: no
zeros, stage 1 is exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from obsfmu.observers.checks import ParameterError, as_vector, require_hurwitz, require_square
from obsfmu.observers.modal import observability_matrix, observer_gain

__all__ = ["UIODesign", "relative_degree", "check_relative_degree", "uio_matrices", "uio_gain"]

_RELATIVE_TOL = 1e-10


def _markov(A, B, C, k) -> float:
    """``C A^k B`` (a scalar for a single-input single-output plant)."""
    return float(C @ np.linalg.matrix_power(A, k) @ B)


def _scale(A, B, C, k) -> float:
    return float(np.linalg.norm(C) * np.linalg.norm(A, 2) ** k * np.linalg.norm(B)) or 1.0


def relative_degree(A, B, C) -> int:
    """Smallest ``r`` with ``C A^(r-1) B != 0`` (relative to the size of the matrices)."""
    A, B, C = _siso(A, B, C)
    for k in range(A.shape[0]):
        if abs(_markov(A, B, C, k)) > _RELATIVE_TOL * _scale(A, B, C, k):
            return k + 1
    raise ParameterError("B: C A^k B = 0 for every k < n, the output does not see the input "
                         "(relative degree undefined)")


def check_relative_degree(A, B, C, r) -> int:
    """Check that the plant has relative degree ``r`` and that (3) is solvable.

    Raises :class:`~observers.checks.ParameterError` naming ``r`` when
    ``C A^k B != 0`` for some ``k < r - 1`` or when
    ``rank(C A^(r-1) B) != rank B``.
    """
    A, B, C = _siso(A, B, C)
    n = A.shape[0]
    if float(r) != int(r) or not 1 <= int(r) <= n:
        raise ParameterError(f"r: the relative degree must be an integer in 1..{n}, got {r!r}")
    r = int(r)
    for k in range(r - 1):
        value = _markov(A, B, C, k)
        if abs(value) > _RELATIVE_TOL * _scale(A, B, C, k):
            raise ParameterError(f"r: C A^{k} B = {value:.6g} is not 0, so the relative degree is "
                                 f"{k + 1}, not {r}")
    value = _markov(A, B, C, r - 1)
    rank_cab = int(abs(value) > _RELATIVE_TOL * _scale(A, B, C, r - 1))
    rank_b = int(np.linalg.matrix_rank(B[:, None]))
    if rank_cab != rank_b:
        raise ParameterError(f"r: rank(C A^{r - 1} B) = {rank_cab} != rank B = {rank_b} "
                             f"(C A^{r - 1} B = {value:.3g}): (3) has no solution; the relative "
                             f"degree is larger than {r}")
    return r


def uio_matrices(A, B, C, r) -> tuple[np.ndarray, np.ndarray]:
    """``G`` and ``M`` of (3)-(4) for relative degree ``r`` (checked)."""
    A, B, C = _siso(A, B, C)
    r = check_relative_degree(A, B, C, r)
    cab = np.atleast_2d(_markov(A, B, C, r - 1))
    G = B[:, None] @ np.linalg.inv(cab.T @ cab) @ cab.T                  # (3)
    G = G.ravel()
    M = A - np.outer(G, C @ np.linalg.matrix_power(A, r))                # (4)
    return G, M


def uio_gain(A, B, C, r, poles) -> np.ndarray:
    """``L`` with ``eig(F) = eig(M - L C) = poles`` (``place(M^T, C^T, poles)^T``).

    For ``r < n`` the plant's ``n - r`` invariant zeros are unobservable
    eigenvalues of ``(M, C)`` (fixed eigenvalues of ``F`` for every ``L``, the
    usual minimum-phase condition of unknown-input observers).  Then give only
    the ``k`` poles of the observable part: ``L`` places them and leaves the
    zeros, which must be stable.
    """
    _, M = uio_matrices(A, B, C, r)
    A, B, C = _siso(A, B, C)
    n = A.shape[0]
    poles = np.atleast_1d(np.asarray(poles))
    V = observable_basis(M, C)
    k = V.shape[1]
    if k == n:
        return _place("L", M, C, poles)
    T = np.linalg.svd(observability_matrix(M, C[None, :]))[2]     # rows: observable directions first
    fixed = np.linalg.eigvals((T @ M @ T.T)[k:, k:])
    if np.any(fixed.real >= 0):
        raise ParameterError(f"poles: the plant is not minimum phase: its invariant zeros "
                             f"{np.round(fixed, 6).tolist()} (eigenvalues of F = M - L C that no L moves) are not "
                             "all in the open left half-plane; an unknown-input observer needs a minimum-phase plant "
                             "(A, B, C), no choice of poles or L can help")
    if poles.size != k:
        raise ParameterError(f"poles: (M, C) has {n - k} unobservable eigenvalues {np.round(fixed, 6).tolist()} "
                             f"(the plant's zeros, kept in F); give the {k} poles of the observable part")
    M_o, C_o = (T @ M @ T.T)[:k, :k], (C @ T.T)[:k]
    return T[:k].T @ _place("L", M_o, C_o, poles)


def _place(name, M, C, poles) -> np.ndarray:
    try:
        return observer_gain(M, C[None, :], poles).ravel()
    except ParameterError as exc:
        raise ParameterError(f"{name}: cannot place eig(M - L C) ({exc})") from None


def _siso(A, B, C):
    A = require_square("A", A)
    n = A.shape[0]
    B = as_vector("B", B, n)
    C = as_vector("C", C, n)
    return A, B, C


@dataclass(frozen=True)
class UIODesign:
    r"""The checked matrices of (2)-(8) for a single-input single-output plant.

    Use :meth:`create`; the fields are derived data.

    Attributes
    ----------
    A, B, C : the plant (B, C as 1-D arrays)
    r : int, relative degree
    G, M, L, F : eqs. (3), (4), ``F = M - L C`` (Hurwitz)
    G_i : list of ``F^(r-1-i) G``, the coefficients of ``y^(i)`` in (8)
    L_tilde : ``F^r G + L``, the input vector of ``z_r' = F z_r + L_tilde y``
    c0 : ``C G_0 = C F^(r-1) G`` (= 1, see the module docstring)
    V : (n, k) orthonormal basis of the observable subspace of ``(F, C)``; ``k = n`` unless the
        plant has invariant zeros (``r < n``): they stay unobservable eigenvalues of ``F``
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    r: int
    G: np.ndarray
    M: np.ndarray
    L: np.ndarray
    F: np.ndarray
    G_i: tuple
    L_tilde: np.ndarray
    c0: float
    V: np.ndarray

    @property
    def n(self) -> int:
        return self.A.shape[0]

    @classmethod
    def create(cls, A, B, C, r, L) -> "UIODesign":
        A, B, C = _siso(A, B, C)
        G, M = uio_matrices(A, B, C, r)
        r = int(r)
        L = as_vector("L", L, A.shape[0])
        F = require_hurwitz("L", M - np.outer(L, C))
        G_i = tuple(np.linalg.matrix_power(F, r - 1 - i) @ G for i in range(r))
        L_tilde = np.linalg.matrix_power(F, r) @ G + L
        return cls(A, B, C, r, G, M, L, F, G_i, L_tilde, float(C @ G_i[0]), observable_basis(F, C))


def observable_basis(F, C) -> np.ndarray:
    """Orthonormal basis (columns) of the observable subspace of ``(F, C)`` (row space of ``O``)."""
    O = observability_matrix(F, C[None, :])
    _, singular, Vt = np.linalg.svd(O)
    k = int(np.sum(singular > 1e-9 * singular[0]))
    return Vt[:k].T if k < F.shape[0] else np.eye(F.shape[0])


