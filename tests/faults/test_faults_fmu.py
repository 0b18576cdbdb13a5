"""Fault injection on every FMU kind of the scenarios, through fmpy's ``FMU2Slave`` (issue 13).

A refused call returns its status -- fmi2Discard for a refused step, fmi2Error for an illegal
call or a bad parameter set --, leaves the instance exactly as it was (the same serialized
state, the same outputs) and the instance keeps working: after fmi2Error at once (the binary
keeps its state machine state), after fmi2Discard from a state restored with fmi2SetFMUstate (the
step left it in stepFailed, as the FMI 2.0 standard prescribes; a master does the same).  Numbers
are drawn by hypothesis (derandomized, a few examples each).  The table of cases and statuses is
``docs/faults.md``.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faults_support import BAD_VALUES, DISCARD, ERROR, OK, LiveProbes, Probe

KINDS = ["generator-plant", "gpebo-observer", "lti-plant", "ltv-adaptive-observer", "ltv-disturbed-plant",
         "ltv-output-nonlinear-plant", "luenberger-observer", "signal-source", "sine-source", "state-affine-chemostat",
         "state-affine-observer", "state-affine-pendulum", "state-feedback", "uio-ftdrem-observer"]
WITHOUT_INPUTS = {"ltv-disturbed-plant", "signal-source", "sine-source"}
WITH_INPUTS = [kind for kind in KINDS if kind not in WITHOUT_INPUTS]
#: kinds that sub-step: a huge step must exceed their budget
SUBSTEPPING = {"ltv-adaptive-observer", "ltv-disturbed-plant", "ltv-output-nonlinear-plant",
               "state-affine-chemostat", "state-affine-observer", "state-affine-pendulum"}
DISCRETE = {"generator-plant", "gpebo-observer"}

EXAMPLES = settings(max_examples=6, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])
HUGE = st.sampled_from(BAD_VALUES) | st.floats(min_value=1.01e100, max_value=1e308) \
    | st.floats(min_value=-1e308, max_value=-1.01e100)


def test_the_kinds_are_all_the_kinds_of_the_scenarios(kind_fmus):
    assert sorted(kind_fmus) == KINDS


@pytest.fixture(scope="module")
def live(kind_fmus):
    probes = LiveProbes(kind_fmus)
    yield probes
    probes.free()


def refused_and_unchanged(probe: Probe, h: float, expected: str, level: int = DISCARD) -> None:
    """``doStep(h)`` is refused with ``expected`` logged at ``level``, which is its status (the status
    rule of TEAM.md), and changes neither state nor outputs.  After fmi2Discard the instance is in
    stepFailed; the state saved before the step is then restored (what a master does)."""
    before, outputs, mark = probe.state_bytes(), probe.outputs(), len(probe.log)
    status = probe.step(h)
    assert status == level, probe.messages(mark)
    assert [entry for entry in probe.log[mark:] if expected in entry[1] and entry[0] == level], probe.log[mark:]
    probe.assert_unchanged(before, "stepFailed" if level == DISCARD else "stepComplete")
    np.testing.assert_array_equal(probe.outputs(), outputs)
    if level == DISCARD:
        assert probe.step(h) == ERROR and "is not allowed in state stepFailed" in probe.messages(mark)
        assert probe.restore_bytes(before) == OK, probe.messages(mark)


def works(probe: Probe, step: float) -> None:
    """Good inputs again: the next step succeeds with finite outputs."""
    probe.drive_inputs(int(round(probe.t / step)), step)
    assert probe.step(step) == OK, probe.messages()
    assert np.all(np.isfinite(probe.outputs()))


# ------------------------------------------------------------------------------ inputs
@pytest.mark.parametrize("kind", WITH_INPUTS)
@pytest.mark.parametrize("what", ["value", "derivative"])
@EXAMPLES
@given(data=st.data())
def test_a_bad_input_or_input_derivative_is_refused_naming_it(live, kind, what, data):
    probe, step, _ = live(kind)
    name, value = data.draw(st.sampled_from(probe.names("input"))), data.draw(HUGE)
    probe.drive_inputs(int(round(probe.t / step)), step)
    if what == "value":                                       # setting is allowed, stepping is not
        assert probe.set(name, value) == OK
    else:
        assert probe.call(probe.slave.setRealInputDerivatives, [probe.vr(name)], [1], [value]) == OK
    refused_and_unchanged(probe, step, f"input {name} = " if what == "value" else f"input derivative der({name}) = ")
    works(probe, step)


def test_an_input_leaving_the_bound_within_the_step_is_refused(live):
    probe, step, _ = live("luenberger-observer")
    probe.set("y", 9e99)
    assert probe.call(probe.slave.setRealInputDerivatives, [probe.vr("y")], [1], [9e99]) == OK
    refused_and_unchanged(probe, 1.0, "input y at the step end (value + h * derivative) = 1.8e+100 exceeds")
    works(probe, step)


# ------------------------------------------------------------------------------ parameters
def parameter_bases(probe: Probe) -> set[str]:
    return {name.split("[")[0] for name in probe.names("parameter")}


@pytest.mark.parametrize("kind", KINDS)
@settings(EXAMPLES, max_examples=3)
@given(data=st.data())
def test_a_non_finite_or_huge_parameter_is_named_at_initialization(kind_fmus, kind, data):
    step, path = kind_fmus[kind]
    probe = Probe(path, kind, init=False)
    name, value = data.draw(st.sampled_from(probe.names("parameter"))), data.draw(HUGE)
    start = probe.get([name])[0]
    assert probe.set(name, value) == OK
    mark = len(probe.log)
    assert probe.call(probe.slave.exitInitializationMode) == ERROR
    assert f"{name} = {value:g}" in probe.messages(mark)
    # refused, nothing changed: still in initialization mode, where the parameter can be corrected
    assert probe.step(step) == ERROR and "not allowed in state initializationMode" in probe.messages(mark)
    output = probe.names("output")[0]
    assert probe.call(probe.slave.getReal, [probe.vr(output)]) == ERROR   # no valid block: no outputs either
    assert "cannot be computed: the parameters do not define a valid block" in probe.messages(mark)
    assert probe.set(name, start) == OK
    assert probe.call(probe.slave.exitInitializationMode) == OK, probe.messages(mark)
    works(probe, step)
    probe.free()


@pytest.mark.parametrize("kind", KINDS)
@settings(EXAMPLES, max_examples=4)
@given(data=st.data())
def test_zero_negative_or_extreme_parameters_never_give_a_non_finite_step(kind_fmus, kind, data):
    """Either fmi2ExitInitializationMode refuses naming a parameter, or every step succeeds with
    finite outputs within the bound, or is refused and changes nothing."""
    step, path = kind_fmus[kind]
    probe = Probe(path, kind, init=False)
    name = data.draw(st.sampled_from(probe.names("parameter")))
    value = data.draw(st.sampled_from([0.0, -1.0, -1e6, 1e6, 1e90, -1e90, 1e-300]))
    assert probe.set(name, value) == OK
    mark = len(probe.log)
    status = probe.call(probe.slave.exitInitializationMode)
    if status == ERROR:
        message = probe.messages(mark)
        assert any(base in message for base in parameter_bases(probe)), message
    else:
        assert status == OK
        for _ in range(3):
            probe.drive_inputs(int(round(probe.t / step)), step)
            before = probe.state_bytes()
            status = probe.step(step)
            assert status in (OK, DISCARD), probe.messages(mark)
            if status == DISCARD:
                probe.assert_unchanged(before, "stepFailed")
                break
            assert np.all(np.abs(probe.outputs()) <= 1e100), probe.outputs()
    probe.free()


@pytest.mark.parametrize("kind", KINDS)
def test_fixed_parameters_are_refused_after_initialization(live, kind):
    probe, step, _ = live(kind)
    name = probe.names("parameter")[0]
    old, before, mark = probe.get([name]), probe.state_bytes(), len(probe.log)
    assert probe.set(name, 2.0 * old[0] + 1.0) == ERROR
    assert "parameters are fixed after initialization" in probe.messages(mark)
    assert probe.get([name]) == old                            # the value in use is reported
    modes = [v.name for v in probe.description.modelVariables if v.name.endswith("_interpolation")]
    if modes:
        assert probe.set(modes[0], 1) == ERROR
    assert probe.set(probe.names("output")[0], 1.0) == ERROR   # outputs cannot be set
    assert "is an output" in probe.messages(mark)
    assert probe.call(probe.slave.setRealInputDerivatives, [probe.vr(name)], [1], [0.1]) == ERROR
    assert "is not a real input" in probe.messages(mark)
    assert probe.state_bytes() == before
    works(probe, step)


def test_an_invalid_value_after_initialization_cannot_kill_the_instance(kind_fmus):
    """Issue 13: ship observer ``N[1] = 0`` after initialization, then fmi2SetFMUstate."""
    step, path = kind_fmus["luenberger-observer"]
    probe = Probe(path)
    probe.run(step, 3)
    state = probe.slave.getFMUstate()
    assert probe.set("N[1]", 0.0) == ERROR
    assert probe.call(probe.slave.setFMUstate, state) == OK
    probe.run(step, 3)
    probe.slave.freeFMUstate(state)
    probe.free()


# ------------------------------------------------------------------------------ steps
@pytest.mark.parametrize("kind", KINDS)
def test_a_huge_step_returns_at_once_and_changes_nothing_when_refused(kind_fmus, kind):
    step, path = kind_fmus[kind]
    probe = Probe(path, kind)
    probe.run(step, 2)
    probe.drive_inputs(2, step)
    before, mark = probe.state_bytes(), len(probe.log)
    status = probe.step(1e6)
    if kind in SUBSTEPPING or kind in DISCRETE:             # a discrete block: 1e6 samples (issue 36: any step)
        assert status == DISCARD and "substep_budget" in probe.messages(mark), probe.messages(mark)
    assert status in (OK, DISCARD)
    if status == DISCARD:
        probe.assert_unchanged(before, "stepFailed")
        assert probe.restore_bytes(before) == OK
        works(probe, step)
    else:
        assert np.all(np.isfinite(probe.outputs()))
    mark = len(probe.log)
    assert probe.step(1e300) in (OK, DISCARD)               # issue 37: a bare "ValueError: cannot convert NaN"
    assert "ValueError" not in probe.messages(mark) and "a bug" not in probe.messages(mark), probe.messages(mark)
    probe.free()


@pytest.mark.parametrize("kind", KINDS)
def test_a_step_of_1e300_is_taken_or_refused_saying_why(live, kind):
    """Issue 37.9: ``fmi2DoStep(h = 1e300)`` was a Discard logging a bare ``ValueError: cannot convert float NaN
    to integer`` (the matrix exponential of A h) or ``LinAlgError: Singular matrix`` (an LTV block's input
    history collapsed at the scale of the step).  Now the message names the step and what to do."""
    probe, step, _ = live(kind)
    before, mark = probe.state_bytes(), len(probe.log)
    status = probe.step(1e300)
    assert status in (OK, DISCARD), probe.messages(mark)
    if status == OK:                                   # the sources: a function of time
        assert kind in WITHOUT_INPUTS | {"state-feedback"} and np.all(np.isfinite(probe.outputs()))
        assert probe.restore_bytes(before) == OK
        return
    message = probe.messages(mark)
    assert "h = 1e+300" in message and ("shorter" in message or "substep_budget" in message), message
    assert not any(bare in message for bare in ("ValueError:", "LinAlgError:", "cannot convert", "Singular")), message
    probe.assert_unchanged(before, "stepFailed")
    assert probe.restore_bytes(before) == OK


def test_the_issue_step_of_a_million_seconds_on_the_pendulum_observer(build_dir):
    """Issue 13: ``fmi2DoStep(h = 1e6)`` on the state-affine-pendulum observer never returned."""
    from obsfmu.fmus.scenarios import ensure_fmus, get
    probe = Probe(ensure_fmus(get("state-affine-pendulum"), build_dir)["state_affine_pendulum_observer"])
    refused_and_unchanged(probe, 1e6, "substep_budget: the step h = 1e+06 needs 1e+09 sub-steps of at most "
                                      "max_substep = 0.001, more than substep_budget = 1000")
    works(probe, 1e-3)
    probe.free()


@pytest.mark.parametrize("kind, model_step", [("ltv-adaptive-observer", None), ("ltv-output-nonlinear-plant", None),
                                              ("state-affine-observer", None), ("state-affine-pendulum", 1e-3),
                                              ("state-affine-chemostat", 1e-2), ("ltv-disturbed-plant", None)])
def test_the_substep_budget_is_a_parameter(kind_fmus, kind, model_step):
    """With ``substep_budget = 3`` a step needing 5 sub-steps is refused before any work."""
    step, path = kind_fmus[kind]
    probe = Probe(path, kind, start={"substep_budget": 3})
    names = probe.names("parameter")
    longest = probe.get(["max_substep"])[0] if "max_substep" in names else model_step
    h = 5 * longest if longest else 5.0            # ltv-disturbed-plant: rate-limited, far more than 5
    probe.drive_inputs(0, step)
    refused_and_unchanged(probe, h, "more than substep_budget = 3")
    works(probe, step)
    probe.free()


@pytest.mark.parametrize("h", [0.0, -1e-3, float("nan"), float("inf")])
def test_a_step_size_that_is_not_positive_and_finite_is_an_error(live, h):
    """Refused by the binary before the slave (the slave's own check serves Python callers)."""
    probe, step, _ = live("luenberger-observer")
    refused_and_unchanged(probe, h, "communicationStepSize", ERROR)
    assert "is not a positive finite number" in probe.messages(len(probe.log) - 1)
    works(probe, step)


# ------------------------------------------------------------------------------ failures inside the blocks
#: kind -> (start values, {input: value} set before the steps, step length, what the log says)
INJECTED = {
    "lti-plant": ({}, {}, 400.0, "after the step state x"),                   # the unstable plant overflows
    "luenberger-observer": ({}, {"u": 9e99, "y": 9e99}, 1e-3, "after the step state x_hat"),
    "state-feedback": ({}, {"x_hat[1]": 9e99}, 1e-3, "after the step output u"),
    "signal-source": ({"exp_amplitude": 1.0, "exp_rate": -800.0}, {}, 0.5, "after the step output y"),
    "ltv-output-nonlinear-plant": ({}, {"u": 9e99}, 1e-4, "substep_budget"),
    "ltv-adaptive-observer": ({}, {"y": 9e99}, 1e-4, "after the step state"),
    "ltv-disturbed-plant": ({"xi0[2]": 1e60}, {}, 1e-3, "substep_budget"),
    "uio-ftdrem-observer": ({}, {"y": 9e99}, 1.0, "after the step state"),
    "generator-plant": ({"gamma_theta[2]": 1e60}, {}, 1.0, "after the step state xi"),
    "gpebo-observer": ({}, {"u": 9e99, "y": 9e99}, 1.0, "after the step state"),
    "state-affine-observer": ({}, {"u": 9e99, "y": 9e99}, 1e-3, "SignalError: Delta, Y: det overflowed"),
    "state-affine-pendulum": ({"b": 1e99}, {}, 1e-3, "after the step state x"),
    "state-affine-chemostat": ({}, {"u": 9e99}, 2e-3, "SignalError: x: the step"),
}


#: kinds whose step cannot fail with parameters that pass initialization: y(t) a closed form of t alone
CANNOT_FAIL_IN_A_STEP = {"sine-source"}


def test_every_kind_that_can_fail_in_a_step_is_driven_into_failure():
    assert set(INJECTED) == set(KINDS) - CANNOT_FAIL_IN_A_STEP


@pytest.mark.parametrize("kind", sorted(INJECTED))
def test_a_failure_inside_the_block_is_discarded_and_rolled_back(kind_fmus, kind):
    """Each block kind driven into failure by its parameters or inputs: the step is refused, the
    state is unchanged, and the state of a normal run brings the instance back to normal steps."""
    step, path = kind_fmus[kind]
    normal = Probe(path, "normal")
    normal.run(step, 1)
    good, t_good = normal.state_bytes(), normal.t
    normal.free()
    start, inputs, h, expected = INJECTED[kind]
    probe = Probe(path, kind, start=start)
    for name, value in inputs.items():
        probe.set(name, value)
    for _ in range(8):                                      # some failures take a few steps to build up
        before, mark = probe.state_bytes(), len(probe.log)
        status = probe.step(h)
        if status != OK:
            break
    assert status == DISCARD, probe.messages(mark)
    assert expected in probe.messages(mark), probe.messages(mark)
    probe.assert_unchanged(before, "stepFailed")
    assert probe.restore_bytes(good, t_good) == OK           # parameters of the state included
    probe.run(step, 2)
    probe.free()


@pytest.mark.parametrize("scenario, stop_time", [("uio-ftdrem", 0.1), ("discrete-gpebo", 40.0)])
def test_a_host_that_raises_on_floating_point_errors_does_not_break_the_fmus(build_dir, scenario, stop_time):
    """numpy is shared with the importer: a host with ``np.seterr(all="raise")`` and warnings as errors
    used to turn a harmless underflow inside these observers into a failed (uio-ftdrem at 0.067 s) or
    refused (discrete-gpebo at sample 37) step.  The FMUs must run as they do under numpy's defaults,
    and leave the host's settings as they were."""
    import warnings

    from obsfmu.fmus.scenarios import run
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        old = np.seterr(all="raise")
        try:
            result, _ = run(scenario, build_dir, stop_time=stop_time)
            assert np.geterr() == {"divide": "raise", "over": "raise", "under": "raise", "invalid": "raise"}
        finally:
            np.seterr(**old)
    assert result.time[-1] == pytest.approx(stop_time)
