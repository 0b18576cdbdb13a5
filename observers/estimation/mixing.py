r"""Mixing: from the square regression ``Y_e = Phi_e theta`` to ``p`` scalar regressions.

Second stage of DREM (papers 000 eq. (19), 003 (17)-(19), 004 eq. (7)):
multiplying by the adjugate ``adj(Phi_e)`` (``adj(A) A = det(A) I``) gives

.. math:: \mathcal Y = \operatorname{adj}(\Phi_e)\, Y_e = \Delta\,\theta,
          \qquad \Delta = \det \Phi_e ,

that is ``Y_i = Delta theta_i`` for each ``i`` separately.

Adjugate without an inverse.  By Cramer's rule
``(adj(A) b)_i = det(A with column i replaced by b)``, an identity of
polynomials that holds for singular ``A`` too.  :func:`mix` evaluates the
``p + 1`` determinants in one batched LU call; nothing is inverted, and
``Delta = 0`` (e.g. zero filter states at start-up) gives ``Y = 0`` exactly.

Scaling.  ``Delta`` is a product of ``p`` factors: for ``p = 10`` rows of size
1e-3 it is ~1e-30 (the scalar gains see ``Delta^2`` ~ 1e-60), rows of size 1e31
overflow.  With ``normalize=True`` each row of ``[Phi_e | Y_e]`` is divided
by the norm of its ``Phi_e`` part.  That keeps every row an exact regression,
leaves the solution ``theta`` unchanged, and by Hadamard's inequality
``|Delta| <= 1``: the scalar rate ``gamma Delta^2`` is at most ``gamma``
whatever the size of the signals.  For bounded ``Phi_e``
(``|row| <= B``) ``|Delta_normalised| >= |Delta| / B^p``, so ``Delta`` not
square-integrable implies the same of the normalised one (the convergence
condition is kept).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import SignalError

__all__ = ["mix", "normalize_rows"]


def normalize_rows(Y_e, Phi_e) -> tuple[np.ndarray, np.ndarray]:
    """Divide each row of ``Y_e = Phi_e theta`` by the Euclidean norm of its ``Phi_e`` row.

    Zero rows are left as they are.  Returns new arrays ``(Y_e, Phi_e)``.
    """
    norms = np.linalg.norm(Phi_e, axis=1)
    scale = np.divide(1.0, norms, out=np.ones_like(norms), where=norms > 0)
    return Y_e * scale, Phi_e * scale[:, None]


def mix(Y_e, Phi_e, normalize: bool = True) -> tuple[np.ndarray, float]:
    r"""Return ``(Y, Delta)`` with ``Delta = det(Phi_e)`` and ``Y = adj(Phi_e) Y_e``.

    Parameters
    ----------
    Y_e : ndarray, shape (p,)
    Phi_e : ndarray, shape (p, p)
        Extended regression ``Y_e = Phi_e theta``.
    normalize : bool, default True
        Row-normalise first (:func:`normalize_rows`), so ``|Delta| <= 1``.

    Returns
    -------
    Y : ndarray, shape (p,)
        Mixed outputs, ``Y_i = Delta theta_i``.
    Delta : float
        Determinant of the (normalised) ``Phi_e``.

    Raises
    ------
    SignalError
        If ``Delta`` or ``Y`` is not finite (overflow without normalisation).
    """
    Y_e = np.asarray(Y_e, dtype=float)
    Phi_e = np.asarray(Phi_e, dtype=float)
    if normalize:
        Y_e, Phi_e = normalize_rows(Y_e, Phi_e)
    p = Y_e.size
    stack = np.repeat(Phi_e[None], p + 1, axis=0)
    columns = np.arange(p)
    stack[columns + 1, :, columns] = Y_e          # Cramer: column i replaced by Y_e
    with np.errstate(over="ignore", invalid="ignore"):
        determinants = np.linalg.det(stack)
    if not np.isfinite(determinants).all():
        raise SignalError(
            f"Delta, Y: det overflowed ({determinants.tolist()}); signals too large for "
            "normalize=False; state unchanged"
        )
    return determinants[1:], float(determinants[0])
