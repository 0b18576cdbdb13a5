"""Paper 004 observer as plain blocks (no FMI): validation, the regression identity, the reference.

The monolithic reference (``fmus/scenarios/state_affine_common/reference.py``) is independent code; here the
blocks are driven by a small loop that passes ``y`` and ``u`` as straight lines over each step,
as the co-simulation master does with linear coupling.
"""

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.modal import observer_gain
from obsfmu.observers.state_affine import StateAffineModel, StateAffineObserver
from obsfmu.plants import state_affine as ex
from obsfmu.fmus.scenarios.state_affine_common import reference as ref


def pendulum_model(**changes):
    arguments = dict(q=2, p=2, l=0, n=2, ny=1, nu=1, Lambda=ex.PENDULUM_LAMBDA, Psi=ex.pendulum_Psi,
                     w=ex.pendulum_w, phi=ex.pendulum_phi, c=ex.pendulum_c, phi_L=ex.pendulum_phi_L,
                     C=ex.PENDULUM_C, L=observer_gain(ex.PENDULUM_LAMBDA, ex.PENDULUM_C, [2j, -2j]))
    arguments.update(changes)
    return StateAffineModel(**arguments)


def chemostat_model(**changes):
    arguments = dict(q=2, p=1, l=0, n=2, ny=1, nu=1, Lambda=ex.chemostat_Lambda, Psi=ex.chemostat_Psi,
                     w=ex.chemostat_w, phi=ex.chemostat_phi, c=ex.chemostat_c, phi_L=ex.chemostat_phi_L)
    arguments.update(changes)
    return StateAffineModel(**arguments)


def pendulum_observer(**changes):
    settings = dict(rates=ref.PENDULUM["rates"], gamma=ref.PENDULUM["gamma"], gamma_x=ref.PENDULUM["gamma_x"])
    settings.update(changes)
    return StateAffineObserver(pendulum_model(), **settings)


def drive(plant, observer, u_of, h, stop, every):
    """Step plant and observer together; record ``(t, x, x_hat, theta_hat)`` every ``every`` steps."""
    records = []
    steps = int(round(stop / h))
    for k in range(steps + 1):
        t = k * h
        if k % every == 0:
            out = observer.outputs(t, {})
            records.append((t, plant.x.copy(), out["x_hat"], out["theta_hat"]))
        if k == steps:
            break
        u = Segment.between([u_of(t)], [u_of(t + h)], h)
        y0 = plant.outputs(t, {})["y"]
        plant.advance(t, h, {"u": u})
        observer.advance(t, h, {"y": Segment.between(y0, plant.outputs(t + h, {})["y"], h), "u": u})
    return [np.array(column) for column in zip(*records)]


# ----------------------------------------------------------------------------- the user's model is checked
def _psi_wrong(y, u):
    return np.zeros((2, 1))


def _phi_three(y, u):
    return np.zeros(3)


def _lambda_3x3(y, u):
    return np.zeros((3, 3))


def _phi_L_three(chi, theta):
    return np.zeros(3)


def _w_nan(y, u):
    return np.array([0.0, np.nan])


@pytest.mark.parametrize("changes, message", [
    (dict(Psi=_psi_wrong), r"Psi: .*_psi_wrong returned shape \(2, 1\), expected \(2, 2\) \(q x p\)"),
    (dict(phi=_phi_three), r"phi: .*returned shape \(3,\), expected \(2,\) \(l \+ q entries"),
    (dict(phi_L=_phi_L_three), r"phi_L: .*returned shape \(3,\), expected \(2,\)"),
    (dict(p=3), r"Psi: .*returned shape \(2, 2\), expected \(2, 3\)"),
    (dict(Lambda=np.eye(3)), r"Lambda: expected shape \(2, 2\) \(q x q\), got \(3, 3\)"),
    (dict(C=[[1.0, 0.0, 0.0]]), r"C: expected 2 columns"),
    (dict(L=[[1.0, 2.0]]), r"L: expected 2 rows"),
    (dict(Psi=None), r"Psi: expected a function"),
    (dict(q=0), r"q: expected an integer >= 1"),
    (dict(w=_w_nan), r"w: .*non-finite value .*\(at the probe point"),
    (dict(C=None), r"C, L: a constant Lambda \(Statement 2\) needs"),
])
def test_model_with_mismatched_dimensions_is_refused(changes, message):
    with pytest.raises(ParameterError, match=message):
        pendulum_model(**changes)


def test_time_varying_model_is_checked_too():
    with pytest.raises(ParameterError, match=r"Lambda: .*_lambda_3x3 returned shape \(3, 3\), expected \(2, 2\)"):
        chemostat_model(Lambda=_lambda_3x3)
    with pytest.raises(ParameterError, match="C, L: only for a constant Lambda"):
        chemostat_model(C=[[0.0, 1.0]], L=[[0.0], [1.0]])


def test_unobservable_pair_is_refused():
    """Statement 2 needs (Lambda, C) observable (Assumption 6): measuring the velocity-like chi_2 is not."""
    with pytest.raises(ParameterError, match=r"C: the pair \(Lambda, C\) is not observable \(rank .* 1 < q = 2\)"):
        pendulum_model(C=[[0.0, 1.0]], L=[[0.0], [1.0]])


@pytest.mark.parametrize("L, message", [
    ([[-1.0], [4.0]], r"Lambda - L C: eigenvalue .* has a positive real part"),
    ([[0.0], [0.0]], r"Lambda - L C: eigenvalue 0.* Jordan block, .* grow like t"),
])
def test_growing_filters_are_refused(L, message):
    with pytest.raises(ParameterError, match=message):
        pendulum_model(L=L)


def test_hurwitz_injection_is_accepted():
    model = pendulum_model(L=observer_gain(ex.PENDULUM_LAMBDA, ex.PENDULUM_C, [-2.0, -3.0]))
    assert np.allclose(np.sort(np.linalg.eigvals(model.Lambda_L).real), [-3.0, -2.0])


@pytest.mark.parametrize("changes, message", [
    (dict(rates=[1.0, 2.0, 3.0]), r"rates: expected k = l \+ q \+ p = 4 filter rates"),
    (dict(rates=[1.0, 2.0, 2.0, 3.0]), r"rates: expected distinct a_i > 0"),
    (dict(rates=[1.0, 2.0, -3.0, 4.0]), r"rates: expected distinct a_i > 0"),
    (dict(gamma=0.0), r"gamma: must be > 0"),
    (dict(gamma_x=np.inf), r"gamma_x: entry \(1,\) is not finite|gamma_x: .*not finite"),
    (dict(mu=1.0), r"mu: must lie in \(0, 1\)"),
    (dict(chi_hat0=[0.0]), r"chi_hat0: expected 2 entries"),
    (dict(theta_hat0=[0.0, 1.0, 2.0]), r"theta_hat0: expected 2 entries"),
])
def test_bad_observer_settings_are_refused(changes, message):
    with pytest.raises(ParameterError, match=message):
        pendulum_observer(**changes)


def _w_explodes(y, u):
    return np.array([0.0, u[0] if abs(u[0]) < 100 else np.nan])


def test_non_finite_model_value_leaves_the_state_unchanged():
    observer = StateAffineObserver(pendulum_model(w=_w_explodes), [0.5, 2, 8, 32], 1e10, 1e10)
    line = {"y": Segment.between([0.1], [0.2], 1e-3), "u": Segment.between([1.0], [2.0], 1e-3)}
    observer.advance(0.0, 1e-3, line)
    before = observer.get_state()
    with pytest.raises(SignalError, match=r"w: .*_w_explodes returned a non-finite value"):
        observer.advance(1e-3, 1e-3, {"y": line["y"], "u": Segment.between([1.0], [500.0], 1e-3)})
    after = observer.get_state()
    for name, value in before.items():
        np.testing.assert_array_equal(after[name], value, err_msg=name)
    observer.advance(1e-3, 1e-3, line)      # and it keeps working
    assert np.all(np.isfinite(observer.chi_hat))


# ----------------------------------------------------------------------------- the regression
def test_extended_regression_is_exact_and_chi_enters_only_through_the_identity_rows():
    """Mixing gives Y = Delta col(chi(t), e(0), theta_p) along a plant trajectory (derivation check),
    and the paper's filtered rows alone have parallel chi-columns (why the identity rows are needed)."""
    plant = ex.Pendulum(9.81, 0.5, [0.5, 0.0])
    observer = pendulum_observer()
    u_of = ref.sines(**ref.PENDULUM["u"])
    chi0 = np.array([0.5, 0.0 + 0.5 * 0.5])
    h, checked = 2.5e-4, 0
    for k in range(int(round(3.0 / h))):
        t = k * h
        u = Segment.between([u_of(t)], [u_of(t + h)], h)
        y0 = plant.x[:1].copy()
        plant.advance(t, h, {"u": u})
        observer.advance(t, h, {"y": Segment.between(y0, plant.x[:1], h), "u": u})
        if k % 400 == 399 and abs(observer.delta) > 1e-6:
            chi = np.array([plant.x[0], plant.x[1] + 0.5 * plant.x[0]])
            unknowns = np.concatenate([chi, chi0, [0.5, 9.81]])
            np.testing.assert_allclose(observer.mixed / observer.delta, unknowns, atol=2e-6)
            checked += 1
    assert checked >= 4
    parametrization = observer.parametrization
    _, Psi_e = parametrization.regression(observer.filters)
    filtered_chi_columns = Psi_e[:parametrization.k, parametrization.chi]
    assert np.linalg.matrix_rank(filtered_chi_columns, tol=1e-9) == 1       # y = C chi: all parallel to C
    assert np.linalg.matrix_rank(Psi_e) == parametrization.N


# ----------------------------------------------------------------------------- against the reference
def test_pendulum_block_matches_the_monolithic_reference():
    reference = ref.cached("pendulum", 20.0, 0.01)
    plant = ex.Pendulum(9.81, 0.5, ref.PENDULUM["x0"])
    t, x, x_hat, theta_hat = drive(plant, pendulum_observer(), ref.sines(**ref.PENDULUM["u"]), 5e-4, 5.0, 20)
    rows = slice(0, t.size)
    np.testing.assert_allclose(t, reference["time"][rows], atol=1e-12)
    assert np.abs(x - reference["x"][rows]).max() < 2e-6            # measured 1.1e-6 (u held as a chord)
    assert np.abs(theta_hat - reference["theta_hat"][rows]).max() < 5e-5   # measured 2.2e-5
    assert np.abs(x_hat - reference["x_hat"][rows]).max() < 1.5e-5        # measured 4.9e-6
    assert np.abs(theta_hat[-1] - [0.5, 9.81]).max() < 5e-6                # measured 5.6e-7
    assert np.abs(x_hat[-1] - x[-1]).max() < 2e-6                          # measured 3.1e-7


def test_chemostat_block_matches_the_monolithic_reference():
    reference = ref.cached("chemostat", 30.0, 0.01)
    plant = ex.Chemostat(10.0, ref.CHEMOSTAT["x0"])
    observer = StateAffineObserver(chemostat_model(), ref.CHEMOSTAT["rates"], ref.CHEMOSTAT["gamma"],
                                   ref.CHEMOSTAT["gamma_x"])
    t, x, x_hat, theta_hat = drive(plant, observer, ref.sines(**ref.CHEMOSTAT["u"]), 1e-3, 8.0, 10)
    rows = slice(0, t.size)
    assert np.abs(x - reference["x"][rows]).max() < 2e-7                   # measured 8.3e-8
    assert np.abs(theta_hat - reference["theta_hat"][rows]).max() < 1e-5   # measured 3.1e-6
    assert np.abs(x_hat - reference["x_hat"][rows]).max() < 5e-6           # measured 1.3e-6
    assert np.abs(theta_hat[-1] - 10.0).max() < 1e-6                       # measured 1.5e-7
    assert np.abs(x_hat[-1] - x[-1]).max() < 5e-7                          # measured 8.5e-8


# ----------------------------------------------------------------------------- theta_l: relation (3) with unknowns
OMEGA, BIAS = 2.0, 0.3


def _oscillator_Lambda(y, u):
    return np.array([[0.0, OMEGA], [-OMEGA, 0.0]])


def _oscillator_w(y, u):
    return np.array([0.0, u[0]])


def _biased_phi(y, u):
    return np.array([1.0, 1.0, 0.0])        # theta_l + chi_1 = y: a sensor with unknown offset


def _biased_c(y, u):
    return y[0]


def _identity(chi, theta):
    return np.array(chi, dtype=float)


class _Oscillator:
    """chi' = [[0, w], [-w, 0]] chi + (0, u), y = chi_1 + bias (RK4, for the loop of :func:`drive`)."""

    def __init__(self, x0):
        self.x = np.array(x0, dtype=float)

    def outputs(self, t, inputs):
        return {"y": np.array([self.x[0] + BIAS])}

    def advance(self, t, h, inputs):
        f = lambda x, s: _oscillator_Lambda(None, None) @ x + _oscillator_w(None, inputs["u"].at(s))  # noqa: E731
        for i in range(4):
            s, d = i * h / 4, h / 4
            k1 = f(self.x, s)
            k2 = f(self.x + d / 2 * k1, s + d / 2)
            k3 = f(self.x + d / 2 * k2, s + d / 2)
            k4 = f(self.x + d * k3, s + d)
            self.x = self.x + d / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")   # scipy's numerical Jacobian probing
def test_unknown_parameter_of_the_algebraic_relation_statement_1():
    """l = 1, p = 0, time-varying form: an oscillator read by a sensor with an unknown offset.

    ``gamma_x Delta^2 dt`` reaches 36: the observer step must land on ``chi`` at the end of the
    step (a forcing held over the step would lag by ``dt/2``: 1e-3 here)."""
    model = StateAffineModel(q=2, p=0, l=1, n=2, ny=1, nu=1, Lambda=_oscillator_Lambda, Psi=None, w=_oscillator_w,
                             phi=_biased_phi, c=_biased_c, phi_L=_identity)
    example = ref.Example(name="oscillator", q=2, p=0, l=1, plant=lambda x, u, true: _oscillator_Lambda(0, 0) @ x
                          + np.array([0.0, u]), output=lambda x: x[0] + BIAS,
                          Lambda=lambda y, u: _oscillator_Lambda(0, 0), Psi=lambda y, u: np.zeros((2, 0)),
                          w=lambda y, u: np.array([0.0, u]), phi=lambda y, u: np.array([1.0, 1.0, 0.0]),
                          c=lambda y, u: y, phi_L=lambda chi, th: np.array(chi))
    settings = dict(rates=[1.0, 3.0, 9.0], gamma=1e8, gamma_x=1e8)
    u_of = ref.sines(amplitude=[1.0], omega=[1.3])
    times = np.round(np.arange(401) * 0.01, 12)
    reference = ref.Monolithic(example, {}, **settings).simulate(np.array([1.0, -0.5]), u_of, times)
    observer = StateAffineObserver(model, **settings)
    t, x, x_hat, theta_hat = drive(_Oscillator([1.0, -0.5]), observer, u_of, 1e-3, 4.0, 10)
    assert np.abs(reference["theta_hat"][-1] - BIAS).max() < 1e-9
    assert np.abs(reference["x_hat"][-1] - x[-1]).max() < 1e-6
    assert np.abs(theta_hat - reference["theta_hat"]).max() < 2e-5     # measured 5.7e-6
    assert np.abs(x_hat - reference["x_hat"]).max() < 1e-5             # measured 3.6e-6
    assert abs(theta_hat[-1, 0] - BIAS) < 1e-6 and np.abs(x_hat[-1] - x[-1]).max() < 2e-6   # 2e-8, 4e-7
    assert observer.switch_time is not None and observer.switch_time < 1.0                  # 0.446
