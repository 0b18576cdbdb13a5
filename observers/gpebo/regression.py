r"""Input-output regression for the generator coefficients of paper 000's example (step 1).

The paper's general recipe (8)-(16) -- write the input-output model at
several shifts, eliminate the generator states by a determinant -- is
printed for the example in a garbled form, without its ``h`` vectors or
sampling.  This module is our own derivation (also in ``docs/paper000.md``).

Model.  ``n = 2``, ``delta = 0``, ``h_beta = [1, 0]``,
``h_theta = [[1, 0], [0, 0]]`` (so ``theta2 = 0``), ``Ts = 1`` (``t = k``):

.. math::
    x_1(k+1) = x_2(k) + \theta_1(k) f_1(x_1(k)), \qquad x_2(k+1) = \beta(k) u(k),

with ``Gamma_beta = [[0, 1], [gamma_beta, 0]]``, ``Gamma_theta = [[0, 1], [gamma_theta, 0]]``,
i.e. ``beta(k+2) = gamma_beta beta(k)`` and ``theta1(k+2) = gamma_theta theta1(k)``.

Input-output form (8).  Eliminating ``x2``, for every ``k >= 0`` (``x(0)``
drops out because ``A^2 = 0``):

.. math:: y(k+2) = \beta(k)\,u(k) + \theta_1(k+1)\, s(k+1), \qquad s(j) = f_1(y(j)).

Extension (10)-(11).  Written at ``k``, ``k+2``, ``k+4`` and expressed in the
two unknowns ``b = beta(k)``, ``c = theta1(k+1)`` of the first line:

.. math::
    \begin{bmatrix} u(k) & s(k+1) & y(k+2) \\
                    \gamma_\beta u(k+2) & \gamma_\theta s(k+3) & y(k+4) \\
                    \gamma_\beta^2 u(k+4) & \gamma_\theta^2 s(k+5) & y(k+6) \end{bmatrix}
    \begin{bmatrix} b \\ c \\ -1 \end{bmatrix} = 0 .

The vector ``[b; c; -1]`` is never zero, so the determinant vanishes for
every ``k`` (the mixing step (14)-(15) in one line).  Expanded, with
``u_j = u(k+j)``, ``s_j = s(k+j)``, ``y_j = y(k+j)``:

.. math::
    \gamma_\theta u_0 s_3 y_6 - \gamma_\theta^2 u_0 s_5 y_4 - \gamma_\beta s_1 u_2 y_6
    + \gamma_\beta^2 s_1 u_4 y_4 + \gamma_\beta \gamma_\theta^2 u_2 s_5 y_2
    - \gamma_\beta^2 \gamma_\theta u_4 s_3 y_2 = 0 .

It is homogeneous in six monomials of ``gamma``; only their ratios are
identifiable.  Dividing by ``gamma_beta`` (nonzero, as the paper assumes)
and keeping the term with coefficient 1 on the left gives the regression
(16), overparametrised with 5 unknowns:

.. math::
    \zeta = s_1 u_2 y_6 = \rho^T \sigma, \qquad
    \rho = \begin{bmatrix} s_1 u_4 y_4 \\ -s_3 u_4 y_2 \\ s_5 u_2 y_2 \\ s_3 u_0 y_6 \\ -s_5 u_0 y_4 \end{bmatrix},
    \qquad
    \sigma = \begin{bmatrix} \gamma_\beta \\ \gamma_\beta\gamma_\theta \\ \gamma_\theta^2 \\
             \gamma_\theta/\gamma_\beta \\ \gamma_\theta^2/\gamma_\beta \end{bmatrix}.

Shifted back by 6 samples it is realisable: at sample ``k`` it uses
``u(k-6), u(k-4), u(k-2)`` and ``y(k-5) .. y(k)``, and it holds exactly for
``k >= 6``.  The left inverse ``sigma^L`` (stage 1 of the paper's method) is
``gamma_beta = sigma_1``, ``gamma_theta = sigma_1 sigma_4`` (no division).

Excitation.  DREM needs 5 linearly independent rows ``rho``.  A constant
input leaves the plant on a periodic orbit where they are dependent; a
sampling period commensurate with a generator (``Ts = pi/2`` against the
4-periodic ``beta`` with ``u = sin t + sin 2t``) makes every other ``u(k)``
vanish; ``u = exp(-0.5 t)`` excites only a few samples before the rows
align.  See ``docs/paper000.md`` for the measurements.
"""

from __future__ import annotations

from itertools import permutations
from math import lcm

import numpy as np

from obsfmu.observers.checks import ParameterError

from .companion import CompanionRegression
from .model import GeneratorModel
from .terms import GENERATORS, MAPS, io_terms

__all__ = ["ExampleRegression", "ShiftRegression", "regression_for", "is_example"]


def is_example(model: GeneratorModel) -> bool:
    """``model`` has the structure of paper 000's example (any ``f``)."""
    return (model.n == 2 and model.sizes == (2, 2, 0) and np.array_equal(model.h_beta, [1.0, 0.0])
            and np.array_equal(model.H_theta, [[1.0, 0.0], [0.0, 0.0]]))


def regression_for(model: GeneratorModel, unknown=None):
    """The regression for ``model`` with the unknown ``gamma`` entries ``unknown`` ("last" | "all" per generator).

    Every generator "last" (the default, ``gamma = [0, ..., 0, g]``): the example's hand-derived
    regression for its structure, :class:`ShiftRegression` otherwise; a whole ``gamma`` unknown somewhere:
    :class:`~observers.gpebo.companion.CompanionRegression`.
    """
    if unknown is not None and any(form != "last" for form in unknown):
        return CompanionRegression(model, unknown)
    return ExampleRegression(model) if is_example(model) else ShiftRegression(model)


class ExampleRegression:
    """Regression ``zeta(k) = rho(k)^T sigma`` of the example (module docstring).

    Parameters
    ----------
    model : GeneratorModel
        Must have the example's structure (``n = 2``, ``h_beta = [1, 0]``,
        ``H_theta = [[1, 0], [0, 0]]``, no ``delta``); ``f_1`` is taken from it.
    """

    #: number of unknowns in sigma
    p = 5
    #: samples k-6 .. k enter one row
    window = 7
    #: names of the identified coefficients, in the order of :meth:`gammas`
    names = ("gamma_beta", "gamma_theta")
    #: entries of gammas the regression is divided by (must be nonzero)
    divisors = (0,)

    def __init__(self, model: GeneratorModel):
        if not is_example(model):
            raise ParameterError(
                "model: the input-output regression is derived for paper 000's example structure "
                "(n = 2, h_beta = [1, 0], H_theta = [[1, 0], [0, 0]], no delta); got n = "
                f"{model.n}, sizes (l, m, r) = {model.sizes}, h_beta = {model.h_beta.tolist()}, "
                f"H_theta = {model.H_theta.tolist()}")
        self.model = model

    @staticmethod
    def sigma(gamma_beta: float, gamma_theta: float) -> np.ndarray:
        """``sigma(gamma)`` of eq. (16) for the example; ``gamma_beta`` must be nonzero."""
        if gamma_beta == 0:
            raise ParameterError("gamma_beta: must be nonzero (the regression is divided by it)")
        gb, gt = float(gamma_beta), float(gamma_theta)
        return np.array([gb, gb * gt, gt * gt, gt / gb, gt * gt / gb])

    @staticmethod
    def gammas(sigma) -> np.ndarray:
        """Left inverse ``sigma^L``: ``[gamma_beta, gamma_theta] = [sigma_1, sigma_1 sigma_4]``."""
        return np.array([sigma[0], sigma[0] * sigma[3]])

    @staticmethod
    def full_coefficients(gammas) -> tuple[np.ndarray, np.ndarray]:
        """Generator vectors ``gamma_beta = [0, g_beta]``, ``gamma_theta = [0, g_theta]`` of the example."""
        return np.array([0.0, gammas[0]]), np.array([0.0, gammas[1]])

    @staticmethod
    def unknowns(*vectors) -> np.ndarray:
        """The unknowns ``[g_beta, g_theta]`` of the generator vectors (inverse of :meth:`full_coefficients`)."""
        return np.array([float(vector[-1]) for vector in vectors[:2]])

    @staticmethod
    def error_bound(sigma_hat, sigma_error) -> float:
        """Bound on ``max |gamma_hat - gamma|`` from ``|sigma_hat - sigma| <= sigma_error`` (entrywise)."""
        e, s = sigma_error, np.abs(sigma_hat)
        return float(max(e[0], s[0] * e[3] + s[3] * e[0] + e[0] * e[3]))

    def row(self, u, y) -> tuple[float, np.ndarray]:
        """``(zeta(k), rho(k))`` from ``u(k-6 .. k)`` and ``y(k-6 .. k)`` (arrays of 7, oldest first)."""
        s = [float(self.model.nonlinearity(y[j])[0]) for j in (1, 3, 5)]
        s1, s3, s5 = s
        u0, u2, u4 = u[0], u[2], u[4]
        y2, y4, y6 = y[2], y[4], y[6]
        zeta = s1 * u2 * y6
        rho = np.array([s1 * u4 * y4, -s3 * u4 * y2, s5 * u2 * y2, s3 * u0 * y6, -s5 * u0 * y4])
        return zeta, rho


def _real_root(value: float, order: int) -> float:
    """The real ``order``-th root of ``value`` (``order`` odd, or ``value >= 0``)."""
    if order == 1:
        return float(value)
    return float(np.sign(value) * abs(value) ** (1.0 / order))


class ShiftRegression:
    r"""Regression (16) for any plant of the class whose generators have one unknown coefficient each.

    Generator form (the example's, any size ``d``): ``gamma_• = [0, ..., 0, g_•]``, so
    ``Gamma_•^d = g_• I`` and every output ``w`` of the generator obeys ``w(k + d) = g_• w(k)``.

    Input-output form (8).  Unrolling the shift chain ``n`` samples (``A^n = 0``, ``x(k)`` drops out):

    .. math:: y(k+n) = \beta(k) u(k) + \sum_i \theta_i(k+n-i) f_i(y(k+n-i)) + \sum_i \delta_i(k+n-i),

    a sum of ``T`` *terms* ``s_t(k + o_t) w_t(k + o_t)``: a known signal (``u``, ``f_i(y)``, ``1``)
    times an unknown generator output (the ``delta`` terms merge into one, their signal is 1).  With
    ``D = lcm`` of the sizes, ``w_t(k + o_t + j D) = G_t^j w_t(k + o_t)``, ``G_t = g_t^(D / d_t)``.

    Extension (10)-(11).  The form at ``k, k + D, ..., k + T D`` is ``M [w(k); -1] = 0`` with
    ``M[j, t] = G_t^j s_t(k + o_t + j D)`` and last column ``y(k + n + j D)``, hence ``det M = 0``
    (the mixing step (14)-(15)).  By Leibniz ``det M = sum_alpha c_alpha(k) G^alpha``: every
    permutation gives a monomial ``G^alpha`` and a product of data.  Dividing by one monomial
    ``G^alpha0`` (chosen so that every ``G_v`` is one entry, or a product of two entries, of sigma):

    .. math:: \zeta = c_{\alpha_0} = \rho^T \sigma, \qquad \rho = -[c_\alpha]_{\alpha \ne \alpha_0},
              \qquad \sigma = [G^{\alpha - \alpha_0}]_{\alpha \ne \alpha_0} .

    Realisable shifted back by ``n + T D`` samples (``window = n + T D + 1``).  For the paper's
    example this is its 3 x 3 determinant (:class:`ExampleRegression`, which the observer keeps for it).

    Parameters
    ----------
    model : GeneratorModel
        Any structure; refused (naming the field) if a generator reaches no term, if ``D / d`` is
        even (the sign of ``g`` is lost), or if there are more than :attr:`MAX_TERMS` terms.
    """

    MAX_TERMS = 6
    GENERATORS = GENERATORS
    MAPS = MAPS

    def __init__(self, model: GeneratorModel):
        self.model = model
        present = [v for v, size in enumerate(model.sizes) if size]
        self.names = tuple(self.GENERATORS[v] for v in present)
        self.terms = io_terms(model, self.MAX_TERMS)
        T = len(self.terms)
        self.D = lcm(*(model.sizes[v] for v in present))
        self.orders = np.array([self.D // model.sizes[v] for v in present])
        for v, name, order in zip(present, self.names, self.orders):
            if order % 2 == 0:
                raise ParameterError(f"{self.MAPS[v]}: the regression shifts by D = lcm of the generator sizes "
                                     f"{[model.sizes[w] for w in present]} = {self.D} samples, so it identifies "
                                     f"{name}^{order}: an even power loses the sign; give the generators sizes "
                                     "with odd ratios D / d (e.g. all equal)")
        self.window = model.n + T * self.D + 1
        slot = {v: i for i, v in enumerate(present)}
        # Leibniz: permutation -> sign and exponent vector alpha (row j of term t adds j to its variable)
        perms = np.array(list(permutations(range(T + 1))))
        signs = np.array([np.linalg.det(np.eye(T + 1)[p]) for p in perms]).round()
        alphas = np.zeros((len(perms), len(present)), dtype=int)
        for j in range(T + 1):
            for q, p in enumerate(perms):
                if p[j] < T:
                    alphas[q, slot[self.terms[p[j]][0]]] += j
        monomials, groups = np.unique(alphas, axis=0, return_inverse=True)
        self._perms = perms
        self._weights = np.zeros((len(monomials), len(perms)))
        self._weights[groups.ravel(), np.arange(len(perms))] = signs
        self._choose_normaliser(monomials)

    def _choose_normaliser(self, monomials: np.ndarray) -> None:
        """``alpha0`` (lowest total degree first) from which every ``G_v`` is recoverable (:meth:`gammas`)."""
        unit = np.eye(len(self.names), dtype=int)
        for index in np.argsort(monomials.sum(axis=1), kind="stable"):
            others = np.delete(np.arange(len(monomials)), index)
            exponents = monomials[others] - monomials[index]
            recovery = [self._recovery(exponents, unit[v]) for v in range(len(self.names))]
            if all(r is not None for r in recovery):
                self.alpha0, self.others, self.exponents, self.recovery = index, others, exponents, recovery
                self.p = len(others)
                self.divisors = tuple(v for v in range(len(self.names)) if np.any(exponents[:, v] < 0))
                return
        raise ParameterError("H_theta: no normalisation of the determinant regression recovers every generator "
                             f"coefficient ({', '.join(self.names)}) from its sigma")

    @staticmethod
    def _recovery(exponents: np.ndarray, target: np.ndarray):
        """Indices ``(a,)`` or ``(a, b)`` of sigma entries whose product is ``G_v`` (exponent ``target``)."""
        for a, e in enumerate(exponents):
            if np.array_equal(e, target):
                return (a,)
        for a in range(len(exponents)):
            for b in range(a, len(exponents)):
                if np.array_equal(exponents[a] + exponents[b], target):
                    return (a, b)
        return None

    # ------------------------------------------------------------------ the interface of ExampleRegression
    def sigma(self, *gammas) -> np.ndarray:
        """``sigma = [G^(alpha - alpha0)]`` with ``G_v = g_v^(D / d_v)``; the divisors must be nonzero."""
        G = np.array([float(g) ** int(q) for g, q in zip(gammas, self.orders)])
        for v in self.divisors:
            if G[v] == 0:
                raise ParameterError(f"{self.names[v]}: must be nonzero (the regression is divided by it)")
        return np.array([np.prod([G[v] ** int(e[v]) for v in range(len(G))]) for e in self.exponents])

    def gammas(self, sigma) -> np.ndarray:
        """Left inverse ``sigma^L``: each ``G_v`` from one entry or a product of two, then its real root."""
        G = [np.prod([sigma[a] for a in r]) for r in self.recovery]
        return np.array([_real_root(g, int(q)) for g, q in zip(G, self.orders)])

    def full_coefficients(self, gammas) -> tuple[np.ndarray, ...]:
        """Generator vectors ``[0, ..., 0, g_•]`` (as :meth:`GeneratorModel.transition` takes them)."""
        vectors = []
        for v, size in enumerate(self.model.sizes):
            vector = np.zeros(size)
            if size:
                vector[-1] = gammas[self.names.index(self.GENERATORS[v])]
            vectors.append(vector)
        return tuple(vectors)

    def unknowns(self, *vectors) -> np.ndarray:
        """The unknowns ``g`` of the present generators' vectors (inverse of :meth:`full_coefficients`)."""
        return np.array([float(vector[-1]) for vector, size in zip(vectors, self.model.sizes) if size])

    def error_bound(self, sigma_hat, sigma_error) -> float:
        """Bound on ``max |gamma_hat - gamma|`` from ``|sigma_hat - sigma| <= sigma_error`` (entrywise)."""
        s, e, bounds = np.abs(sigma_hat), np.asarray(sigma_error), []
        for r, q in zip(self.recovery, self.orders):
            eG = e[r[0]] if len(r) == 1 else s[r[0]] * e[r[1]] + s[r[1]] * e[r[0]] + e[r[0]] * e[r[1]]
            bounds.append(eG if q == 1 else 2.0 ** (1 - 1 / q) * eG ** (1 / q))   # Hoelder: odd real root
        return float(max(bounds))

    def row(self, u, y) -> tuple[float, np.ndarray]:
        """``(zeta(k), rho(k))`` from ``u``, ``y`` over the window (oldest first)."""
        T, D, n = len(self.terms), self.D, self.model.n
        S = np.empty((T + 1, T + 1))
        for j in range(T + 1):
            for t, (_, signal, offset) in enumerate(self.terms):
                index = offset + j * D
                S[j, t] = u[index] if signal == "u" else 1.0 if signal == "1" else \
                    self.model.nonlinearity(y[index])[signal]
            S[j, T] = y[n + j * D]
        c = self._weights @ np.prod(S[np.arange(T + 1), self._perms], axis=1)
        return float(c[self.alpha0]), -c[self.others]
