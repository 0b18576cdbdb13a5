r"""One LTI system driven by the measured output ``y``, and linear read-outs of its state.

Every filtered signal of paper 003 that does not depend on an estimate -- the
``z`` chain (7), ``e^{F t}``, the filters of (10), (14) and (17) -- is the
state (or a linear function of the state and of ``y``) of one LTI system

.. math:: \dot w = A_w w + b_w y, \qquad s(t) = R\,[y(t);\ w(t)],

built here block by block (a cascade: each new block is driven by ``y`` and
by states added before it).  A *read-out* ``R`` is a matrix with one row per
scalar signal and the columns ``[y, w_1, w_2, ...]``; read-outs made before
later blocks were added are padded with zero columns (:meth:`SignalModel.pad`).

The whole system is advanced exactly over a communication step for ``y``
linear over the step (:class:`~observers.integrators.LinearPropagator`), so
the accuracy of every regressor does not depend on the step.

Filters ``lambda^k / (p + lambda)^k`` are cascades of ``k`` first-order lags
``eta_j' = lambda (eta_{j-1} - eta_j)``, ``eta_0 = u``, which gives the
derivatives needed by the papers' "filtered derivatives" without
differentiating anything:

.. math:: p^j \eta_k = \lambda^j \sum_{l=0}^{j} \binom{j}{l} (-1)^{j-l}\, \eta_{k-l},
          \qquad 0 \le j \le k,

(``p = lambda (E - 1)`` with the shift ``E eta_i = eta_{i-1}``); ``p^k eta_k``
contains ``u`` itself (direct feedthrough).
"""

from __future__ import annotations

from math import comb

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.integrators import LinearPropagator

__all__ = ["SignalModel", "lowpass_derivatives"]


class SignalModel:
    """Builder of ``w' = A_w w + b_w y`` with read-outs over ``[y; w]``.

    Attributes
    ----------
    size : int
        Number of states added so far.
    """

    def __init__(self):
        self._blocks: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        self.size = 0

    # ------------------------------------------------------------------ read-outs
    def output(self) -> np.ndarray:
        """Read-out of ``y`` itself (one row)."""
        row = np.zeros((1, 1 + self.size))
        row[0, 0] = 1.0
        return row

    def zeros(self, rows: int) -> np.ndarray:
        """A read-out of ``rows`` identically zero signals."""
        return np.zeros((rows, 1 + self.size))

    def pad(self, readout: np.ndarray) -> np.ndarray:
        """``readout`` with zero columns for the states added after it was made."""
        readout = np.atleast_2d(readout)
        missing = 1 + self.size - readout.shape[1]
        if missing < 0:
            raise ValueError("read-out has more columns than the model")
        return np.pad(readout, ((0, 0), (0, missing))) if missing else readout

    # ------------------------------------------------------------------ blocks
    def add(self, A_block, drive, initial=None) -> np.ndarray:
        """Add ``k`` states ``v' = A_block v + drive [y; w]``; return the read-out of ``v``.

        Parameters
        ----------
        A_block : (k, k) array_like
        drive : (k, 1 + size) array_like
            Read-out (over the states present now) that drives the new states.
        initial : (k,) array_like, optional
            Initial value of the new states (zero by default).
        """
        A_block = np.atleast_2d(np.asarray(A_block, dtype=float))
        k = A_block.shape[0]
        drive = self.pad(np.asarray(drive, dtype=float).reshape(k, -1))
        initial = np.zeros(k) if initial is None else np.asarray(initial, dtype=float).reshape(k)
        self._blocks.append((self.size, A_block, drive, initial))
        self.size += k
        readout = np.zeros((k, 1 + self.size))
        readout[:, 1 + self.size - k:] = np.eye(k)
        return readout

    def lowpass(self, signal, order: int, lam: float, shift: np.ndarray | None = None) -> list[np.ndarray]:
        """Filter every row of ``signal`` with ``lam^order / (p + lam)^order``.

        Returns ``[F[u], p F[u], ..., p^order F[u]]`` as read-outs (one row per
        row of ``signal``); see :func:`lowpass_derivatives`.

        With ``shift = S`` (a ``d x d`` matrix for the ``d`` rows) the *modulated* filter
        ``lam^order (p I + lam I + S)^-order``: ``eta_j' = lam (eta_{j-1} - eta_j) - S eta_j``, and the
        read-outs are ``(p + S)^j F[u]``.  It makes the filter of a modulated signal LTI:
        ``F[e^{S t} u] = e^{S t} F_S[u]`` and ``p^j F[e^{S t} u] = e^{S t} (p + S)^j F_S[u]`` (zero initial
        states; ``d/dt e^{S t} = S e^{S t}``).
        """
        signal = self.pad(signal)
        if order == 0:
            return [signal]
        d = signal.shape[0]
        cascade = -lam * np.eye(order) + lam * np.eye(order, k=-1)       # eta_j' = lam (eta_{j-1} - eta_j)
        drive = np.zeros((order * d, signal.shape[1]))
        drive[:d] = lam * signal
        A_block = np.kron(cascade, np.eye(d))
        if shift is not None:
            A_block = A_block - np.kron(np.eye(order), shift)
        states = self.add(A_block, drive)
        etas = [self.pad(signal)] + [states[j * d:(j + 1) * d] for j in range(order)]
        return lowpass_derivatives(etas, lam)

    # ------------------------------------------------------------------ the system
    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(A_w, b_w, w0)`` of the complete system."""
        N = self.size
        A = np.zeros((N, N))
        b = np.zeros(N)
        w0 = np.zeros(N)
        for offset, A_block, drive, initial in self._blocks:
            k = A_block.shape[0]
            rows = slice(offset, offset + k)
            A[rows, rows] += A_block
            A[rows, :drive.shape[1] - 1] += drive[:, 1:]
            b[rows] += drive[:, 0]
            w0[rows] = initial
        return A, b, w0

    def propagator(self) -> LinearPropagator:
        """Exact step of ``w`` for ``y`` held or linear over the step."""
        A, b, _ = self.matrices()
        if not np.all(np.isfinite(A)):
            raise ParameterError("filters: the signal model has non-finite entries")
        return LinearPropagator(A, b[:, None])


def lowpass_derivatives(etas: list[np.ndarray], lam: float) -> list[np.ndarray]:
    r"""Read-outs of ``p^j eta_k``, ``j = 0..k``, of the cascade ``eta_0 = u, ..., eta_k``.

    .. math:: p^j \eta_k = \lambda^j \sum_{l=0}^{j} \binom{j}{l} (-1)^{j-l} \eta_{k-l}
    """
    k = len(etas) - 1
    return [lam ** j * sum(comb(j, l) * (-1) ** (j - l) * etas[k - l] for l in range(j + 1))
            for j in range(k + 1)]
