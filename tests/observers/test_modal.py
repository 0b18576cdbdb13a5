"""Modal design: standard forms and pole placement against analytic results (paper 002)."""

import numpy as np
import pytest
from scipy.special import comb

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.modal import (ackermann, design_observer, design_state_feedback, observer_gain, place)
from obsfmu.observers.standard_forms import binomial, butterworth, settling_time, standard_poles

A_SHIP = np.array([[0.0, 1.0], [-2.0, 3.0]])
B_SHIP = np.array([[0.0], [1.0]])
C_SHIP = np.array([[1.0, 0.0]])


@pytest.mark.parametrize("n", [1, 2, 3, 5])
@pytest.mark.parametrize("t_settle", [0.15, 0.3, 2.0])
def test_binomial_form_matches_the_binomial_theorem(n, t_settle):
    T = t_settle / (3 * n)
    expected = np.array([comb(n, k) / T**k for k in range(n + 1)])  # (s + 1/T)^n
    np.testing.assert_allclose(binomial(n, t_settle), expected, rtol=1e-12)


def test_paper_002_standard_polynomials():
    np.testing.assert_array_equal(binomial(2, 0.3), [1, 40, 400])
    np.testing.assert_array_equal(binomial(2, 0.15), [1, 80, 1600])


def test_paper_002_gains_are_reproduced_exactly():
    K = design_state_feedback(A_SHIP, B_SHIP, t_settle=0.3)
    N = design_observer(A_SHIP, C_SHIP, t_settle=0.15)
    assert np.max(np.abs(K - [[398.0, 43.0]])) < 1e-9
    assert np.max(np.abs(N - [[83.0], [1847.0]])) < 1e-9


def test_paper_002_composite_eigenvalues():
    K = design_state_feedback(A_SHIP, B_SHIP, t_settle=0.3)
    N = design_observer(A_SHIP, C_SHIP, t_settle=0.15)
    Ae = np.block([[A_SHIP, -B_SHIP @ K], [N @ C_SHIP, A_SHIP - N @ C_SHIP - B_SHIP @ K]])
    # repeated eigenvalues are ill-conditioned: compare the characteristic polynomial ...
    np.testing.assert_allclose(np.poly(Ae), np.poly([-20, -20, -40, -40]), rtol=1e-9)
    # ... and the eigenvalues to the accuracy a double eigenvalue allows (sqrt(eps) * scale)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(Ae).real), [-40, -40, -20, -20], atol=1e-4)
    np.testing.assert_allclose(np.poly(A_SHIP - B_SHIP @ K), [1, 40, 400], rtol=1e-12)
    np.testing.assert_allclose(np.poly(A_SHIP - N @ C_SHIP), [1, 80, 1600], rtol=1e-12)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_butterworth_settles_in_the_requested_time(n):
    poles = standard_poles(n, 1.5, "butterworth")
    assert settling_time(np.real(np.poly(poles))) == pytest.approx(1.5, rel=2e-3)
    radius = np.abs(poles)
    np.testing.assert_allclose(radius, radius[0], rtol=1e-9)  # on a half circle
    assert np.all(poles.real < 0)


def test_butterworth_second_order_is_the_textbook_polynomial():
    np.testing.assert_allclose(butterworth(2, 3.0), [1, 3 * np.sqrt(2), 9], rtol=1e-12)


@pytest.mark.parametrize("poles", [[-1, -1, -1], [-2, -1 + 1j, -1 - 1j], [-5, -5, -0.5]])
def test_single_input_placement_with_repeated_and_complex_poles(poles):
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 3))
    b = rng.standard_normal((3, 1))
    k = ackermann(A, b, poles)
    np.testing.assert_allclose(np.poly(A - b @ k), np.real(np.poly(poles)), rtol=1e-8, atol=1e-8)


def test_multi_input_placement_distinct_and_repeated_poles():
    rng = np.random.default_rng(7)
    A = rng.standard_normal((4, 4))
    B = rng.standard_normal((4, 2))
    for poles in ([-1, -2, -3, -4], [-2, -2, -2, -2]):   # the second exceeds rank(B) = 2
        K = place(A, B, poles)
        assert K.shape == (2, 4)
        np.testing.assert_allclose(np.poly(A - B @ K), np.poly(poles), rtol=1e-6, atol=1e-6)


def test_multi_output_observer_gain():
    rng = np.random.default_rng(3)
    A = rng.standard_normal((4, 4))
    C = rng.standard_normal((2, 4))
    N = observer_gain(A, C, [-3, -3, -4, -5])
    assert N.shape == (4, 2)
    np.testing.assert_allclose(np.poly(A - N @ C), np.poly([-3, -3, -4, -5]), rtol=1e-6)


@pytest.mark.parametrize("call, message", [
    (lambda: place(A_SHIP, np.zeros((2, 1)), [-1, -2]), "not controllable"),
    (lambda: observer_gain(A_SHIP, [[0.0, 0.0]], [-1, -2]), "not observable"),
    (lambda: place(A_SHIP, B_SHIP, [-1, -2, -3]), "poles: expected 2 poles"),
    (lambda: place(A_SHIP, B_SHIP, [-1 + 1j, -2]), "conjugate pairs"),
    (lambda: place([[0, 1, 2], [3, 4, 5]], B_SHIP, [-1, -2]), "A: expected a square matrix"),
    (lambda: place(A_SHIP, [[0.0], [1.0], [2.0]], [-1, -2]), "B: expected 2 rows"),
    (lambda: place([[np.nan, 1], [0, 1]], B_SHIP, [-1, -2]), "A: entry (1, 1) is not finite"),
    (lambda: standard_poles(2, 0.3, "bessel"), "form: unknown standard form"),
    (lambda: standard_poles(2, -1.0), "t_settle: must be > 0"),
    (lambda: design_observer(A_SHIP, C_SHIP, poles=[-1, -2], t_settle=1.0), "exactly one of"),
])
def test_bad_design_input_names_the_problem(call, message):
    with pytest.raises(ParameterError, match=message.replace("(", r"\(").replace(")", r"\)")):
        call()
