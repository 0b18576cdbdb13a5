"""Paper 001 without FMI: the LTV plant and the adaptive observer blocks, and their error handling.

The reference (``fmus/scenarios/ltv_common/reference.py``) imports nothing from the project: plant and
plant + filters + estimator are each ONE ODE solved with scipy (the plant: Radau at rtol = atol = 1e-10;
plant + filters + estimator: DOP853 at rtol = atol = 1e-12).
"""

import math

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.ltv import LTVAdaptiveObserver
from obsfmu.observers.ltv.stepping import SUBSTEP_POINTS, IntegralSamples, PolynomialInputs, resolved_output
from obsfmu.plants.ltv import A_paper, L_paper, OutputNonlinearLTVPlant, f_sin
from obsfmu.plants.signals import SampledNoise
from obsfmu.fmus.scenarios.ltv_common import reference as ref

C = [1.0, 0.0]


def observer(**options):
    return LTVAdaptiveObserver(**(dict(A=A_paper, C=C, L=L_paper, f=f_sin) | options))


def plant(case, **options):
    return OutputNonlinearLTVPlant(A_paper, C, f_sin, case["k"], case["b"], case["m"], case["x0"], **options)


def run_blocks(case, T, h, interpolate=True, **observer_options):
    """Plant then observer (Gauss-Seidel), u = sin t; inputs interpolated across the step or held.

    Returns times, plant states, observer estimates ``theta_hat`` and ``x_hat``.
    """
    p, o = plant(case), observer(**observer_options)
    steps = int(round(T / h))
    x, theta_hat, x_hat = [p.x.copy()], [o.outputs(0.0, {})["theta_hat"]], [o.outputs(0.0, {})["x_hat"]]
    for i in range(steps):
        t = i * h
        y0 = p.outputs(t, {})["y"]
        u = Segment.between([math.sin(t)], [math.sin(t + h)], h) if interpolate else Segment.hold([math.sin(t)])
        p.advance(t, h, {"u": u})
        y1 = p.outputs(t + h, {})["y"]
        o.advance(t, h, {"u": u, "y": Segment.between(y0, y1, h) if interpolate else Segment.hold(y1)})
        out = o.outputs(t + h, {})
        x.append(p.x.copy())
        theta_hat.append(out["theta_hat"])
        x_hat.append(out["x_hat"])
    return h * np.arange(steps + 1), np.array(x), np.array(theta_hat), np.array(x_hat)


# --- numerics against the independent reference ---------------------------------------------

def test_plant_follows_the_monolithic_solution_while_it_grows_to_hundreds():
    times = np.linspace(0.0, 10.0, 101)
    x = ref.simulate_plant(times, **ref.PAPER)
    p, h, x_blocks = plant(ref.PAPER), 1e-3, [ref.PAPER["x0"]]
    for i in range(10_000):
        t = i * h
        p.advance(t, h, {"u": Segment.between([math.sin(t)], [math.sin(t + h)], h)})
        x_blocks.append(p.outputs(t + h, {})["x"])
    relative = np.abs(np.array(x_blocks)[::100] - x) / (1.0 + np.abs(x))
    assert np.abs(x).max() > 300                  # the paper's plant is unstable
    assert relative.max() < 1e-7                  # measured 3.5e-8 (u as parabolas, RK4 resolving sin y)


def test_observer_agrees_with_the_monolithic_solution_in_the_stiff_start():
    """gamma Psi F Psi^T ~ 1e4 1/s at t = 0: the estimator's first 0.1 s at a 1e-3 s step."""
    times = np.linspace(0.0, 2.0, 2001)
    reference = ref.simulate(times, **ref.BOUNDED, rtol=1e-12, atol=1e-12)
    _, x, theta_hat, x_hat = run_blocks(ref.BOUNDED, 2.0, 1e-3)
    assert np.abs(theta_hat - reference["theta_hat"]).max() < 2e-6     # measured 7.5e-7 (no start-up ramp)
    assert np.abs(x_hat - reference["x_hat"]).max() < 2e-6


def test_the_true_parameters_are_a_fixed_point_and_give_the_true_state():
    """x = xi + W Theta exactly (filters (2)-(6), regression (7), estimate (10)): started at the truth,
    the observer stays there and x_hat = x while |x| grows past 100."""
    case = ref.PAPER
    start = dict(x_hat0=case["x0"], k_hat0=case["k"], b_hat0=case["b"], m_hat0=case["m"])
    _, x, theta_hat, x_hat = run_blocks(case, 6.0, 1e-3, **start)
    assert np.abs(x).max() > 100
    assert np.abs(theta_hat - ref.true_theta(**case)).max() < 1e-5    # measured 2.8e-6
    assert (np.abs(x_hat - x) / (1.0 + np.abs(x))).max() < 1e-6        # measured 2.6e-7


def test_holding_y_over_the_step_costs_accuracy():
    times = np.linspace(0.0, 3.0, 301)
    reference = ref.simulate(times, **ref.BOUNDED)
    deviation = {}
    for interpolate in (True, False):
        _, _, theta_hat, _ = run_blocks(ref.BOUNDED, 3.0, 1e-3, interpolate)
        deviation[interpolate] = np.abs(theta_hat[::10] - reference["theta_hat"]).max()
    assert deviation[True] < 2e-6                 # measured 2.5e-7
    assert deviation[False] > 1e-3                # measured 4.5e-3 (a lag of h/2)


# --- inputs inside a step -------------------------------------------------------------------

def feed(history, times, values, mode):
    """Segments as the slave builds them: interpolate (2), extrapolate (1) or hold (0)."""
    polynomials = []
    for k in range(1, len(times) - 1):
        t, h = times[k], times[k + 1] - times[k]
        if mode == "interpolate":
            segment = Segment.between([values[k]], [values[k + 1]], h)
        elif mode == "extrapolate":
            segment = Segment([values[k]], [(values[k] - values[k - 1]) / (times[k] - times[k - 1])])
        else:
            segment = Segment.hold([values[k]])
        inputs, after = history.step(t, h, {"y": segment})
        polynomials.append((t, segment, inputs["y"]))
        history = after
    return polynomials


@pytest.mark.parametrize("degree", [2, 3, 4])
def test_interpolated_inputs_become_polynomials_exact_to_their_degree(degree):
    times = np.array([0.0, 0.1, 0.25, 0.3, 0.5, 0.55, 0.7, 1.0])           # uneven steps
    polynomial = lambda t: 1.0 - 2.0 * t + 3.0 * t ** 2 - 0.5 * t ** degree   # noqa: E731
    polynomials = feed(PolynomialInputs(degree), times, polynomial(times), "interpolate")
    assert polynomials[0][2].degree == 1                                    # no history yet: the chord
    for k, (t, _, inputs) in enumerate(polynomials):
        assert inputs.degree == min(k + 1, degree)                          # the history fills up
        if inputs.degree == degree:
            for s in np.linspace(0.0, inputs.h, 7):
                assert inputs.at(s) == pytest.approx(polynomial(t + s), abs=1e-10)   # nodes kept to 1e-12 h


@pytest.mark.parametrize("mode", ["extrapolate", "hold"])
def test_held_or_extrapolated_inputs_are_left_as_they_are(mode):
    times = np.linspace(0.0, 1.0, 11)
    for t, segment, inputs in feed(PolynomialInputs(4), times, np.sin(3 * times), mode):
        assert inputs.coefficients == (segment.start[0], segment.slope[0])


def test_the_input_history_is_rebound_not_changed():
    history = PolynomialInputs(3)
    before = dict(history.samples)
    _, after = history.step(0.0, 0.1, {"y": Segment.between([1.0], [2.0], 0.1)})
    assert history.samples == before and after is not history and after.history("y") == ((0.0, 0.1), (1.0, 2.0))
    with pytest.raises(SignalError, match="input y: not finite"):
        history.step(0.0, 0.1, {"y": Segment([np.nan], [0.0])})
    with pytest.raises(ParameterError, match="input_degree: expected an integer from 1 to 5"):
        PolynomialInputs(7)


def fast_output(mu=-4.0):
    """``y' = 1500 + 2e4 t + mu sin(y)``, ``I' = sin(y)`` solved tightly (scipy DOP853): the wiggle
    that ``m f(y)`` puts on the paper case's output late in the run (|y'| ~ 1.5e3 rad/s, h = 1e-3)."""
    from scipy.integrate import solve_ivp
    return solve_ivp(lambda t, z: [1500.0 + 2e4 * t + mu * math.sin(z[0]), math.sin(z[0])], (0.0, 5e-3),
                     [2.0, 0.0], method="DOP853", rtol=1e-13, atol=1e-13, dense_output=True).sol


@pytest.mark.parametrize("degree", [2, 3, 4])
def test_resolving_the_fast_part_of_y_follows_it_between_samples(degree):
    """``f_correction``: y inside a step from its samples, the samples of ``int f(y)`` and ``mu = C^T m``."""
    mu, h, count = -4.0, 1e-3, 8
    exact = fast_output(mu)
    history = PolynomialInputs(degree)
    for k in range(4):                                   # the 4th step [3h, 4h] has the whole history
        polynomials, after = history.step(k * h, h, {"y": Segment.between([exact(k * h)[0]], [exact((k + 1) * h)[0]], h)})
        history = after if k < 3 else history
    t, times = 3 * h, after.history("y")[0]
    past = [exact(s)[1] - exact(t)[1] for s in times[:-1]]
    truth = np.array([[exact(t + (i + th) * h / count)[0] for th in SUBSTEP_POINTS] for i in range(count)])
    error = {}
    for estimate in (0.0, mu, 1.01 * mu):
        points, change = resolved_output(math.sin, polynomials["y"], times, past, estimate, count)
        error[estimate] = np.abs(np.array(points) - truth).max()
        assert change == pytest.approx(exact(t + h)[1] - exact(t)[1], abs=2e-7)   # int f(y): 1e-7 (p), 4e-10
    assert error[0.0] > 1e-4                              # the polynomial alone: 2.9e-4 to 4.9e-4
    assert error[mu] < 1e-7                               # 8.9e-9
    assert error[1.01 * mu] < 0.02 * error[0.0]           # 1 % off in mu: 1 % of the polynomial's error


def test_the_samples_of_the_integral_restart_with_the_history_and_are_rebound():
    samples = IntegralSamples(2)
    first = samples.after(0.0, 0.1, 0.5)
    second = first.after(0.1, 0.1, 0.25)
    assert samples.samples == (0, (0.0,) * 3, (0.0,) * 3) and first is not samples   # immutable, fixed layout
    assert second.at((0.0, 0.1, 0.2)) == [-0.75, -0.25, 0.0]                       # relative to the last one
    assert second.at((0.05, 0.2)) is None                                          # not a sample
    assert second.after(0.3, 0.1, 1.0).samples == (2, (0.0, 0.3, 0.4), (0.0, 0.0, 1.0))   # a gap restarts


def test_resolving_the_fast_part_changes_nothing_while_y_is_slow():
    """Bounded case, 1 s at 1e-3: with ``f_correction`` the observer stays on the reference
    (``C^T m_hat`` is far off in the first steps: the guard ``|mu| h <= 0.5`` holds it off)."""
    times = np.linspace(0.0, 1.0, 101)
    reference = ref.simulate(times, **ref.BOUNDED)
    _, _, plain, _ = run_blocks(ref.BOUNDED, 1.0, 1e-3)
    _, _, corrected, _ = run_blocks(ref.BOUNDED, 1.0, 1e-3, f_correction=True)
    assert np.abs(corrected[::10] - reference["theta_hat"]).max() < 2e-6   # 2.5e-7 (without: 2.5e-7)
    assert np.abs(corrected - plain).max() < 1e-6                          # 1.3e-8


# --- bad input: clear, early, naming the parameter -------------------------------------------

@pytest.mark.parametrize("options, message", [
    (dict(C=[1.0, 0.0, 0.0]), r"A: A\(t\) must return shape \(3, 3\)"),
    (dict(C=[0.0, 0.0]), "C: the output vector is zero"),
    (dict(C=[1.0, float("nan")]), r"C: entry \(2,\) is not finite"),
    (dict(L=lambda t: np.zeros(2)), r"L: A0\(t\) = A\(t\) - L\(t\) C\^T has the eigenvalue"),
    (dict(L=lambda t: np.zeros(3)), r"L: L\(t\) must return shape \(2,\)"),
    (dict(A="plants.ltv:A_paper"), "A: expected a function of time"),
    (dict(f=lambda y: float("nan")), r"f: f\(0\) or f\(1\) is not finite"),
    (dict(f=lambda y: np.ones((2, 2))), r"f: f\(y\) must return one number or a vector of p numbers, got shape"),
    (dict(f=lambda y: np.ones(2), unknowns=("k", "b"), m=[1.0, 2.0]), r"m: expected an n x p = 2 x 2 matrix"),
    (dict(gamma=-1.0), "gamma: must be > 0"),
    (dict(beta=0.0), "beta: must be > 0"),
    (dict(f0=float("inf")), "f0: entry"),
    (dict(x_hat0=[1.0, 2.0, 3.0]), "x_hat0: expected 2 entries"),
    (dict(max_substep=0.0), "max_substep: must be > 0"),
])
def test_observer_rejects_bad_configuration(options, message):
    arguments = dict(A=A_paper, C=C, L=L_paper, f=f_sin) | options
    with pytest.raises(ParameterError, match=message):
        LTVAdaptiveObserver(**arguments)


@pytest.mark.parametrize("options, message", [
    (dict(k=[1.0]), "k: expected 2 entries"),
    (dict(x0=[0.0, float("inf")]), r"x0: entry \(2,\) is not finite"),
    (dict(A=lambda t: np.eye(3)), r"A: A\(t\) must return shape \(2, 2\)"),
    (dict(max_dy=-1.0), "max_dy: must be > 0"),
])
def test_plant_rejects_bad_configuration(options, message):
    arguments = dict(A=A_paper, C=C, f=f_sin, **ref.BOUNDED) | options
    with pytest.raises(ParameterError, match=message):
        OutputNonlinearLTVPlant(**arguments)


def test_noise_parameters_are_checked():
    with pytest.raises(ParameterError, match="noise_std: must be >= 0"):
        SampledNoise(-0.1, 1e-3, 0)


def observer_state(o):
    return o.S.copy(), o.estimator.theta_hat.copy(), o.estimator.P.copy(), o.get_state()["inputs"]["samples"]


def test_a_non_finite_input_is_refused_and_the_state_kept():
    o = observer()
    o.advance(0.0, 1e-3, {"u": Segment.hold([0.0]), "y": Segment.between([1.0], [1.1], 1e-3)})
    before = observer_state(o)
    with pytest.raises(SignalError, match="not finite|non-finite"):
        o.advance(1e-3, 1e-3, {"u": Segment.hold([0.0]), "y": Segment.between([1.1], [float("nan")], 1e-3)})
    after = observer_state(o)
    for a, b in zip(before[:3], after[:3]):
        np.testing.assert_array_equal(a, b)
    assert before[3] == after[3]


def test_filters_growing_because_A0_is_unstable_stop_the_observer_with_a_clear_error():
    """Frozen-time checks (t = 0..10) cannot prove uniform stability; growth is caught while running."""
    def late_unstable_L(t):
        return L_paper(t) if t < 11.0 else L_paper(t) + np.array([-5.0, 0.0])   # A0 = [[5, 1], [-9, 0]]

    o = observer(L=late_unstable_L)
    step = {"u": Segment.hold([0.0]), "y": Segment.hold([0.0])}
    t = 11.0
    with pytest.raises(ParameterError, match=r"L: the filter transition matrix Phi reached .* not uniformly stable"):
        for _ in range(200):
            before = o.S.copy()
            o.advance(t, 0.1, step)
            t += 0.1
    np.testing.assert_array_equal(o.S, before)
    assert 15.0 < t < 20.0                        # |Phi| ~ e^{2.5 (t - 11)} reaches 1e8 after ~7 s
