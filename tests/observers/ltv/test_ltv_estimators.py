"""The estimators of the paper-001 observer (least squares, DREM, gradient) and their diagnostics.

Block level, on the mass-spring-damper of examples/ltv_mass_spring_damper.toml (observer canonical
coordinates, unknowns ``k`` and ``x(0)``).  For each estimator: its guaranteed bound covers the true
error at every step (so ``converged`` is never early), and it converges where it should.
"""

import copy
import math

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.ltv import LTVAdaptiveObserver
from obsfmu.observers.ltv.estimators import DELTA_FLOOR, ESTIMATORS
from obsfmu.plants.ltv import OutputNonlinearLTVPlant

C = [1.0, 0.0]
K, B, M, X0 = [-0.6, -4.0], [0.0, 1.0], [0.0, -0.5], [0.5, 0.3]
THETA = np.array([-X0[0], -X0[1], *K])
STEPPING = {"input_degree": 3, "max_substep": 5e-3}
GAINS = {"least-squares": {"gamma": 1000.0, "beta": 0.5}, "drem": {"gamma": 100.0}, "gradient": {"gamma": 1000.0}}


def A(t):
    return np.array([[0.0, 1.0], [0.0, 0.0]])


def L(t):
    return np.array([0.0, 9.0])


def cube(y):
    return y ** 3


def force(t):
    return 2.0 * math.sin(2 * math.pi * 0.1 * t) + math.sin(2 * math.pi * 0.37 * t)


def observer(estimator, **options):
    return LTVAdaptiveObserver(A, C, L, cube, unknowns=("k",), b=B, m=M, theta_bound=5.0, estimator=estimator,
                               **GAINS[estimator], **STEPPING, **options)


def stepped(p, o, T, h):
    """Plant then observer for ``T / h`` steps, inputs interpolated over each step: ``(t + h, observer outputs)``."""
    for i in range(int(round(T / h))):
        t = i * h
        y0 = p.outputs(t, {})["y"]
        u = Segment.between([force(t)], [force(t + h)], h)
        p.advance(t, h, {"u": u})
        o.advance(t, h, {"u": u, "y": Segment.between(y0, p.outputs(t + h, {})["y"], h)})
        yield t + h, o.outputs(t + h, {})


def run(estimator, T, h=1e-2):
    """Plant then observer, interpolated inputs; per step the true error, the bound and the flag."""
    p = OutputNonlinearLTVPlant(A, C, cube, K, B, M, X0, **STEPPING)
    o = observer(estimator)
    rows = []
    for t, out in stepped(p, o, T, h):
        error = float(np.linalg.norm(out["theta_hat"] - THETA))
        rows.append((t, error, o.estimator.error_bound(o.initial_error), out["converged"][0],
                     out["excitation"][0], float(np.abs(out["x_hat"] - p.x).max())))
    return np.array(rows)


@pytest.fixture(scope="module", params=ESTIMATORS)
def history(request):
    return request.param, run(request.param, 25.0)


#: the error floor of the 1e-2 s steps (the regression is exact only to it: 7.3e-7 LS, 7.6e-7 DREM at 25 s), which
#: the exact-regression bounds do not see -- a tolerance far above it is what the flag needs.  DREM's normalised
#: gain moves the estimate to Y / Delta at once, so it sees the floor divided by Delta (measured: error above the
#: bound by at most 2.4e-5, at 1.36 s)
FLOOR = {"least-squares": 2e-6, "drem": 5e-5, "gradient": 2e-6}


def test_the_bound_covers_the_true_error_so_converged_is_never_early(history):
    estimator, rows = history
    t, error, bound, converged, excitation, _ = rows.T
    assert np.all(error <= bound + FLOOR[estimator]), estimator
    assert np.all(error[converged == 1] <= 1e-3), estimator
    assert np.all(excitation >= 0), estimator


def test_least_squares_and_drem_converge_and_flag_it_the_gradient_is_slow(history):
    """LS (gamma 1000, beta 0.5) and DREM (gamma 100, a = 1, the normalised gain's default floor) identify x(0)
    and k to 1e-3 and say so; the gradient (gamma 1000) on the same badly conditioned regression is still far
    off at 25 s."""
    estimator, rows = history
    t, error, _, converged, excitation, state = rows.T
    if estimator == "gradient":
        assert error[-1] > 0.1 and not converged.any() and 0 < excitation[-1] < 1
        return
    first = t[np.argmax(converged == 1)]
    assert converged[-1] == 1 and error[-1] < 1e-6 and state[-1] < 1e-6
    assert first < {"least-squares": 9.0, "drem": 2.0}[estimator]      # 8.6 s and 1.28 s (raw DREM gain: 21.9 s)
    assert np.all(converged[t >= first] == 1)


def run_six_unknowns(delta_floor, T=14.0, h=1e-2):
    """k and m unknown besides x(0) (6 unknowns), DREM with gamma 100: ``(t, |Theta_hat - Theta|, converged)``."""
    p = OutputNonlinearLTVPlant(A, C, cube, K, B, M, X0, **STEPPING)
    o = LTVAdaptiveObserver(A, C, L, cube, unknowns=("k", "m"), b=B, theta_bound=5.0, estimator="drem", gamma=100.0,
                            delta_floor=delta_floor, **STEPPING)
    theta = np.array([-X0[0], -X0[1], *K, *M])
    rows = [(t, np.linalg.norm(out["theta_hat"] - theta), out["converged"][0]) for t, out in stepped(p, o, T, h)]
    return np.array(rows).T


def test_drem_with_six_unknowns_converges_with_the_normalised_default_and_not_with_the_raw_gain():
    """Issue 36: Delta of 6 unknowns is ~1e-8, so the raw gain gamma Delta^2 never moves the estimates; the
    normalised gain gamma / (delta_floor^2 + Delta^2) with its default floor identifies them, honestly flagged."""
    t, error, converged = run_six_unknowns(DELTA_FLOOR)
    first = t[np.argmax(converged == 1)]
    assert converged[-1] == 1 and first < 11.0                     # measured 9.34 s
    assert np.all(error[converged == 1] <= 1e-3)                   # measured at most 3.1e-4
    assert error[-1] < 1e-5                                        # measured 7.6e-7 (the regression's floor)
    _, raw_error, raw_converged = run_six_unknowns(0.0, T=6.0)
    assert raw_error.min() > 4.0 and not raw_converged.any()       # measured 4.12 throughout


def test_drem_commits_its_extension_only_with_the_step():
    o = observer("drem")
    before = o.estimator.extension.Phi_e
    twin = copy.copy(o.estimator)
    twin.update(np.ones(2), np.ones((2, 4)), 0.1)
    assert o.estimator.extension.Phi_e is before and twin.extension.Phi_e is not before


def test_a_regression_error_bound_is_refused_for_drem_and_gradient():
    for estimator in ("drem", "gradient"):
        with pytest.raises(ParameterError, match=f"^regression_error_bound: the {estimator} estimator"):
            observer(estimator, regression_error_bound=0.1)
    with pytest.raises(ParameterError, match="^estimator: expected one of"):
        LTVAdaptiveObserver(A, C, L, cube, estimator="kalman")
