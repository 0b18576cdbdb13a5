r"""Can the observer of paper 003 identify this plant in this experiment?  An in-memory run says.

Stage 2 estimates ``k_2 = [xi_u, c, c (x) xi_u]`` from regression (17), which is exact only once the
filters' unknown initial derivatives have died out (terms ``t^k e^{-lambda t}``,
:mod:`~observers.uio.regressions`).  Two things can make the observer fail silently, and both are
measured here along the file's own experiment -- the plant's ``y`` from its ``x(0)``, ``xi(0)`` and
``f`` -- with stages 1 and 2 of the observer itself:

1. **Rank.** Where (17) is exact, its rows must span all ``p_2`` unknowns.  With both feedback
   parameters of a companion-form plant unknown, the rows lose one dimension once the filters'
   transients are gone (``s_min / s_max`` 5.9e-15 against 0.056 for the paper's example): the estimates
   then settle at wrong values (``omega`` 34.8 against 3) and the identification test even says
   "identified".  The unidentifiable direction (the right singular vector of ``s_min``) names the
   unknowns.
2. **Excitation where (17) is exact.** Each estimate's error obeys ``theta_tilde' = -g Delta^2
   theta_tilde`` (``g = gamma_2``, eq. (18)): whatever stage 2 gathered while (17) was not yet exact
   shrinks by ``exp(-int g Delta^2)`` over the exact part.  Too little there and the estimates keep
   the transient's error (a fourth-order plant: ``omega`` 1.10 against 1.2, "identified" at 9 s).

Where (17) is exact.  Its error decays like the filters (``lambda_2``, ``lambda_3``) and like the part of
``x_tilde(0)`` that stage 1 cannot see -- along the plant's invariant zeros, kept in ``F``
(:mod:`~observers.uio.design`).  The run knows the plant's true ``xi(0)`` and frequencies, so it measures
that error, ``Y - phi^T k_2``, and takes as exact the part of the run from which it stays below
``EXACT_LEVEL`` of the signals (the rank test does not depend on it: the rows are functions of ``y``
alone).  With ``m_u >= 1`` unknown entries of ``xi(0)`` stage 2 has ``m_u + N + N m_u > 2N`` unknowns, while in steady state ``y`` is a sum of ``N`` sinusoids (``2N``
dimensions): identification rests on the plant's own transient, which must outlast the regression's.
Both findings are necessary conditions: a file that passes may still converge slowly.

The run uses a step of ``1 / (10 x the fastest rate)`` (the filters are exact for ``y`` linear over a
step), so it costs stages 1-2 only, a few thousand steps.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter1d

__all__ = ["ENOUGH_EXCITATION", "EXACT_LEVEL", "RANK_TOLERANCE", "StageTwoExcitation", "invariant_zeros",
           "stage_two_excitation", "stage_two_labels", "stage_two_truth"]

#: ``s_min / s_max`` of the row-normalised exact rows below which (17) is rank deficient
RANK_TOLERANCE = 1e-8

#: (17) counts as exact where ``|Y - phi^T k_2| <= EXACT_LEVEL max (|Y| + |phi| |k_2|)`` (the largest over the
#: last eighth of a period of the fastest sinusoid) from then on (the run's
#: coarse step alone leaves ~2e-5: measured on the paper's example, whose error is there from 3 s on)
EXACT_LEVEL = 1e-3

#: ``int g Delta^2`` over the exact part that shrinks the error gathered before it at least 1000-fold
ENOUGH_EXCITATION = 7.0


@dataclass(frozen=True)
class StageTwoExcitation:
    """What stage 2 sees along an experiment.

    Attributes
    ----------
    ratio : float
        ``s_min / s_max`` of the row-normalised rows of (17) over ``window`` (-1: no row there).
    null : ndarray
        The right singular vector of ``s_min`` (weights of the unknowns in the unidentifiable direction).
    window : (float, float)
        Where (17) is exact in the run (``(stop_time, stop_time)``: nowhere).
    residual : float
        ``|Y - phi^T k_2|`` relative to the signals' size, at the end of the run.
    zeros : ndarray
        The plant's invariant zeros (the eigenvalues of ``F`` that ``C`` does not see).
    exponent : float
        ``int g Delta^2`` over ``window`` (``g = gamma_2``; normalised: the stage's gain): the error stage 2
        gathered before the window shrinks there by ``exp(-exponent)``.
    integral : float
        ``int Delta^2`` over ``window``.
    """

    ratio: float
    null: np.ndarray
    window: tuple[float, float]
    residual: float
    zeros: np.ndarray
    exponent: float
    integral: float

    @property
    def exact_part(self) -> bool:
        """The run reaches the part of the experiment where (17) is exact."""
        return self.window[0] < self.window[1]


def stage_two_labels(free: np.ndarray, harmonics: int) -> list[str]:
    """The names of ``k_2 = [xi_u, c_0..c_{N-1}, c_0 xi_u, ..., c_{N-1} xi_u]`` (``N = 1``: ``omega^2``)."""
    xi = [f"xi0[{j + 1}]" for j in np.flatnonzero(free)]
    c = ["omega^2"] if harmonics == 1 else [f"c_{j}" for j in range(harmonics)]
    return xi + c + [f"{cj} {x}" for cj in c for x in xi]


def invariant_zeros(design) -> np.ndarray:
    """The eigenvalues of ``F`` on the subspace ``C`` does not see (the plant's ``n - r`` zeros)."""
    V = design.V
    if V.shape[1] == design.n:
        return np.zeros(0)
    K = np.linalg.svd(V.T)[2][V.shape[1]:].T               # orthonormal basis of the unseen, F-invariant subspace
    return np.linalg.eigvals(K.T @ design.F @ K)


def _step(observer, plant_rate: float) -> float:
    """``1 / (10 x the fastest rate)`` of the observer's filters, its ``F`` and the plant's signals."""
    rates = [*observer.lambdas, *np.concatenate(observer.rates[:2]), plant_rate,
             *np.abs(np.linalg.eigvals(observer.design.F))]
    return 1.0 / (10.0 * max(rates))


def stage_two_truth(xi0, omega, free) -> np.ndarray:
    """The true ``k_2 = [xi_u, c, c (x) xi_u]`` of a plant with ``xi(0) = xi0`` and frequencies ``omega``:
    ``c`` the coefficients of ``prod_k (mu + omega_k^2) = mu^N + sum_{j<N} c_j mu^j``, ``mu = p^2``."""
    xi_u = np.asarray(xi0, dtype=float)[np.asarray(free, dtype=bool)]
    c = np.poly(-np.asarray(omega, dtype=float) ** 2)[::-1][:-1]
    return np.concatenate([xi_u, c, np.kron(c, xi_u)])


def stage_two_excitation(observer, plant, truth, stop_time: float, plant_rate: float,
                         span: float) -> StageTwoExcitation:
    """Run ``plant`` (a block with no input and output ``y``) and stages 1-2 of a copy of ``observer``
    (a :class:`~observers.uio.UIOFiniteTimeObserver`) over ``[0, stop_time]``; ``truth`` is the plant's
    ``k_2`` (:func:`stage_two_truth`), ``plant_rate`` the fastest rate of its signals (poles,
    frequencies); the error of (17) is measured against the size of the signals over the last ``span``
    (an eighth of the fastest sinusoid's period: long enough to bridge a zero crossing).  Neither block is
    changed."""
    observer, plant = copy.deepcopy(observer), copy.deepcopy(plant)
    h = _step(observer, plant_rate)
    steps = max(1, int(np.ceil(stop_time / h)))
    h = stop_time / steps
    signals, stage1, stage2, V = observer.signals, observer.stage[0], observer.stage[1], observer.design.V
    w, rows = signals.w0.copy(), np.zeros((steps, stage2.p))
    error, size, squares, gains = (np.zeros(steps) for _ in range(4))   # |Y - phi k|, |Y| + |phi||k|, Delta^2 h, g
    y0 = float(plant.outputs(0.0, {})["y"][0])
    for k in range(steps):
        t = k * h
        plant.advance(t, h, {})
        y1 = float(plant.outputs(t + h, {})["y"][0])
        q1, m1 = signals.stage1(y0, w)
        regression = signals.stage2(y0, w, V @ stage1.theta_hat, t)
        stage1.update(q1, m1, h)                                           # (11)-(12)
        stage2.update(regression["Y"], regression["phi"], h)              # (18)-(19)
        Y, rows[k] = regression["Y"], regression["phi"]
        error[k], size[k] = abs(Y - rows[k] @ truth), abs(Y) + np.linalg.norm(rows[k]) * np.linalg.norm(truth)
        squares[k], gains[k] = stage2.delta ** 2 * h, float(np.min(stage2.drem.gain(stage2.delta)))
        w = signals.advance(w, h, y0, (y1 - y0) / h)
        y0 = y1
    width = max(1, int(round(span / h)))
    recent = maximum_filter1d(size, width, origin=(width - 1) // 2)       # the size over the last span
    relative = error / np.maximum(recent, 1e-300)
    inexact = np.flatnonzero(~(relative <= EXACT_LEVEL))
    first = int(inexact[-1]) + 1 if inexact.size else 0
    ratio, null = _conditioning(rows[first:])
    return StageTwoExcitation(ratio, null, (first * h, stop_time), float(relative[-1]), invariant_zeros(observer.design),
                              float(gains[first:] @ squares[first:]), float(squares[first:].sum()))


def _conditioning(rows: np.ndarray) -> tuple[float, np.ndarray]:
    norms = np.linalg.norm(rows, axis=1)
    usable = rows[np.isfinite(norms) & (norms > 0)]
    if len(usable) < rows.shape[1]:
        return -1.0, np.zeros(rows.shape[1])
    _, s, vt = np.linalg.svd(usable / np.linalg.norm(usable, axis=1)[:, None], full_matrices=False)
    return float(s[-1] / s[0]), vt[-1]
