"""``observers.integrators.expm`` (numpy scaling and squaring, Al-Mohy and Higham 2009) against ``scipy.linalg.expm``.

The project computes its matrix exponentials without scipy so that an LTI FMU, the config checks and
``obsfmu run ship`` do not pay the import of scipy (issue 14, target 3); scipy is the independent
reference here.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.linalg import expm as scipy_expm

from obsfmu.observers.integrators import BudgetError, LinearPropagator, expm, rk4_controlled, rk4_step


def _relative(E, R) -> float:
    return float(np.abs(E - R).max() / np.abs(R).max())


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8, 20, 50])
@pytest.mark.parametrize("scale", [1e-6, 1e-2, 0.2, 1.0, 4.0, 30.0])
def test_random_matrices_agree_with_scipy(n, scale):
    """Every Pade degree (norms below 0.015 up to 2^k squarings), stable and unstable matrices alike."""
    M = np.random.default_rng(n).standard_normal((n, n)) * scale / np.sqrt(n)
    assert _relative(expm(M), scipy_expm(M)) < 1e-12


@pytest.mark.parametrize("h", [1e-5, 1e-3, 0.1, 10.0])
def test_van_loan_matrices_of_a_stiff_lti_block_agree_with_scipy(h):
    """The augmented matrix of :class:`LinearPropagator` (nilpotent part; poles -0.01, -1, -1000)."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-10.0, -1010.01, -1001.01]])
    B = np.array([[0.0], [0.0], [1.0]])
    propagator = LinearPropagator(A, B)
    n, m = 3, 1
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n], M[:n, n:n + m], M[n:n + m, n + m:] = A, B, np.eye(m)
    reference = scipy_expm(M * h)
    Phi, G0, G1 = propagator.matrices(h)
    np.testing.assert_allclose(Phi, reference[:n, :n], rtol=1e-12, atol=1e-14 * np.abs(reference).max())
    np.testing.assert_allclose(G0, reference[:n, n:n + m], rtol=1e-11, atol=1e-14 * np.abs(reference).max())


def test_a_non_square_matrix_is_refused():
    with pytest.raises(ValueError, match=r"square matrix, got shape \(2, 3\)"):
        expm(np.zeros((2, 3)))


def test_the_exponential_imports_no_scipy():
    code = ("import sys, numpy as np; from observers.integrators import expm; expm(np.eye(3) * 5.0); "
            "print(any(name == 'scipy' or name.startswith('scipy.') for name in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() \
        == "False"


@pytest.mark.parametrize("coupling", [1e2, 1e4])
def test_highly_non_normal_matrices_agree_with_scipy(coupling):
    """Stable, strongly coupled chains (like the closed loops of high-order designs, whose norm is far
    above their spectral radius): the scaling follows the powers of the matrix, not its norm."""
    n = 20
    M = -np.diag(np.arange(1.0, n + 1)) + coupling * np.eye(n, k=1)
    for t in (1e-3, 0.1, 1.0):
        reference = scipy_expm(M * t)
        assert np.all(np.isfinite(expm(M * t)))
        assert _relative(expm(M * t), reference) < 1e-10, t   # entries up to 5e54


# -- rk4_controlled: RK4 sub-steps under local error control (expression plants)


def _pendulum(t, x):
    return np.array([x[1], -19.62 * np.sin(x[0]) - 0.3 * x[1] + np.sin(3 * t)])


@pytest.mark.parametrize("h, substeps", [(1e-3, 1), (1e-2, 3), (0.05, 50)])
def test_controlled_rk4_is_plain_rk4_where_the_error_is_within_tolerance(h, substeps):
    """Nothing rejected: the same sub-steps, the same result to the last bit (the scenarios' numbers kept)."""
    x_plain = x_controlled = np.array([0.5, 0.0])
    for k in range(20):
        x_plain = rk4_step(_pendulum, k * h, x_plain, h, substeps)
        x_controlled = rk4_controlled(_pendulum, k * h, x_controlled, h, substeps, 1e-8, 1e-12)
    assert np.array_equal(x_plain, x_controlled)


@pytest.mark.parametrize("rate", [-2700.0, -2e4])
def test_controlled_rk4_integrates_a_stiff_decay_to_its_absolute_tolerance(rate):
    """x' = rate x at h = 1e-3 (|h rate| 2.7 and 20: plain RK4 is inaccurate, then unstable): within
    atol = 1e-12 (plus rtol of the start) of exp(rate t) at every point."""
    x, worst = np.array([1.0]), 0.0
    for k in range(50):
        x = rk4_controlled(lambda t, x: rate * x, k * 1e-3, x, 1e-3, 1, 1e-8, 1e-12)
        worst = max(worst, abs(x[0] - np.exp(rate * (k + 1) * 1e-3)))
    assert worst < 1e-9
    plain = np.array([1.0])
    for k in range(50):
        plain = rk4_step(lambda t, x: rate * x, k * 1e-3, plain, 1e-3, 1)
    assert abs(plain[0]) > 1e-3                       # what the error control is for


def test_controlled_rk4_agrees_with_scipy_on_a_nonlinear_stiff_oscillator():
    """Van der Pol, mu = 50 (relaxation: stiff stretches), h = 1e-2 in 10 sub-steps: within 1e-6 of
    scipy's Radau at rtol 1e-12 over 5 s."""
    from scipy.integrate import solve_ivp

    def vdp(t, x):
        return np.array([x[1], 50.0 * (1 - x[0] ** 2) * x[1] - x[0]])
    x = np.array([2.0, 0.0])
    for k in range(500):
        x = rk4_controlled(vdp, k * 1e-2, x, 1e-2, 10, 1e-10, 1e-12)
    reference = solve_ivp(vdp, (0, 5.0), [2.0, 0.0], method="Radau", rtol=1e-12, atol=1e-14).y[:, -1]
    assert np.max(np.abs(x - reference)) < 1e-6


def test_controlled_rk4_refuses_past_its_budget_naming_it():
    with pytest.raises(BudgetError, match="substep_budget = 20 .* rtol = 1e-14"):
        rk4_controlled(lambda t, x: -2700.0 * x, 0.0, np.array([1.0]), 1e-3, 1, 1e-14, 1e-300, budget=20)
