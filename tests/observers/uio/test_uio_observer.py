"""Paper 003 without FMI: design (3)-(4), the regressions against the true plant, stages, bad input.

The plant here is :class:`plants.uio.DisturbedLTVPlant`; ``y`` is handed to the observer
as a straight line between the plant's samples (what the FMU master's linear coupling does).
Numbers quoted in comments were measured with this code (h = 1e-3 s).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm as scipy_expm

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.uio import (GeneratorFlow, UIODesign, UIOFiniteTimeObserver, UIOSettings, check_generator,
                           check_relative_degree, uio_gain)
from obsfmu.observers.uio.harmonic import undo_filter
from obsfmu.observers.uio.regressions import RegressionSignals, frequencies_from_annihilator
from obsfmu.observers.uio.settling import SETTLED, TIMED_OUT, SettlingDetector
from obsfmu.observers.uio.signals import SignalModel
from obsfmu.plants.uio import DisturbedLTVPlant

H_STEP = 1e-3
A = np.array([[0.0, 1.0], [-2.0, 0.0]])
B = np.array([0.0, 1.0])
C = np.array([2.0, 0.0])
X0 = np.array([-1.0, 1.0])
XI0 = np.array([0.0, -1.0])
Z0 = np.array([-3.0, 3.0])
X_TILDE0 = np.array([3.0, -3.0])     # x(0) - z(0) - F G y(0) - G y'(0) = [-1, 1] - [-3, 3] - [-1, 0] - [0, 1]


def paper_observer(settings=None, **changes):
    arguments = dict(A=A, B=B, C=C, r=2, L=uio_gain(A, B, C, 2, [-0.5, -0.3]), H=np.eye(2), B_bar=[1.0, 1.0],
                     z0=Z0, xi0_free=[0, 1], xi0_known=[0, 0], harmonics=1, settings=settings)
    arguments.update(changes)
    return UIOFiniteTimeObserver(**arguments)


def paper_plant(**changes):
    arguments = dict(A=A, B=B, C=C, H=np.eye(2), Gamma=np.zeros((2, 2)), xi0=XI0, x0=X0, amplitude=[5.0],
                     omega=[1.0], phase=[0.0])
    arguments.update(changes)
    return DisturbedLTVPlant(**arguments)


def simulate(plant, observer, T, h=H_STEP):
    """Plant and observer side by side; returns times and dicts of recorded outputs."""
    steps = int(round(T / h))
    plant_rows, observer_rows = [], []
    for k in range(steps + 1):
        t = k * h
        p, o = plant.outputs(t, {}), observer.outputs(t, {})
        plant_rows.append(p)
        observer_rows.append(o)
        if k == steps:
            break
        plant.advance(t, h, {})
        y0, y1 = p["y"][0], plant.outputs(t + h, {})["y"][0]
        observer.advance(t, h, {"y": Segment(np.array([y0]), np.array([(y1 - y0) / h]))})
    stack = lambda rows: {key: np.array([row[key] for row in rows]) for key in rows[0]}  # noqa: E731
    return np.arange(steps + 1) * h, stack(plant_rows), stack(observer_rows)


# --- design (3)-(4): the paper's matrices ---------------------------------------------------------

def test_design_reproduces_the_matrices_of_the_example():
    L = uio_gain(A, B, C, 2, [-0.5, -0.3])
    d = UIODesign.create(A, B, C, 2, L)
    np.testing.assert_allclose(d.G, [0.0, 0.5], atol=1e-15)
    np.testing.assert_allclose(d.M, [[0.0, 1.0], [0.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(L, [0.4, 0.075], atol=1e-12)
    np.testing.assert_allclose(d.F, [[-0.8, 1.0], [-0.15, 0.0]], atol=1e-12)
    np.testing.assert_allclose(d.B - d.G * (C @ A @ B), 0.0, atol=1e-15)          # (3)
    assert C @ d.G == 0.0 and d.c0 == pytest.approx(1.0)                            # no y' in (9)-(10)
    np.testing.assert_allclose(d.V, np.eye(2))                                      # r = n: no zeros


def test_design_of_a_relative_degree_one_plant_keeps_its_zero_in_F():
    A1, B1, C1 = [[0.0, 1.0], [-2.0, -1.0]], [0.0, 1.0], [1.0, 1.0]                # zero at s = -1
    L = uio_gain(A1, B1, C1, 1, [-2.0])
    d = UIODesign.create(A1, B1, C1, 1, L)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(d.F).real), [-2.0, -1.0], atol=1e-12)
    assert d.V.shape == (2, 1)
    with pytest.raises(ParameterError, match=r"poles: \(M, C\) has 1 unobservable eigenvalues \[-1.0\]"):
        uio_gain(A1, B1, C1, 1, [-2.0, -3.0])


@pytest.mark.parametrize("r, message", [
    (1, r"r: rank\(C A\^0 B\) = 0 != rank B = 1"),
    (3, r"r: the relative degree must be an integer in 1..2, got 3"),
    (1.5, r"r: the relative degree must be an integer"),
])
def test_a_wrong_relative_degree_is_refused_naming_r(r, message):
    with pytest.raises(ParameterError, match=message):
        check_relative_degree(A, B, C, r)


def test_relative_degree_lower_than_claimed_is_refused():
    with pytest.raises(ParameterError, match=r"r: C A\^0 B = 1 is not 0, so the relative degree is 1, not 2"):
        check_relative_degree(A, B, [1.0, 1.0], 2)


@pytest.mark.parametrize("change, message", [
    (dict(L=[-0.4, 0.075]), r"L: not Hurwitz"),
    (dict(B_bar=[1.0, 2.0]), r"B_bar: B_bar B must be 1, got 2"),
    (dict(H=np.eye(3)), r"H: expected 2 rows"),
    (dict(A=[[0.0, np.nan], [-2.0, 0.0]]), r"A: entry \(1, 2\) is not finite"),
    (dict(xi0_free=[0, 0.5]), r"xi0_free: entries must be 0 \(known\) or 1"),
    (dict(z0=[1.0, 2.0, 3.0]), r"z0: expected 2 entries"),
    (dict(harmonics=0), r"harmonics: expected an integer >= 1"),
    (dict(settings=UIOSettings(mu=1.5)), r"mu: entries must lie in \(0, 1\)"),
    (dict(settings=UIOSettings(rates=[[10.0], [10.0], [10.0], [10.0]])), r"rates2: expected 2 entries"),
    (dict(settings=UIOSettings(filter_order=1)), r"filter_order: the filter of \(14\) needs order >= r = 2"),
    (dict(settings=UIOSettings(lambdas=(10.0, -1.0, 10.0))), r"lambda2: must be > 0"),
    (dict(Gamma=[[0.0, 1.0], [0.0, 0.0]]), r"Gamma: eigenvalue 0 on the imaginary axis is not semisimple"),
    (dict(Gamma=[[-1.0, 0.0], [0.0, 0.0]], settings=UIOSettings(lambdas=(10.0, 10.0, 0.5))),
     r"lambda3: 0.5 <= -min Re eig\(Gamma\) = 1"),
])
def test_bad_configuration_is_refused_naming_the_parameter(change, message):
    with pytest.raises(ParameterError, match=message):
        paper_observer(**change)


# --- the signal model and the regressions against the true plant -----------------------------------

def test_filtered_derivatives_of_a_sine_match_the_frequency_response():
    """p^j lam^3/(p + lam)^3 [sin w t] in steady state, from the exact propagation of the cascade."""
    lam, w, h = 10.0, 2.0, 1e-3
    model = SignalModel()
    readouts = model.lowpass(model.output(), 3, lam)
    propagator = model.propagator()
    state = np.zeros(model.size)
    steps = 4000
    for k in range(steps):
        t = k * h
        y0, y1 = np.sin(w * t), np.sin(w * (t + h))
        state = propagator.step(state, h, np.array([y0]), np.array([(y1 - y0) / h]))
    t = steps * h
    yw = np.concatenate(([np.sin(w * t)], state))
    response = (lam / (1j * w + lam)) ** 3
    for j, readout in enumerate(readouts[:3]):
        exact = np.imag((1j * w) ** j * response * np.exp(1j * w * t))
        # (h w)^2/12 = 3e-7 relative from the straight lines between samples; transient e^{-40} gone
        assert model.pad(readout)[0] @ yw == pytest.approx(exact, abs=1e-6 * w ** j)
    # p^3 F[y] contains lam^3 y itself: the states saw the lines (mean -h^2 y''/12), the feedthrough the
    # sample, so the read-out is off by lam^3 h^2 w^2 |F(jw)| / 12 (3.3e-4 here) -- why (14) uses order r + 1
    exact = np.imag((1j * w) ** 3 * response * np.exp(1j * w * t))
    bias = lam ** 3 * h ** 2 * w ** 2 * abs(response) / 12
    assert abs(model.pad(readouts[3])[0] @ yw - exact) == pytest.approx(bias, rel=0.1)


def regression_residuals(filter_order, T=12.0, h=H_STEP, xi0=XI0, unknowns=(-1.0, 1.0, -1.0), generator=None):
    """Residuals of (10), (15) and (17) with the TRUE x_tilde(0), xi(0), omega and f (``unknowns`` of (17));
    ``generator = (H, Gamma)``: a time-varying theta, every entry of ``xi(0)`` unknown."""
    plant_changes = {} if generator is None else dict(H=generator[0], Gamma=generator[1])
    unknown = {} if generator is None else dict(xi0_free=np.ones(len(xi0)), xi0_known=np.zeros(len(xi0)))
    observer = paper_observer(settings=UIOSettings(filter_order=filter_order), **plant_changes, **unknown)
    signals: RegressionSignals = observer.signals
    plant = paper_plant(xi0=xi0, **plant_changes)
    order = signals.order
    f_bar_gain = (10.0 / (1j + 10.0)) ** order          # steady state of F_2[5 sin t]
    w = signals.w0.copy()
    rows = []
    for k in range(int(round(T / h))):
        t = k * h
        y0 = plant.outputs(t, {})["y"][0]
        q1, m1 = signals.stage1(y0, w)
        stage2 = signals.stage2(y0, w, X_TILDE0, t)
        f_bar = np.imag(5.0 * f_bar_gain * np.exp(1j * t))
        rows.append([t, q1 - m1 @ X_TILDE0, stage2["q"] - stage2["s"] @ xi0 - f_bar,
                     stage2["Y"] - stage2["phi"] @ np.asarray(unknowns)])
        plant.advance(t, h, {})
        y1 = plant.outputs(t + h, {})["y"][0]
        w = signals.advance(w, h, y0, (y1 - y0) / h)
    return np.array(rows)


def test_regressions_hold_for_the_true_plant_and_decay_to_exact():
    rows = regression_residuals(None)
    t = rows[:, 0]
    assert np.max(np.abs(rows[:, 1])) < 1e-12                     # (10) exact at every sample: 5e-14
    late = t >= 6.0
    # filter transients gone; what is left is the straight-line y between samples, (h w)^2/12 relative,
    # quartering with h: (15) 4.1e-7 (1.0e-7 at h = 5e-4), (17) 2.4e-8 (1.6e-9)
    assert np.max(np.abs(rows[late, 2])) < 1e-6
    assert np.max(np.abs(rows[late, 3])) < 1e-7
    early = (t > 0.5) & (t < 1.0)
    assert np.max(np.abs(rows[early, 3])) > 1.0                   # ... but far from exact early: 254


def test_regressions_hold_with_a_time_varying_theta_of_known_generator():
    """theta_2(t) = xi_1 + xi_2(t) = -1 + 0.3 cos(0.5 t): xi_1 constant, (xi_2, xi_3) rotating at 0.5 rad/s
    (Gamma != 0), xi(0) = [-1, 0.3, 0] unknown: (15) and (17) with s = F_2[e^{Gamma^T t} H^T x] built from the
    modulated filters hold as for a constant theta (unknowns [xi(0), omega^2, omega^2 xi(0)])."""
    Gamma = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.5], [0.0, -0.5, 0.0]]
    rows = regression_residuals(None, xi0=[-1.0, 0.3, 0.0], unknowns=(-1.0, 0.3, 0.0, 1.0, -1.0, 0.3, 0.0),
                                generator=([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]], Gamma))
    t = rows[:, 0]
    assert np.max(np.abs(rows[:, 1])) < 1e-12                     # (10) does not see theta
    late = t >= 6.0
    assert np.max(np.abs(rows[late, 2])) < 1e-6                   # 4.6e-7
    assert np.max(np.abs(rows[late, 3])) < 1e-6                   # 1.1e-7
    early = (t > 0.5) & (t < 1.0)
    assert np.max(np.abs(rows[early, 3])) > 1.0                   # filter transients early: 260


@pytest.mark.parametrize("Gamma", [
    [[0.0, 0.5], [-0.5, 0.0]],                                    # a rotation: unitary eigenbasis
    [[-0.5, 1.0], [0.0, -0.5]],                                   # a stable Jordan block: expm
    [[0.0, 0.0, 0.0], [0.0, 0.0, 2.0], [0.0, -2.0, -0.1]],        # a constant and a damped rotation
])
def test_the_generator_flow_is_the_matrix_exponential(Gamma):
    flow = GeneratorFlow(check_generator(Gamma, len(Gamma)))
    for t in (0.0, 0.37, 12.5, 1e3):
        # scipy's scaling and squaring loses ~1e-15 |Gamma t| (at t = 1e3 the flow is the closer to cos(500))
        np.testing.assert_allclose(flow(t), scipy_expm(np.asarray(Gamma) * t), rtol=0, atol=1e-14 * (1 + 2 * t))


def test_paper_filter_order_leaves_a_sampling_bias_that_order_r_plus_1_removes():
    """lambda^r/(p+lambda)^r makes p^r F[y] contain y itself: lambda^r h^2 y''/12 bias (docs/paper003.md)."""
    paper_order = regression_residuals(2)
    ours = regression_residuals(3)
    late = paper_order[:, 0] >= 6.0
    assert np.max(np.abs(paper_order[late, 3])) > 1e-3            # 3.0e-3 (7.5e-4 at h = 5e-4)
    assert np.max(np.abs(ours[late, 3])) < 1e-7                   # 2.4e-8


# --- the stages on the paper's example ---------------------------------------------------------------

@pytest.fixture(scope="module")
def paper_run():
    return simulate(paper_plant(), paper_observer(), 12.0)


def test_stage1_is_exact_in_finite_time(paper_run):
    t, plant, observer = paper_run
    error = np.abs(observer["x_tilde0_hat"] - X_TILDE0).max(axis=1)
    switch = observer["t_identified"][-1, 0]
    assert 0.03 < switch < 0.1                                     # 0.056 s
    assert np.all(error[t >= switch + 1e-9] < 1e-12)               # 1.9e-14
    assert error[int(round(0.03 / H_STEP))] > 1.0                  # not before the switch


def test_stages_2_to_4_converge_and_report_it(paper_run):
    t, plant, observer = paper_run
    status, times = observer["identified"][-1], observer["t_identified"][-1]
    np.testing.assert_array_equal(status, [SETTLED] * 4)
    assert 4.0 < times[1] < times[2] < times[3] < 9.0              # 6.55, 7.05, 7.56 s
    after = t >= 10.0
    assert np.max(np.abs(observer["omega_hat"][after] - 1.0)) < 1e-8                 # 3.3e-9
    assert np.max(np.abs(observer["xi0_hat"][after] - XI0)) < 1e-7                   # 3.4e-8
    assert np.max(np.abs(observer["f_hat"][after] - plant["f"][after])) < 2e-6       # 5.8e-7
    x, x_hat = plant["x"][after], observer["x_hat"][after]
    assert np.max(np.linalg.norm(x_hat - x, axis=1) / (1 + np.linalg.norm(x, axis=1))) < 1e-6   # 1.2e-7
    # before stage 4, x_hat is the derivative-free part z_bar + F G y: x2 = y'/2 is missing
    before = (t > 0.1) & (t < times[2] - 0.01)               # stage 4 starts with stage 3
    np.testing.assert_allclose(observer["x_hat"][before, 0], plant["x"][before, 0], atol=1e-10)
    np.testing.assert_allclose(observer["x_hat"][before, 1], 0.0, atol=1e-10)


@pytest.mark.parametrize("case", ["r1", "r3"])
def test_other_relative_degrees(case):
    """r = 1 (one zero, at -1) and r = 3 (no zero); their weaker excitation needs larger gains."""
    if case == "r1":
        A_, B_, C_, r, poles = np.array([[0.0, 1.0], [-2.0, -1.0]]), [0.0, 1.0], [1.0, 1.0], 1, [-2.0]
        xi0, x0, gamma = [0.0, -1.0], np.array([-1.0, 1.0]), (1e6, 1e10, 1e6, 1e6)
    else:
        A_ = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -2.0, -2.0]])
        B_, C_, r, poles = [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], 3, [-1.0, -1.5, -2.0]
        xi0, x0, gamma = [0.0, 0.0, -1.0], np.array([1.0, 0.0, -1.0]), (1e12, 1e10, 1e6, 1e10)
    n = len(x0)
    L = uio_gain(A_, B_, C_, r, poles)
    d = UIODesign.create(A_, B_, C_, r, L)
    # start the chain so that x_tilde(0) is observable (the zero's component would decay at e^{-t})
    z0 = x0 - d.G_i[0] * (C_ @ x0) - sum(G * (C_ @ np.linalg.matrix_power(A_, i) @ x0)
                                         for i, G in enumerate(d.G_i) if i > 0) - d.V @ np.ones(d.V.shape[1])
    observer = UIOFiniteTimeObserver(A_, B_, C_, r, L, np.eye(n), B_, z0, np.eye(n)[-1], np.zeros(n), 1,
                                     UIOSettings(gamma=gamma))
    plant = DisturbedLTVPlant(A_, B_, C_, np.eye(n), np.zeros((n, n)), xi0, x0, [2.0], [1.5], [0.3])
    t, p, o = simulate(plant, observer, 12.0)
    np.testing.assert_array_equal(o["identified"][-1], [SETTLED] * 4)
    after = t >= 10.0
    assert np.max(np.abs(o["omega_hat"][after] - 1.5)) < 1e-6              # r1 1.1e-8, r3 1.4e-7
    assert np.max(np.abs(o["xi0_hat"][after] - xi0)) < 1e-5                # r1 2.2e-7, r3 4.6e-7
    assert np.max(np.abs(o["f_hat"][after] - p["f"][after])) < 1e-4        # r1 6.5e-7, r3 3.4e-6
    x, x_hat = p["x"][after], o["x_hat"][after]
    assert np.max(np.linalg.norm(x_hat - x, axis=1) / (1 + np.linalg.norm(x, axis=1))) < 1e-5


# --- run-time errors leave the state untouched ----------------------------------------------------------

def test_nan_input_is_refused_and_the_state_is_unchanged():
    observer = paper_observer()
    segment = {"y": Segment(np.array([1.0]), np.array([0.5]))}
    for k in range(50):
        observer.advance(k * H_STEP, H_STEP, segment)
    before = observer.outputs(0.05, {})
    with pytest.raises(SignalError, match="input y"):
        observer.advance(0.05, H_STEP, {"y": Segment(np.array([np.nan]), np.array([0.0]))})
    after = observer.outputs(0.05, {})
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])


def test_a_failure_inside_a_step_restores_the_state(monkeypatch):
    observer = paper_observer()
    segment = {"y": Segment(np.array([1.0]), np.array([0.5]))}
    for k in range(50):
        observer.advance(k * H_STEP, H_STEP, segment)
    w, stage1 = observer.w.copy(), observer.stage[0].theta_drem.copy()

    def fail(*args, **kwargs):
        raise FloatingPointError("injected")
    monkeypatch.setattr(type(observer.stage[1]), "update", fail)  # after stage 1 has updated
    with pytest.raises(FloatingPointError, match="injected"):
        observer.advance(0.05, H_STEP, segment)
    np.testing.assert_array_equal(observer.w, w)
    np.testing.assert_array_equal(observer.stage[0].theta_drem, stage1)


def test_state_save_and_restore_reproduces_the_continuation():
    observer = paper_observer()
    segment = {"y": Segment(np.array([1.0]), np.array([0.5]))}
    for k in range(30):
        observer.advance(k * H_STEP, H_STEP, segment)
    saved = observer.get_state()
    for k in range(30, 60):
        observer.advance(k * H_STEP, H_STEP, segment)
    first = observer.outputs(0.06, {})
    observer.set_state(saved)
    for k in range(30, 60):
        observer.advance(k * H_STEP, H_STEP, segment)
    for key, value in observer.outputs(0.06, {}).items():
        np.testing.assert_array_equal(value, first[key])


# --- pieces ---------------------------------------------------------------------------------------------

def test_settling_detector_settles_only_when_quiet_and_times_out():
    detector = SettlingDetector(tol=1e-3, window=0.5, timeout=5.0)
    for k in range(10):
        detector.update(0.1 * k, np.array([1.0 + 0.1 * k]), ready=True)     # moving: not settled
    assert not detector.done
    for k in range(10, 16):
        detector.update(0.1 * k, np.array([2.0]), ready=True)
    assert detector.status == SETTLED and detector.time == pytest.approx(1.5)
    never = SettlingDetector(tol=1e-3, window=0.5, timeout=2.0)
    for k in range(25):
        never.update(0.1 * k, np.array([float(k)]), ready=True)
    assert never.status == TIMED_OUT and never.time == pytest.approx(2.0)


def test_the_timeout_does_not_depend_on_how_the_host_sums_its_steps():
    """Issue 28: importers that accumulate t += h reach 9.999999999999897 at 10 s (h = 1e-3): the stage
    timeout at t = 10 fired one step late there, so x_hat differed by up to 1 around the switch."""
    summed, exact = (SettlingDetector(tol=1e-3, window=0.5, timeout=10.0) for _ in range(2))
    t = 0.0
    for k in range(1, 10001):
        t += 1e-3
        summed.update(t, np.array([float(k)]), ready=True)
        exact.update(k * 1e-3, np.array([float(k)]), ready=True)
    assert t < 10.0 and summed.status == exact.status == TIMED_OUT
    assert summed.time == t and exact.time == 10.0                # both at the step that reaches 10 s


def test_frequencies_from_the_annihilator_and_undoing_the_filter():
    # (p^2 + 1)(p^2 + 4) = p^4 + 5 p^2 + 4
    np.testing.assert_allclose(frequencies_from_annihilator([4.0, 5.0]), [1.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(frequencies_from_annihilator([2.25]), [1.5])
    # f_bar = a1 sin + a2 cos of F = lam^3/(p + lam)^3 [f]  =>  f = Im((a1 + j a2)((j w + lam)/lam)^3 e^{j w t})
    a, w, lam = np.array([0.3, -1.2]), 2.0, 10.0
    b = undo_filter(a, [w], lam, 3)
    t = 0.7
    expected = np.imag((a[0] + 1j * a[1]) * ((1j * w + lam) / lam) ** 3 * np.exp(1j * w * t))
    assert b @ [np.sin(w * t), np.cos(w * t)] == pytest.approx(expected, rel=1e-13)


def test_plant_with_time_varying_parameters_matches_a_radau_solution():
    """Plant (1) with Gamma != 0 and two sinusoids against solve_ivp on [x; xi] (independent)."""
    from scipy.integrate import solve_ivp

    Gamma = np.array([[0.0, 0.5], [-0.5, 0.0]])
    amplitude, omega, phase = np.array([2.0, 0.5]), np.array([1.0, 3.0]), np.array([0.2, -1.0])
    plant = paper_plant(Gamma=Gamma, xi0=[0.3, -1.0], amplitude=amplitude, omega=omega, phase=phase)

    def rhs(t, s):
        x, xi = s[:2], s[2:]
        f = np.sum(amplitude * np.sin(omega * t + phase))
        return np.concatenate([A @ x + B * (xi @ x + f), Gamma @ xi])

    T = 5.0
    exact = solve_ivp(rhs, (0.0, T), np.concatenate([X0, [0.3, -1.0]]), method="Radau", rtol=1e-12,
                      atol=1e-12, dense_output=True)
    for k in range(int(round(T / H_STEP))):
        plant.advance(k * H_STEP, H_STEP, {})
    out = plant.outputs(T, {})
    np.testing.assert_allclose(out["x"], exact.sol(T)[:2], atol=1e-9)          # 4e-12
    np.testing.assert_allclose(out["xi"], exact.sol(T)[2:], atol=1e-12)
    np.testing.assert_allclose(out["theta"], out["xi"])                           # H = I
    assert out["f"][0] == pytest.approx(np.sum(amplitude * np.sin(omega * T + phase)))
    np.testing.assert_array_equal(out["f_omega"], omega)


def test_plant_measurement_noise_is_added_to_y_only():
    from obsfmu.plants.signals import SampledNoise

    plant = paper_plant(noise=SampledNoise(1e-3, 1e-3, 7))
    out = plant.outputs(0.5, {})
    assert out["y"][0] != C @ out["x"] and abs(out["y"][0] - C @ out["x"]) < 1e-2


@pytest.mark.parametrize("change, message", [
    (dict(H=np.eye(3)), r"H: expected 2 rows"),
    (dict(Gamma=np.eye(3)), r"Gamma: expected 2 rows"),
    (dict(omega=[1.0, 2.0]), r"omega: expected 1 entries, got 2"),
    (dict(omega=[-1.0]), r"omega: frequencies must be >= 0"),
    (dict(x0=[np.inf, 0.0]), r"x0: entry \(1,\) is not finite"),
])
def test_bad_plant_parameters_are_refused_naming_them(change, message):
    with pytest.raises(ParameterError, match=message):
        paper_plant(**change)


def test_excitation_shows_the_stages_adapting_now(paper_run):
    """Issue 36: `excitation` read 0 while stages 2-3 adapted (stage 4, not started, counted as 0).  Now it is
    the smallest |Delta| of the stages started and not identified: positive while stages 2-3 adapt, between
    stage 1's switch and stage 4's start."""
    t, _, observer = paper_run
    excitation, times = observer["excitation"][:, 0], observer["t_identified"][-1]
    adapting = (t > times[0] + 0.01) & (t < times[2] - 0.01)       # stage 1 identified, stage 4 not started
    assert np.all(excitation[adapting] > 0.0)
    assert np.all(np.isfinite(excitation)) and np.all(excitation >= 0.0)
