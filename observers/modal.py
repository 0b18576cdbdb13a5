"""Modal synthesis: pole placement for state feedback ``K`` and observer gain ``N``.

Pure functions that return arrays (python-control style).  Conventions of
paper 002:

    u = -K x_hat (+ r),               eig(A - B K) = desired loop poles,
    x_hat' = A x_hat + B u + N (y - C x_hat),   eig(H) = eig(A - N C) = observer poles.

Repeated poles are the normal case here (the binomial form has an n-fold
pole), and ``scipy.signal.place_poles`` refuses a multiplicity above
``rank(B)``.  Single-input problems therefore use Ackermann's formula

    K = [0 ... 0 1] W_c^{-1} D(A),    W_c = [B, A B, ..., A^{n-1} B],

which is exact for any multiplicity; multi-input problems use
``place_poles`` when it can, and otherwise reduce to a single input
``B v`` (cyclic design).  The result is always checked by comparing the
characteristic polynomial of the closed loop with the desired one (the
eigenvalues of a matrix with repeated eigenvalues are too ill-conditioned
to compare).
"""

from __future__ import annotations

import numpy as np

from .checks import ParameterError, as_matrix, as_vector, require_square
from .standard_forms import standard_poles

__all__ = [
    "controllability_matrix",
    "observability_matrix",
    "ackermann",
    "place",
    "observer_gain",
    "desired_poles",
    "design_state_feedback",
    "design_observer",
]


def controllability_matrix(A, B) -> np.ndarray:
    """``[B, A B, ..., A^{n-1} B]``."""
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    blocks = [B]
    for _ in range(A.shape[0] - 1):
        blocks.append(A @ blocks[-1])
    return np.hstack(blocks)


def observability_matrix(A, C) -> np.ndarray:
    """``[C; C A; ...; C A^{n-1}]``."""
    return controllability_matrix(np.asarray(A, float).T, np.asarray(C, float).T).T


def _check_poles(poles, n: int, name: str) -> np.ndarray:
    poles = np.atleast_1d(np.asarray(poles, dtype=complex))
    if poles.ndim != 1 or poles.size != n:
        raise ParameterError(f"{name}: expected {n} poles (the system order), got {poles.size}")
    if not np.all(np.isfinite(poles)):
        raise ParameterError(f"{name}: poles must be finite, got {poles.tolist()}")
    if not np.allclose(np.sort_complex(poles), np.sort_complex(poles.conj()), rtol=1e-12, atol=0):
        raise ParameterError(f"{name}: complex poles must come in conjugate pairs, got {poles.tolist()}")
    return poles


def _characteristic(poles: np.ndarray) -> np.ndarray:
    return np.real(np.poly(poles))


def _verify(closed_loop: np.ndarray, poles: np.ndarray, name: str) -> None:
    want = _characteristic(poles)
    got = np.poly(closed_loop)
    scale = np.maximum(np.abs(want), 1.0)
    if np.max(np.abs(got - want) / scale) > 1e-6:
        raise ParameterError(
            f"{name}: placement is numerically unreliable (closed-loop characteristic polynomial "
            f"{np.round(got, 6).tolist()} instead of {np.round(want, 6).tolist()}); "
            "rescale the model or choose other poles"
        )


def ackermann(A, b, poles) -> np.ndarray:
    """Single-input pole placement by Ackermann's formula.

    Returns the row ``k`` (shape ``(1, n)``) with ``eig(A - b k) = poles``;
    any pole multiplicity is allowed.
    """
    A = require_square("A", A)
    n = A.shape[0]
    b = as_matrix("B", b, shape=(n, 1))
    poles = _check_poles(poles, n, "poles")
    Wc = controllability_matrix(A, b)
    if np.linalg.matrix_rank(Wc) < n:
        raise ParameterError("(A, B): not controllable, the poles cannot be placed")
    desired = _characteristic(poles)
    D_of_A = sum(c * np.linalg.matrix_power(A, n - i) for i, c in enumerate(desired))
    last_row = np.zeros(n)
    last_row[-1] = 1.0
    return np.linalg.solve(Wc.T, last_row)[None, :] @ D_of_A


def _max_multiplicity(poles: np.ndarray) -> int:
    return max(int(np.sum(np.isclose(poles, p, rtol=1e-9, atol=1e-12))) for p in poles)


def _cyclic_direction(A: np.ndarray, B: np.ndarray) -> np.ndarray | None:
    """A column combination ``v`` for which ``(A, B v)`` is controllable, if one exists."""
    n, m = B.shape
    candidates = [np.ones(m)] + [np.eye(m)[i] for i in range(m)]
    candidates += [np.random.default_rng(seed).standard_normal(m) for seed in range(5)]
    for v in candidates:
        if np.linalg.matrix_rank(controllability_matrix(A, B @ v[:, None])) == n:
            return v
    return None


def place(A, B, poles) -> np.ndarray:
    """State-feedback gain ``K`` (``m x n``) with ``eig(A - B K) = poles``.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    poles : (n,) array_like
        Desired closed-loop poles; complex ones in conjugate pairs; repeated poles allowed.

    Raises
    ------
    ParameterError
        Wrong dimensions, non-finite entries, ``(A, B)`` not controllable, or an
        unreliable placement.
    """
    A = require_square("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, shape=(n, None))
    poles = _check_poles(poles, n, "poles")
    if np.linalg.matrix_rank(controllability_matrix(A, B)) < n:
        raise ParameterError("(A, B): not controllable, the poles cannot be placed")
    if B.shape[1] == 1:
        K = ackermann(A, B, poles)
    elif _max_multiplicity(poles) <= np.linalg.matrix_rank(B):
        from scipy.signal import place_poles   # here: scipy.signal costs ~0.5 s to import
        K = place_poles(A, B, poles, method="YT").gain_matrix
    else:
        v = _cyclic_direction(A, B)
        if v is None:
            raise ParameterError(
                "poles: a pole multiplicity exceeds rank(B) and no single input direction "
                "controls (A, B); choose distinct poles"
            )
        K = v[:, None] @ ackermann(A, B @ v[:, None], poles)
    _verify(A - B @ K, poles, "poles")
    return K


def observer_gain(A, C, poles) -> np.ndarray:
    """Observer gain ``N`` (``n x p``) with ``eig(A - N C) = poles`` (by duality)."""
    A = require_square("A", A)
    n = A.shape[0]
    C = as_matrix("C", C, shape=(None, n))
    if np.linalg.matrix_rank(observability_matrix(A, C)) < n:
        raise ParameterError("(A, C): not observable, an observer gain cannot be designed")
    return place(A.T, C.T, poles).T


def desired_poles(n: int, *, poles=None, t_settle=None, form: str = "binomial", name: str = "poles"):
    """Resolve a design request: explicit ``poles`` or a ``t_settle`` with a standard ``form``."""
    if (poles is None) == (t_settle is None):
        raise ParameterError(f"{name}: give exactly one of 'poles' or 't_settle'")
    if poles is not None:
        values = np.asarray(poles)
        if np.iscomplexobj(values):
            return _check_poles(values, n, name)
        return _check_poles(as_vector(name, values), n, name)
    return standard_poles(n, t_settle, form)


def design_state_feedback(A, B, *, poles=None, t_settle=None, form: str = "binomial") -> np.ndarray:
    """Modal controller ``K`` for ``u = -K x``: explicit poles or a standard form.

    >>> design_state_feedback([[0, 1], [-2, 3]], [[0], [1]], t_settle=0.3)   # paper 002
    array([[398.,  43.]])
    """
    A = require_square("A", A)
    return place(A, B, desired_poles(A.shape[0], poles=poles, t_settle=t_settle, form=form))


def design_observer(A, C, *, poles=None, t_settle=None, form: str = "binomial") -> np.ndarray:
    """Observer gain ``N`` for ``x_hat' = A x_hat + B u + N (y - C x_hat)``.

    >>> design_observer([[0, 1], [-2, 3]], [[1, 0]], t_settle=0.15)        # paper 002
    array([[  83.],
           [1847.]])
    """
    A = require_square("A", A)
    return observer_gain(A, C, desired_poles(A.shape[0], poles=poles, t_settle=t_settle, form=form))
