"""Modal synthesis: pole placement for state feedback ``K`` and observer gain ``N``.

Pure functions that return arrays (python-control style).  Conventions of
paper 002:

    u = -K x_hat (+ r),               eig(A - B K) = desired loop poles,
    x_hat' = A x_hat + B u + N (y - C x_hat),   eig(H) = eig(A - N C) = observer poles.

Single input.  Repeated poles are the normal case here (the binomial form
has an n-fold pole), and ``scipy.signal.place_poles`` refuses a multiplicity
above ``rank(B)``.  Two methods, tried in this order:

* Ackermann's formula ``K = [0 ... 0 1] W_c^{-1} D(A)``,
  ``W_c = [B, A B, ..., A^{n-1} B]``: exact for any multiplicity, tried while
  ``W_c`` is well conditioned (``cond(W_c) <= 1e8``: small plants such as
  paper 002's, whose gains it reproduces to the last digit);
* the eigenvector (Sylvester) method: the closed-loop eigenvectors solve
  ``(A - p_i I) x_i = b`` (generalised eigenvectors ``(A - p I) x_{j+1} = x_j``
  for a repeated pole), and ``K X = g`` with ``g`` one at the head of every
  chain (Bhattacharyya & de Souza 1982: ``A X - X Lambda = b g``).  Its
  accuracy is set by ``cond(X)``, the sensitivity of the requested closed
  loop itself, not by ``cond(W_c)``, which grows like a Vandermonde matrix
  with the order (1e30 for a 50-state modal plant).

The gain of the method whose closed loop is closer to the request is kept.

Multi-input problems use Tits and Yang's robust placement when it can (numpy
alone for real poles, :mod:`observers.robust_placement`; SciPy's ``place_poles``
for complex ones), and otherwise reduce to a single input ``B v`` (cyclic design).

Check after design.  Whatever the method, the gain is accepted only if the
eigenvalues of ``A - B K`` as computed in double precision match the
requested poles one to one within :data:`POLE_ACCURACY` (relative).  A pole
of multiplicity ``k`` is perturbed like ``(eps cond)^(1/k)``: the binomial
form of order 20 (a 20-fold pole) cannot be placed in double precision --
its computed eigenvalues scatter over tens of percent and the observer
diverges -- and is refused with that reason instead of being built.
"""

from __future__ import annotations

import numpy as np

from .checks import ParameterError, as_matrix, as_vector, require_positive, require_square
from .lti_model import StateSpace
from .robust_placement import robust_place
from .standard_forms import standard_poles

__all__ = [
    "shifted_poles",
    "controllability_matrix",
    "observability_matrix",
    "controllable_dimension",
    "is_controllable",
    "is_observable",
    "ackermann",
    "eigenvector_placement",
    "pole_deviation",
    "POLE_ACCURACY",
    "transient_growth",
    "MAX_TRANSIENT_GROWTH",
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


def controllable_dimension(A, B, tolerance: float = 1e-10) -> int:
    """Dimension of the controllable subspace of ``(A, B)`` by the orthogonal staircase.

    Block Arnoldi on ``B, A B, ...`` with re-orthogonalisation; a direction is new when its
    singular value exceeds ``tolerance * max(|A|, |B|)``.  Unlike the rank of
    ``[B, A B, ..., A^{n-1} B]`` -- whose condition grows like a Vandermonde matrix's, 1e30 for a
    50-state modal plant -- this decides correctly at any order (Van Dooren 1981).
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)
    n = A.shape[0]
    threshold = tolerance * max(np.linalg.norm(A, 2), np.linalg.norm(B, 2), 1e-300)
    basis = np.zeros((n, 0))
    block = B
    while basis.shape[1] < n:
        for _ in range(2):                                  # twice is enough (Kahan, Parlett)
            block = block - basis @ (basis.T @ block)
        U, singular, _ = np.linalg.svd(block, full_matrices=False)
        rank = int(np.sum(singular > threshold))
        if rank == 0:
            break
        basis = np.hstack([basis, U[:, :rank]])
        block = A @ U[:, :rank]
    return basis.shape[1]


def is_controllable(A, B) -> bool:
    return controllable_dimension(A, B) == np.asarray(A).shape[0]


def is_observable(A, C) -> bool:
    return controllable_dimension(np.asarray(A, float).T, np.asarray(C, float).T) == np.asarray(A).shape[0]


def _check_poles(poles, n: int, name: str) -> np.ndarray:
    poles = np.atleast_1d(np.asarray(poles, dtype=complex))
    if poles.ndim != 1 or poles.size != n:
        raise ParameterError(f"{name}: expected {n} poles (the system order), got {poles.size}")
    if not np.all(np.isfinite(poles)):
        raise ParameterError(f"{name}: poles must be finite, got {poles.tolist()}")
    if not np.allclose(np.sort_complex(poles), np.sort_complex(poles.conj()), rtol=1e-12, atol=0):
        raise ParameterError(f"{name}: complex poles must come in conjugate pairs, got {poles.tolist()}")
    return poles


#: largest relative distance |eig - p| / |p| between a requested pole and its eigenvalue of the closed
#: loop: 1 %.  Simple poles of a sound design meet it by orders of magnitude; a k-fold pole spreads
#: like (eps cond)^(1/k) (1e-8 for paper 002's double poles, 4 % for a 10-fold binomial pole).
POLE_ACCURACY = 1e-2
#: Ackermann's formula is used while the controllability matrix is at most this ill-conditioned
ACKERMANN_CONDITION = 1e8


def _characteristic(poles: np.ndarray) -> np.ndarray:
    """The coefficients of ``prod_i (s - p_i)``, highest power first, multiplied out in real arithmetic: a real
    pole gives ``s - p``, a conjugate pair ``s^2 - 2 Re(p) s + |p|^2`` (real by construction; and no complex
    ufunc, which the C runtime of wine 8 lacks, runs in an FMU that designs its gain at initialisation)."""
    coefficients = np.ones(1)
    for p in poles:
        if abs(p.imag) <= 1e-12 * abs(p):     # real (up to the rounding _check_poles accepts)
            coefficients = np.convolve(coefficients, [1.0, -p.real])
        elif p.imag > 0:                       # its conjugate (checked present by _check_poles) is skipped
            coefficients = np.convolve(coefficients, [1.0, -2.0 * p.real, p.real ** 2 + p.imag ** 2])
    return coefficients


def pole_deviation(closed_loop, poles) -> float:
    """Largest ``|lambda_i - p_i| / |p_i|`` over the requested ``poles`` matched one to one (nearest
    first) with the eigenvalues ``lambda_i`` of ``closed_loop`` computed in double precision."""
    eigenvalues = list(np.linalg.eigvals(np.asarray(closed_loop, dtype=float)))
    poles = np.asarray(poles, dtype=complex)
    floor = 1e-9 * max(1.0, float(np.max(np.abs(poles))))     # poles at 0: absolute
    worst = 0.0
    for p in sorted(poles, key=lambda q: (q.real, q.imag)):
        distances = np.abs(np.asarray(eigenvalues) - p)
        i = int(np.argmin(distances))
        worst = max(worst, float(distances[i]) / max(abs(complex(p)), floor))
        eigenvalues.pop(i)
    return worst


#: largest amplification max_t |exp(M t)| of a designed closed loop M accepted by the configs
MAX_TRANSIENT_GROWTH = 1e8


def transient_growth(closed_loop) -> float:
    """``max_t |exp(M t)|_2`` (sampled on a log grid up to 30 time constants of the slowest mode).

    How much an initial error can grow before a stable closed loop ``M`` damps it -- and how much
    the rounding errors of a simulation of it grow.  Infinite if ``M`` is not Hurwitz.
    """
    from .integrators import expm

    M = np.asarray(closed_loop, dtype=float)
    eigenvalues = np.linalg.eigvals(M)
    if np.any(eigenvalues.real >= 0):
        return float("inf")
    fastest, slowest = np.abs(eigenvalues).max(), -eigenvalues.real.max()
    return max(1.0, max(float(np.linalg.norm(expm(M * t), 2))
                        for t in np.geomspace(1e-2 / fastest, 30.0 / slowest, 60)))


def _refuse(name: str, poles: np.ndarray, deviation: float, detail: str) -> ParameterError:
    multiplicity = _max_multiplicity(poles)
    hint = (f"a pole of multiplicity {multiplicity} is perturbed like (eps cond)^(1/{multiplicity}); "
            "choose distinct poles (e.g. form = \"butterworth\") " if multiplicity > 1 else "choose ")
    return ParameterError(
        f"{name}: the requested poles cannot be placed reliably in double precision: the eigenvalues "
        f"of the closed loop computed from the designed gain are off by {deviation:.2g} (relative; "
        f"accepted: {POLE_ACCURACY:g}){detail}; {hint}slower poles, or poles closer to the plant's own")


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


def _chains(poles: np.ndarray) -> list[tuple[complex, int]]:
    """Distinct poles with their multiplicities (conjugates kept next to each other)."""
    chains: list[tuple[complex, int]] = []
    for p in sorted(poles, key=lambda q: (q.real, abs(q.imag), q.imag)):
        if chains and _same_pole(p, chains[-1][0]):
            chains[-1] = (chains[-1][0], chains[-1][1] + 1)
        else:
            chains.append((complex(p), 1))
    return chains


def eigenvector_placement(A, b, poles) -> np.ndarray:
    """Single-input pole placement from the closed-loop (generalised) eigenvectors.

    ``(A - p I) x_1 = b``, ``(A - p I) x_{j+1} = x_j`` along the chain of a pole of
    multiplicity ``k``; each chain is scaled to unit norm; ``k`` solves ``k X = g`` (``g`` one at
    the head of each chain, zero elsewhere).  Needs no pole to be an eigenvalue of ``A``.
    """
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    b = np.asarray(b, dtype=float).reshape(n)
    columns, g = [], []
    for p, multiplicity in _chains(np.asarray(poles, dtype=complex)):
        shifted = A - p * np.eye(n)
        chain = [np.linalg.solve(shifted, b)]
        for _ in range(multiplicity - 1):
            chain.append(np.linalg.solve(shifted, chain[-1]))
        scale = 1.0 / np.linalg.norm(chain[0])
        columns += [scale * x for x in chain]
        g += [scale] + [0.0] * (multiplicity - 1)
    X = np.column_stack(columns)
    k = np.linalg.solve(X.T, np.asarray(g, dtype=complex))
    return np.real(k)[None, :]


def _single_input(A: np.ndarray, b: np.ndarray, poles: np.ndarray, name: str) -> np.ndarray:
    """The most accurate method's gain if it passes the check (module docstring), else refuse."""
    methods = [eigenvector_placement]
    if np.linalg.cond(controllability_matrix(A, b)) <= ACKERMANN_CONDITION:
        methods.insert(0, ackermann)
    best = (np.inf, None)
    for method in methods:
        try:
            k = method(A, b, poles)
        except np.linalg.LinAlgError:
            continue                        # a requested pole is an eigenvalue of A: the other method
        if np.all(np.isfinite(k)):
            deviation = pole_deviation(A - b @ k, poles)
            if deviation < best[0]:
                best = (deviation, k)
    deviation, k = best
    if k is None or deviation > POLE_ACCURACY:
        raise _refuse(name, poles, deviation, "" if k is None else f" (largest gain entry {np.abs(k).max():.3g})")
    return k


def _same_pole(p, q) -> bool:
    """``p`` and ``q`` are one pole (relative 1e-9, absolute 1e-12), in Python's complex arithmetic: numpy's
    complex scalar functions call the C runtime's complex functions, which wine 8 lacks (an FMU that designs
    its gain at initialisation runs this under wine in the tests)."""
    p, q = complex(p), complex(q)
    return abs(p - q) <= 1e-12 + 1e-9 * abs(q)


def _max_multiplicity(poles: np.ndarray) -> int:
    return max(sum(_same_pole(q, p) for q in poles) for p in poles)


def _cyclic_direction(A: np.ndarray, B: np.ndarray) -> np.ndarray | None:
    """A column combination ``v`` for which ``(A, B v)`` is controllable, if one exists."""
    n, m = B.shape
    candidates = [np.ones(m)] + [np.eye(m)[i] for i in range(m)]
    candidates += [np.random.default_rng(seed).standard_normal(m) for seed in range(5)]
    for v in candidates:
        if np.linalg.matrix_rank(controllability_matrix(A, B @ v[:, None])) == n:
            return v
    return None


def place(A, B, poles, name: str = "poles") -> np.ndarray:
    """State-feedback gain ``K`` (``m x n``) with ``eig(A - B K) = poles``.

    Parameters
    ----------
    A : (n, n) array_like
    B : (n, m) array_like
    poles : (n,) array_like
        Desired closed-loop poles; complex ones in conjugate pairs; repeated poles allowed.
    name : str
        How errors name the poles (e.g. ``observer.poles``).

    Raises
    ------
    ParameterError
        Wrong dimensions, non-finite entries, ``(A, B)`` not controllable, or poles that the
        closed loop does not have to :data:`POLE_ACCURACY` (relative) in double precision.
    """
    A = require_square("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, shape=(n, None))
    poles = _check_poles(poles, n, name)
    if not is_controllable(A, B):
        raise ParameterError("(A, B): not controllable, the poles cannot be placed")
    if B.shape[1] == 1:
        return _single_input(A, B, poles, name)
    if _max_multiplicity(poles) <= np.linalg.matrix_rank(B):
        K = _robust(A, B, poles, name)
    else:
        v = _cyclic_direction(A, B)
        if v is None:
            raise ParameterError(
                f"{name}: a pole multiplicity exceeds rank(B) and no single input direction "
                "controls (A, B); choose distinct poles"
            )
        return v[:, None] @ _single_input(A, B @ v[:, None], poles, name)
    deviation = pole_deviation(A - B @ K, poles)
    if deviation > POLE_ACCURACY:
        raise _refuse(name, poles, deviation, "")
    return K


def _robust(A: np.ndarray, B: np.ndarray, poles: np.ndarray, name: str) -> np.ndarray:
    """Tits & Yang's robust multi-input placement: numpy alone for real poles (:mod:`observers.robust_placement`,
    what an FMU designing its gain at initialisation runs), SciPy's ``place_poles`` for complex ones."""
    if all(p.imag == 0 for p in poles):
        return robust_place(A, B, np.array([p.real for p in poles]))
    try:
        from scipy.signal import (
            place_poles,  # here: scipy.signal costs ~0.5 s to import
        )
    except ImportError:                        # in an FMU: numpy only
        raise ParameterError(f"{name}: complex poles with several inputs (outputs) are placed by scipy, which is not "
                             "installed here; choose real poles") from None
    return place_poles(A, B, poles, method="YT").gain_matrix


def observer_gain(A, C, poles, name: str = "poles") -> np.ndarray:
    """Observer gain ``N`` (``n x p``) with ``eig(A - N C) = poles`` (by duality)."""
    A = require_square("A", A)
    n = A.shape[0]
    C = as_matrix("C", C, shape=(None, n))
    if not is_observable(A, C):
        raise ParameterError("(A, C): not observable, an observer gain cannot be designed")
    return place(A.T, C.T, poles, name).T


def shifted_poles(A, shift, name: str = "shift") -> np.ndarray:
    """The eigenvalues of ``A`` moved left by ``shift`` (> 0): poles that keep the design well conditioned."""
    shift = require_positive(name, shift)
    eigenvalues = np.linalg.eigvals(A)
    eigenvalues = np.where(np.abs(eigenvalues.imag) <= 1e-12 * max(1.0, np.abs(eigenvalues).max()),
                           eigenvalues.real, eigenvalues)
    return eigenvalues - shift


def desired_poles(n: int, *, poles=None, t_settle=None, form: str = "binomial", name: str = "poles",
                  normalised: float | None = None):
    """Resolve a design request: explicit ``poles`` or a ``t_settle`` with a standard ``form`` (``normalised``:
    the Butterworth form's settling time at radius 1, computed before)."""
    if (poles is None) == (t_settle is None):
        raise ParameterError(f"{name}: give exactly one of 'poles' or 't_settle'")
    if poles is not None:
        values = np.asarray(poles)
        if np.iscomplexobj(values):
            return _check_poles(values, n, name)
        return _check_poles(as_vector(name, values), n, name)
    return standard_poles(n, t_settle, form, normalised)


def design_state_feedback(A, B=None, *, poles=None, t_settle=None, form: str = "binomial") -> np.ndarray:
    """Modal controller ``K`` for ``u = -K x``: explicit poles or a standard form.

    ``A`` may be a whole system (``B`` omitted): a ``control.StateSpace`` or an ``(A, B, C, D)`` tuple.

    >>> design_state_feedback([[0, 1], [-2, 3]], [[0], [1]], t_settle=0.3)   # paper 002
    array([[398.,  43.]])
    """
    if B is None:
        model = StateSpace.of(A)
        A, B = model.A, model.B
    A = require_square("A", A)
    return place(A, B, desired_poles(A.shape[0], poles=poles, t_settle=t_settle, form=form))


def design_observer(A, C=None, *, poles=None, t_settle=None, form: str = "binomial") -> np.ndarray:
    """Observer gain ``N`` for ``x_hat' = A x_hat + B u + N (y - C x_hat)``.

    ``A`` may be a whole system (``C`` omitted): a ``control.StateSpace`` or an ``(A, B, C, D)`` tuple.

    >>> design_observer([[0, 1], [-2, 3]], [[1, 0]], t_settle=0.15)        # paper 002
    array([[  83.],
           [1847.]])
    """
    if C is None:
        model = StateSpace.of(A)
        A, C = model.A, model.C
    A = require_square("A", A)
    return observer_gain(A, C, desired_poles(A.shape[0], poles=poles, t_settle=t_settle, form=form))
