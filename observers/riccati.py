"""Riccati equations of LQR and the steady-state Kalman gain, by Newton's method in numpy alone.

An FMU that carries its noise covariances (or LQR weights) as parameters designs its gain at initialisation,
with numpy only (no scipy in an FMU).  From a stabilising gain -- the one the build designed with SciPy's
Schur-method solvers, for the same model -- Newton's iteration converges quadratically to the stabilising
solution:

* continuous (Kleinman 1968): ``A_k = A - B K_k``; ``A_k' P + P A_k + Q + K_k' R K_k = 0``;
  ``K_{k+1} = R^-1 B' P``, for ``A' P + P A - P B R^-1 B' P + Q = 0``;
* discrete (Hewer 1971): ``A_k = A - B K_k``; ``P = A_k' P A_k + Q + K_k' R K_k``;
  ``K_{k+1} = (R + B' P B)^-1 B' P A``, for ``P = A' P A - A' P B (R + B' P B)^-1 B' P A + Q``.

Each Lyapunov equation is solved as one linear system in the ``n^2`` entries of ``P`` (Kronecker form: the
plants here are small).  The observer gains are the duals, ``N = K(A', C', Q, R)'``: continuous ``N = P C' R^-1``, and the
discrete predictor's ``N = A P C' (C P C' + R)^-1``.
"""

from __future__ import annotations

import numpy as np

from .checks import ParameterError

__all__ = ["checked_weight", "lqr_newton", "dlqr_newton", "kalman_newton", "dkalman_newton"]

#: Newton stops when the gain changes by less than this (relative), or fails after MAX_ITERATIONS
TOLERANCE, MAX_ITERATIONS = 1e-13, 60


def checked_weight(name: str, value, size: int, definite: bool, what: str = "covariance") -> np.ndarray:
    """A ``size x size`` symmetric positive (semi)definite matrix, or a :class:`ParameterError` naming ``name``."""
    value, article = np.asarray(value, dtype=float), "an" if what[0] in "aeiou" else "a"
    if value.shape != (size, size):
        shape = " x ".join(str(s) for s in value.shape) or "a scalar"
        raise ParameterError(f"{name}: expected a {size} x {size} matrix, got {shape}")
    if not np.all(np.isfinite(value)):
        raise ParameterError(f"{name}: {article} {what} must be finite")
    if not np.allclose(value, value.T, rtol=1e-12, atol=0.0):
        raise ParameterError(f"{name}: {article} {what} must be symmetric")
    smallest = np.linalg.eigvalsh(value).min()
    if smallest <= 0 if definite else smallest < -1e-12 * max(1.0, np.abs(value).max()):
        raise ParameterError(f"{name}: {article} {what} must be positive {'definite' if definite else 'semidefinite'} "
                             f"(smallest eigenvalue {smallest:.3g})")
    return value


def _lyapunov(M: np.ndarray, S: np.ndarray, discrete: bool) -> np.ndarray:
    """``P`` with ``M' P + P M + S = 0`` (continuous) or ``P = M' P M + S`` (discrete), symmetrised."""
    n = len(M)
    identity = np.eye(n)
    if discrete:
        system = np.eye(n * n) - np.kron(M.T, M.T)
    else:
        system = np.kron(identity, M.T) + np.kron(M.T, identity)
    P = np.linalg.solve(system, (S if discrete else -S).reshape(-1)).reshape(n, n)
    return 0.5 * (P + P.T)


def _newton(A, B, Q, R, K0, name: str, discrete: bool) -> np.ndarray:
    A, B, K = (np.asarray(M, dtype=float) for M in (A, B, K0))
    for _ in range(MAX_ITERATIONS):
        closed = A - B @ K
        eigenvalues = np.linalg.eigvals(closed)
        if (np.max(np.abs(eigenvalues)) >= 1.0) if discrete else (np.max(eigenvalues.real) >= 0.0):
            raise ParameterError(f"{name}: the Riccati iteration lost stability (no stabilising solution for these "
                                 "weights, or a model the build's gain does not stabilise)")
        P = _lyapunov(closed, Q + K.T @ R @ K, discrete)
        updated = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A) if discrete else np.linalg.solve(R, B.T @ P)
        if np.max(np.abs(updated - K)) <= TOLERANCE * max(1.0, np.max(np.abs(updated))):
            return updated
        K = updated
    raise ParameterError(f"{name}: the Riccati iteration did not converge in {MAX_ITERATIONS} steps")


def lqr_newton(A, B, Q, R, K0, name: str = "Q, R") -> np.ndarray:
    """The LQR gain ``K = R^-1 B' P`` (minimises ``int x' Q x + u' R u``), from a stabilising ``K0``."""
    return _newton(A, B, Q, R, K0, name, discrete=False)


def dlqr_newton(A, B, Q, R, K0, name: str = "Q, R") -> np.ndarray:
    """The discrete LQR gain ``K = (R + B' P B)^-1 B' P A``, from a gain ``K0`` with ``A - B K0`` Schur-stable."""
    return _newton(A, B, Q, R, K0, name, discrete=True)


def kalman_newton(A, C, Q, R, N0, name: str = "Q, R") -> np.ndarray:
    """The steady-state Kalman gain ``N = P C' R^-1`` (process noise on every state), from a stabilising ``N0``."""
    return lqr_newton(np.asarray(A).T, np.asarray(C).T, Q, R, np.asarray(N0).T, name).T


def dkalman_newton(A, C, Q, R, N0, name: str = "Q, R") -> np.ndarray:
    """The discrete predictor's steady-state Kalman gain ``N = A P C' (C P C' + R)^-1``, from ``N0`` with
    ``A - N0 C`` Schur-stable: the dual of the discrete LQR, ``N = dlqr(A', C', Q, R)'``."""
    return dlqr_newton(np.asarray(A).T, np.asarray(C).T, Q, R, np.asarray(N0).T, name).T
