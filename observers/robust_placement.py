"""Robust multi-input pole placement for real poles in numpy alone (Tits & Yang's algorithm).

``K`` with ``eig(A - B K) = poles`` for ``rank(B) > 1`` has freedom beyond the poles: the closed-loop
eigenvectors ``X = [x_1 ... x_n]``.  Tits & Yang ("Globally convergent algorithms for robust pole assignment
by state feedback", IEEE TAC 41(10), 1996) choose them to maximise ``|det X|`` (the closed loop's eigenvalues
are then the least sensitive): each ``x_j`` lies in the kernel ``S_j`` of ``U_1' (A - p_j I)``
(``B = [U_0 U_1] [Z; 0]``), and the algorithm rotates pairs ``(x_i, x_j)`` within ``S_i x S_j`` (section
6.1) until ``|det X|`` stops growing; then ``A - B K = X diag(p) X^-1`` gives ``K = Z^-1 U_0' (A - X P X^-1)``.

This is SciPy's ``place_poles(method="YT")`` (BSD-3, ``scipy/signal/_ltisys.py``) for real poles, in numpy only
(``numpy.linalg.qr`` for ``scipy.linalg.qr``): an FMU carries numpy, not scipy, and designs its gain at
initialisation with it (:mod:`fmus.runtime.kinds.linear`); the tests check it against SciPy's to 1e-9.
Complex poles keep SciPy's implementation (:func:`observers.modal.place`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["robust_place"]

#: SciPy's defaults: stop when |det X| changes by less than RTOL in a sweep, or after MAXITER sweeps
RTOL, MAXITER = 1e-3, 30


def robust_place(A, B, poles) -> np.ndarray:
    """``K`` (``m x n``) with ``eig(A - B K) = poles`` (real, each repeated at most ``rank(B)`` times,
    ``rank(B) > 1``; ``(A, B)`` controllable): the eigenvectors of the closed loop as well conditioned as Tits
    and Yang's iteration makes them."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    poles = np.sort(np.asarray(poles, dtype=float))           # SciPy's order for real poles
    n = A.shape[0]
    u, z = np.linalg.qr(B, mode="complete")
    rank = np.linalg.matrix_rank(B)
    u0, u1, z = u[:, :rank], u[:, rank:], z[:rank, :]
    if rank == n:                                              # B invertible: A - B K = diag(poles)
        return -np.linalg.lstsq(B, np.diag(poles) - A, rcond=None)[0]
    kernels, columns = [], []
    for p in poles:                                            # S_j = ker U_1' (A - p_j I)
        space = (u1.T @ (A - p * np.eye(n))).T
        kernel = np.linalg.qr(space, mode="complete")[0][:, space.shape[1]:]
        start = kernel.sum(axis=1)
        kernels.append(kernel)
        columns.append(start / np.linalg.norm(start))
    X = np.column_stack(columns)
    _maximise_determinant(kernels, X, poles)
    closed_loop = np.linalg.solve(X.T, np.diag(poles) @ X.T).T    # X diag(p) X^-1
    return -np.linalg.solve(z, u0.T @ (closed_loop - A))


def _maximise_determinant(kernels: list, X: np.ndarray, poles: np.ndarray) -> None:
    """Tits & Yang's sweeps over pairs of columns of ``X`` (in place), SciPy's update order for real poles."""
    floor = np.sqrt(np.spacing(1))
    order = _update_order(len(poles))
    for _ in range(MAXITER):
        before = abs(np.linalg.det(X))
        for i, j in order:
            others = np.delete(X, (i, j), axis=1)
            Q = np.linalg.qr(others, mode="complete")[0]
            _rotate_pair(kernels, Q, X, i, j)
        after = max(floor, abs(np.linalg.det(X)))
        if abs((after - before) / after) < RTOL and after > floor:
            return


def _update_order(count: int) -> np.ndarray:
    """The pairs ``(i, j)`` (0-based) one sweep updates, for ``count`` real poles (SciPy's ``_YT_loop``)."""
    half = count // 2
    first, second = [count, *2 * np.arange(1, half + count % 2)], [1, *2 * np.arange(1, half + count % 2) + 1]
    first += list(2 * np.arange(1, half + 1) - 1)
    second += list(2 * np.arange(1, half + 1))
    for j in np.arange(2, half + count % 2):
        for i in range(1, half + 1):
            first.append(i)
            second.append(i + j)
    for j in np.arange(2, half + count % 2):
        for i in range(half + 1, count + 1):
            first.append(i)
            second.append(i + j if i + j <= count else i + j - count)
    for i in range(1, half + 1):
        first.append(i)
        second.append(i + half)
    return np.array([first, second]).T - 1


def _rotate_pair(kernels: list, Q: np.ndarray, X: np.ndarray, i: int, j: int) -> None:
    """Section 6.1 of Tits & Yang for a real pair: the new ``(x_i, x_j)`` in ``S_i x S_j`` that maximises
    ``|det X|`` with the other columns fixed (``Q``'s last two columns span their complement)."""
    u, v = Q[:, -2, None], Q[:, -1, None]
    M = kernels[i].T @ (u @ v.T - v @ u.T) @ kernels[j]
    um, sm, vm = np.linalg.svd(M)
    mu1, mu2 = um.T[:2, :, None]
    nu1, nu2 = vm[:2, :, None]
    pair = np.vstack((X[:, i, None], X[:, j, None]))
    if not np.allclose(sm[0], sm[1]):
        basis = np.vstack((kernels[i] @ mu1, kernels[j] @ nu1))
    else:
        both = np.block([[kernels[i], np.zeros(kernels[i].shape)], [np.zeros(kernels[j].shape), kernels[j]]])
        basis = both @ np.vstack((np.hstack((mu1, mu2)), np.hstack((nu1, nu2))))
    projected = basis @ basis.T @ pair
    n = X.shape[0]
    if not np.allclose(projected, 0):
        projected = np.sqrt(2) * projected / np.linalg.norm(projected)
        X[:, i], X[:, j] = projected[:n, 0], projected[n:, 0]
    else:
        X[:, i], X[:, j] = basis[:n, 0], basis[n:, 0]
