r"""The regressions of paper 003 as read-outs of one LTI system driven by ``y``.

Stage 1, eq. (10).  With ``z = z_r`` of (7) and ``Phi(t) = e^{F t}``, eq. (9)
times ``C`` is (see :mod:`~observers.uio.design`: ``C G_i = 0`` for ``i >= 1``)

.. math:: q_1 = \mathcal F_1[(1 - C G_0)\, y - C z] = \mathcal F_1[C \Phi]\,\tilde x(0) = m_1^T k_1,
          \qquad \mathcal F_1 = \frac{\lambda_1^{r-1}}{(p + \lambda_1)^{r-1}},

exact at every instant (zero filter states, constant ``k_1``).

Stage 2, eqs. (13)-(17), for constant ``theta = H xi(0)`` (``Gamma = 0``; a known generator
``Gamma != 0`` modulates the filters of ``s``, :meth:`RegressionSignals._modulated_rows`).  With
``z_bar = z + Phi x_tilde(0)`` the plant state is
``x = z_bar + sum_i G_i y^(i)`` (9); put it into (1) and multiply by ``B_bar``
(``B_bar B = 1``), using ``z_bar' = F z_bar + L_tilde y``:

.. math:: \bar B\Bigl[(F - A)\bar z + \tilde L y
          + \sum_{i=0}^{r-1}\bigl(G_i y^{(i+1)} - A G_i y^{(i)}\bigr)\Bigr]
          = x^T H \xi(0) + f .

Filter with ``F_2 = lambda_2^r / (p + lambda_2)^r`` (zero initial states) and
write ``F_2[y^(i)] = p^i F_2[y]`` -- exact up to terms ``t^k e^{-lambda_2 t}``
from the unknown initial derivatives, which is why stages 2-3 converge
asymptotically and not at ``nu < mu``:

.. math:: q = s^T \xi(0) + \bar f \quad (15), \qquad
          s = H^T\Bigl(F_2[\bar z] + \sum_{i=0}^{r-1} G_i\, p^i F_2[y]\Bigr), \qquad
          \bar f = F_2[f],

with ``q = B_bar [(F - A) F_2[z_bar] + L_tilde F_2[y] + sum_i (G_i p^{i+1} - A G_i p^i) F_2[y]]``
(derivative-free: ``p^j F_2`` is proper for ``j <= r``).  Known entries of
``xi(0)`` (the paper: ``theta_1 = 0``) move to the left: ``q_u = q - s_k^T xi_k``.

A sum of ``N`` sinusoids obeys ``P(p) f_bar = 0`` in steady state, with
``P(p) = prod_k (p^2 + omega_k^2) = p^{2N} + sum_{j<N} c_j p^{2j}``
(``N = 1``: ``c_0 = omega^2``, the paper's ``p^2 f_bar = -omega^2 f_bar``).
Apply ``P(p)`` to ``q_u - s_u^T xi_u`` (16) and the filter
``F_3 = lambda_3^{2N} / (p + lambda_3)^{2N}`` (second order for ``N = 1``, as
in (17)):

.. math:: p^{2N}F_3[q_u] = p^{2N}F_3[s_u]^T \xi_u
          + \sum_{j<N} c_j \bigl(F_3 p^{2j}[s_u]^T \xi_u - F_3 p^{2j}[q_u]\bigr),

the regression (17) in the unknowns ``k_2 = [xi_u, c, c (x) xi_u]`` -- for
``N = 1`` and the paper's example ``[xi0_2, omega^2, omega^2 xi0_2]``.  As
printed, (16)-(17) mix the signs of the ``omega^2`` terms (``F[q] - F[S]``
multiplying ``omega^2`` and ``omega^2 xi(0)`` together); the form above is
the consistent one.

Linearity in ``x_tilde(0)``.  ``z_bar = z + Phi x_tilde(0)``, and every filter is
linear, so each stage-2 signal is ``v_0(t) + sum_j x_tilde0_j v_j(t)``: the
*components* ``v_0`` (driven by ``z`` and ``y``) and ``v_j`` (driven by
``Phi e_j``) are filtered separately and combined with the *current*
estimate of ``x_tilde(0)``.  Once stage 1 is exact the stage-2 signals are
exactly those of a known ``x_tilde(0)``, with no memory of the wrong
values before.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb

import numpy as np

from obsfmu.observers.checks import ParameterError

from .design import UIODesign
from .generator import GeneratorFlow
from .signals import SignalModel

__all__ = ["RegressionSignals", "annihilator_regression", "frequencies_from_annihilator"]


@dataclass(frozen=True)
class _Layout:
    """Row offsets of the stage-2 read-outs of one component."""

    m: int
    m_u: int
    harmonics: int

    @property
    def rows(self) -> int:
        return 1 + self.m + (self.harmonics + 1) * (1 + self.m_u)


class RegressionSignals:
    r"""All regressors of stages 1 and 2, exact for ``y`` linear over each step.

    Parameters
    ----------
    design : UIODesign
    H : (n, m) ndarray
        ``theta = H xi``.
    B_bar : (n,) ndarray
        Row with ``B_bar B = 1``.
    free : (m,) bool ndarray
        Entries of ``xi(0)`` to estimate; the others are known.
    xi0_known : (m,) ndarray
        Values of the known entries (others ignored).
    harmonics : int
        Number ``N`` of sinusoids in ``f``.
    lambdas : (3,) sequence
        ``lambda_1`` (stage-1 filter, order ``r - 1``), ``lambda_2`` (filter of
        (14)), ``lambda_3`` (filter of (17), order ``2N``).
    z0 : (n,) ndarray
        ``z_r(0)``.
    order : int, optional
        Order ``k >= r`` of the filter ``F_2 = lambda_2^k / (p + lambda_2)^k`` of (14);
        default ``r + 1`` (see the notes).

    Notes
    -----
    The state ``w`` of the LTI system is kept by the caller (the observer)
    so that a step can be computed before it is committed.

    Filter order of (14).  The paper uses ``k = r``, the least order that
    makes ``p^r F_2[y]`` proper; it then contains ``lambda^r y`` itself (direct
    feedthrough).  In a co-simulation the filter states integrate ``y``
    interpolated linearly between samples, whose ripple has the mean
    ``-h^2 y''/12`` while the feedthrough takes the exact sample: the
    read-out is off by about ``lambda^r h^2 y''/12`` (measured on the paper's
    example at ``h = 1e-3``: a bias of 4e-4 in ``omega_hat``, 2.6e-4 in
    ``f_hat``, quartering with ``h``).  With ``k = r + 1`` every read-out is
    strictly proper and sees the same smoothed input (relative error
    ``(h omega)^2 / 12``).  ``f_bar = F_2[f]`` and (23) use the same ``k``.
    """

    def __init__(self, design: UIODesign, H, B_bar, free, xi0_known, harmonics: int, lambdas, z0,
                 order: int | None = None, generator: GeneratorFlow | None = None):
        d = design
        self.generator = generator
        n = d.n
        self.free = np.asarray(free, dtype=bool)
        self.known = ~self.free
        self.xi0_known = np.asarray(xi0_known, dtype=float)
        self.layout = _Layout(H.shape[1], int(self.free.sum()), int(harmonics))
        lam1, lam2, lam3 = (float(v) for v in lambdas)
        self.order = order = d.r + 1 if order is None else int(order)
        if order < d.r:
            raise ParameterError(f"filter_order: the filter of (14) needs order >= r = {d.r}, got {order}")
        if generator is not None:
            _check_modulated_filters(generator, lam2, lam3)

        model = SignalModel()
        y = model.output()
        z = model.add(d.F, np.outer(d.L_tilde, y[0]), z0)                    # (7): z_r' = F z_r + L_tilde y
        phi = [model.add(d.F, model.zeros(n), np.eye(n)[j]) for j in range(n)]   # e^{F t} e_j

        # stage 1, eq. (10)
        y, z = model.pad(y), model.pad(z)
        q1 = (1.0 - d.c0) * y - d.C @ z
        m1 = d.V.T @ np.vstack([d.C @ model.pad(column) for column in phi])   # unknowns: V^T x_tilde(0)
        self._q1 = model.lowpass(q1, d.r - 1, lam1)[0]
        self._m1 = model.lowpass(m1, d.r - 1, lam1)[0]

        # stage 2, eqs. (14)-(17): y-path (component 0 only) and the z_bar-path per component
        y_derivatives = model.lowpass(model.output(), order, lam2)              # p^i F_2[y], i = 0..order
        components = [(z, True)] + [(column, False) for column in phi]
        self._rates = (lam2, lam3)
        rows = self._constant_rows if generator is None else self._modulated_rows
        pieces = [rows(model, d, H, B_bar, z_bar, y_derivatives if with_y else None) for z_bar, with_y in components]
        self._stage2 = np.stack([np.vstack([model.pad(piece) for piece in readouts]) for readouts in pieces])
        self._zbar = np.stack([model.pad(z_bar) for z_bar, _ in components])
        self._q1, self._m1 = model.pad(self._q1), model.pad(self._m1)
        self.propagator = model.propagator()
        self.w0 = model.matrices()[2]
        self.size = model.size

    def _filtered(self, model: SignalModel, d: UIODesign, B_bar, z_bar, y_derivatives):
        """``F_2[z_bar]`` and ``q`` of (15) (the same for a constant and a time-varying ``theta``)."""
        z_f = model.lowpass(z_bar, self.order, self._rates[0])[0]
        q = (B_bar @ (d.F - d.A)) @ z_f
        if y_derivatives is not None:
            q = q + sum(beta * model.pad(y_derivatives[i]) for i, beta in enumerate(_betas(d, B_bar)))
        return z_f, np.atleast_2d(model.pad(q))

    def _constant_rows(self, model: SignalModel, d: UIODesign, H, B_bar, z_bar, y_derivatives):
        """Read-outs of one component for ``Gamma = 0``: ``q``, ``s`` (15) and ``p^{2j} F_3[q_u, s_u]`` (17)."""
        z_f, q = self._filtered(model, d, B_bar, z_bar, y_derivatives)
        s = H.T @ z_f
        if y_derivatives is not None:
            s = s + sum(np.outer(H.T @ d.G_i[i], model.pad(y_derivatives[i])[0]) for i in range(d.r))
        s = model.pad(s)
        q_u = q - self.xi0_known[self.known] @ s[self.known]
        annihilated = model.lowpass(np.vstack([q_u, s[self.free]]), 2 * self.layout.harmonics, self._rates[1])
        return [q, s] + annihilated[::2]

    def _modulated_rows(self, model: SignalModel, d: UIODesign, H, B_bar, z_bar, y_derivatives):
        r"""Read-outs of one component for ``Gamma != 0`` (:mod:`~observers.uio.generator`).

        ``s = F_2[e^{Gamma^T t} H^T x] = e^{Gamma^T t} sigma`` with ``sigma = F_2^Gamma[H^T x]``, the
        filter modulated by ``S = Gamma^T`` (:meth:`SignalModel.lowpass`), and
        ``p^{2j} F_3[s] = e^{Gamma^T t} (p + S)^{2j} F_3^Gamma[sigma]``: every filter stays LTI, ``e^{Gamma^T t}``
        multiplies the read-outs (:meth:`stage2`).  The ``y^(i)`` of ``x = z_bar + sum_i G_i y^(i)`` come
        from ``F_2^Gamma[u y^(i)] = p^i F_2^Gamma[u y]``, ``p^i = sum_l C(i, l) (-S)^(i-l) (p + S)^l``.
        Rows: ``q``, ``sigma`` (m), ``p^{2j} F_3[q]`` (j = 0..N), ``(p + S)^{2j} F_3^Gamma[sigma]`` (m each).
        """
        S = self.generator.Gamma.T
        order, N, (lam2, lam3) = self.order, self.layout.harmonics, self._rates
        _, q = self._filtered(model, d, B_bar, z_bar, y_derivatives)
        sigma = model.pad(model.lowpass(H.T @ model.pad(z_bar), order, lam2, shift=S)[0])
        if y_derivatives is not None:
            for i in range(d.r):
                shifted = model.lowpass(np.outer(H.T @ d.G_i[i], model.output()[0]), order, lam2, shift=S)
                sigma = model.pad(sigma) + _unshifted_derivative(shifted, S, i)
        sigma = model.pad(sigma)
        powers_q = model.lowpass(q, 2 * N, lam3)[::2]
        powers_sigma = model.lowpass(sigma, 2 * N, lam3, shift=S)[::2]
        return [q, sigma] + powers_q + powers_sigma

    # ------------------------------------------------------------------ evaluation
    @staticmethod
    def _yw(y: float, w: np.ndarray) -> np.ndarray:
        return np.concatenate(([y], w))

    def advance(self, w: np.ndarray, h: float, y0: float, dy: float) -> np.ndarray:
        """State at ``t + h`` for ``y(t + s) = y0 + s dy``."""
        return self.propagator.step(w, h, np.array([y0]), np.array([dy]))

    def stage1(self, y: float, w: np.ndarray) -> tuple[float, np.ndarray]:
        """``(q_1, m_1)`` of (10)."""
        yw = self._yw(y, w)
        return float((self._q1 @ yw)[0]), self._m1 @ yw

    def z_bar(self, y: float, w: np.ndarray, x_tilde0: np.ndarray) -> np.ndarray:
        """``z_bar = z_r + e^{F t} x_tilde(0)`` for the given estimate."""
        return _combine(self._zbar @ self._yw(y, w), x_tilde0)

    def stage2(self, y: float, w: np.ndarray, x_tilde0: np.ndarray, t: float = 0.0) -> dict[str, np.ndarray]:
        """Signals of (15) and (17) at time ``t`` for the estimate ``x_tilde0`` of ``x_tilde(0)``.

        Returns ``q`` (scalar), ``s`` (m), ``Y`` and ``phi`` of regression (17).  ``t`` matters only
        for a time-varying ``theta`` (``e^{Gamma^T t}``, :meth:`_modulated_rows`).
        """
        values = _combine(self._stage2 @ self._yw(y, w), x_tilde0)
        L = self.layout
        if self.generator is not None:
            return self._modulated_stage2(values, self.generator(t))
        q, s = values[0], values[1:1 + L.m]
        powers = values[1 + L.m:].reshape(L.harmonics + 1, 1 + L.m_u)       # row j: p^{2j} F_3[q_u, s_u]
        Y, phi = annihilator_regression(powers[:, 0], powers[:, 1:])
        return {"q": q, "s": s, "Y": Y, "phi": phi}

    def _modulated_stage2(self, values: np.ndarray, flow: np.ndarray) -> dict[str, np.ndarray]:
        """(15) and (17) from the rows of :meth:`_modulated_rows` and ``flow = e^{Gamma t}``."""
        L = self.layout
        m, count = L.m, L.harmonics + 1
        q, s = values[0], flow.T @ values[1:1 + m]
        P_q = values[1 + m:1 + m + count]
        P_s = values[1 + m + count:].reshape(count, m) @ flow       # row j: (e^{Gamma^T t} (p + S)^{2j} F_3[sigma])^T
        P_q_u = P_q - P_s[:, self.known] @ self.xi0_known[self.known]
        Y, phi = annihilator_regression(P_q_u, P_s[:, self.free])
        return {"q": q, "s": s, "Y": Y, "phi": phi}


def _check_modulated_filters(generator: GeneratorFlow, *rates: float) -> None:
    """The modulated filters ``lambda I + Gamma^T`` must be stable: ``Re eig(Gamma) > -lambda``."""
    decay = generator.slowest_decay
    for name, lam in zip(("lambda2", "lambda3"), rates):
        if lam + decay <= 0:
            raise ParameterError(f"{name}: {lam:g} <= -min Re eig(Gamma) = {-decay:g}; the filters of (14)/(17) "
                                 f"modulated by e^(Gamma t) need Re eig(Gamma) > -{name} (raise {name})")


def _unshifted_derivative(shifted: list[np.ndarray], S: np.ndarray, i: int) -> np.ndarray:
    """``p^i eta`` from ``shifted[l] = (p + S)^l eta``: ``sum_l C(i, l) (-S)^(i-l) (p + S)^l eta``."""
    return sum(comb(i, l) * np.linalg.matrix_power(-S, i - l) @ shifted[l] for l in range(i + 1))


def _combine(values: np.ndarray, x_tilde0: np.ndarray) -> np.ndarray:
    """``v_0 + sum_j x_tilde0_j v_j`` over the component axis (axis 0)."""
    return values[0] + np.tensordot(x_tilde0, values[1:], axes=1)


def _betas(d: UIODesign, B_bar: np.ndarray) -> list[float]:
    r"""Coefficients ``beta_i`` of ``p^i F_2[y]`` in ``q``, ``i = 0..r``.

    ``B_bar [L_tilde y + sum_i (G_i y^{(i+1)} - A G_i y^{(i)})] = sum_i beta_i y^{(i)}``.
    """
    betas = np.zeros(d.r + 1)
    betas[0] += B_bar @ d.L_tilde
    for i, G in enumerate(d.G_i):
        betas[i + 1] += B_bar @ G
        betas[i] -= B_bar @ d.A @ G
    return betas.tolist()


def annihilator_regression(P_q: np.ndarray, P_s: np.ndarray) -> tuple[float, np.ndarray]:
    r"""Regression (17) from ``P_q[j] = p^{2j} F_3[q_u]`` and ``P_s[j] = p^{2j} F_3[s_u]``.

    .. math:: Y = P_q[N], \qquad
              \phi = \bigl[P_s[N];\ -P_q[0..N-1];\ P_s[0], \dots, P_s[N-1]\bigr],

    unknowns ``[xi_u, c_0..c_{N-1}, c_0 xi_u, ..., c_{N-1} xi_u]``.
    """
    N = P_q.size - 1
    phi = np.concatenate([P_s[N], -P_q[:N], P_s[:N].ravel()])
    return float(P_q[N]), phi


def frequencies_from_annihilator(c: np.ndarray) -> np.ndarray:
    r"""``omega_k`` from ``P(j omega) = 0``, ``P(p) = p^{2N} + sum_{j<N} c_j p^{2j}``.

    With ``mu = omega^2``: ``sum_j c_j (-mu)^j = 0`` (``c_N = 1``).  Roots that
    are not real and positive before convergence are mapped to ``sqrt(|Re mu|)``;
    sorted ascending.  ``N = 1``: ``omega = sqrt(|c_0|)``.
    """
    c = np.asarray(c, dtype=float)
    N = c.size
    if N == 1:
        return np.sqrt(np.abs(c))
    coefficients = [(-1.0) ** j * (1.0 if j == N else c[j]) for j in range(N, -1, -1)]
    roots = np.roots(coefficients)
    return np.sort(np.sqrt(np.abs(roots.real)))
