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

import numpy as np

from observers.checks import ParameterError

from .model import GeneratorModel

__all__ = ["ExampleRegression"]


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

    def __init__(self, model: GeneratorModel):
        expected = (model.n == 2 and model.sizes == (2, 2, 0) and np.array_equal(model.h_beta, [1.0, 0.0])
                    and np.array_equal(model.H_theta, [[1.0, 0.0], [0.0, 0.0]]))
        if not expected:
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

    def row(self, u, y) -> tuple[float, np.ndarray]:
        """``(zeta(k), rho(k))`` from ``u(k-6 .. k)`` and ``y(k-6 .. k)`` (arrays of 7, oldest first)."""
        s = [float(self.model.nonlinearity(y[j])[0]) for j in (1, 3, 5)]
        s1, s3, s5 = s
        u0, u2, u4 = u[0], u[2], u[4]
        y2, y4, y6 = y[2], y[4], y[6]
        zeta = s1 * u2 * y6
        rho = np.array([s1 * u4 * y4, -s3 * u4 * y2, s5 * u2 * y2, s3 * u0 * y6, -s5 * u0 * y4])
        return zeta, rho
