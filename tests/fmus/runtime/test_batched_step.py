"""``obsfmuDoStepBatched``: the binary's one-call step (issue 14) is exactly the four FMI calls it stands for.

``fmi2SetReal(vr, u); fmi2SetRealInputDerivatives(vr, 1, du); fmi2DoStep(t, h); fmi2GetReal(out, y)``
and the batched call are run side by side on two instances of the same FMU, for every block kind:
the outputs and the serialized states must agree bit for bit, step after step -- with every
input given, with a subset of them (the others held by their ``_interpolation`` mode), in another
order, and without derivatives.  Faults keep their statuses and messages (docs/faults.md): a NaN
input is a Discard naming it with nothing changed, an unknown value reference or a call out of
the state machine is an Error that leaves the instance as it was; the outputs are written only
when the step is taken.
"""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from fmpy import read_model_description

from faults_support import DISCARD, ERROR, OK, Probe, split_state

KINDS_WITH_INPUTS = ["gpebo-observer", "lti-plant", "ltv-adaptive-observer", "ltv-output-nonlinear-plant",
                     "luenberger-observer", "state-affine-chemostat", "state-affine-observer",
                     "state-affine-pendulum", "state-feedback", "uio-ftdrem-observer", "generator-plant"]
STEPS = 6


def batched(probe: Probe):
    """The binary's ``obsfmuDoStepBatched`` with its argument types."""
    function = probe.slave.dll.obsfmuDoStepBatched
    pointer, size = ctypes.c_void_p, ctypes.c_size_t
    function.argtypes = [pointer, ctypes.c_double, ctypes.c_double, pointer, size, pointer, pointer, pointer, size,
                         pointer]
    function.restype = ctypes.c_int
    return function


class StepPlan(ctypes.Structure):
    """``ObsfmuStepPlan`` of fmus/native/loader.c, declared here independently of the master's."""
    _fields_ = [("vr", ctypes.c_void_p), ("nvr", ctypes.c_size_t), ("value", ctypes.c_void_p),
                ("slope", ctypes.c_void_p), ("output_vr", ctypes.c_void_p), ("n_outputs", ctypes.c_size_t),
                ("output", ctypes.c_void_p)]


def planned(probe: Probe):
    """The binary's ``obsfmuDoStepPlanned``: ``obsfmuDoStepBatched`` with its arrays in a struct."""
    function = probe.slave.dll.obsfmuDoStepPlanned
    function.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.POINTER(StepPlan)]
    function.restype = ctypes.c_int
    return function


def call_batched(probe: Probe, h: float, names, values, slopes, outputs: np.ndarray, form: str = "batched") -> int:
    """One batched step of ``probe`` at its time (``slopes`` None: no derivatives), by ``obsfmuDoStepBatched``
    or, ``form="planned"``, ``obsfmuDoStepPlanned``; its status."""
    vr = np.array([probe.vr(n) for n in names], dtype=np.uint32)
    out_vr = np.array([probe.vr(n) for n in probe.names("output")], dtype=np.uint32)
    values = np.ascontiguousarray(values, dtype=float)
    slopes = None if slopes is None else np.ascontiguousarray(slopes, dtype=float)
    arrays = (vr.ctypes.data, len(vr), values.ctypes.data, None if slopes is None else slopes.ctypes.data,
              out_vr.ctypes.data, len(out_vr), outputs.ctypes.data)
    if form == "planned":
        status = planned(probe)(probe.slave.component, probe.t, h, ctypes.byref(StepPlan(*arrays)))
    else:
        status = batched(probe)(probe.slave.component, probe.t, h, *arrays)
    if status in (OK, 1):
        probe.t += h
    return status


def signal(k: int, step: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    t = k * step
    return (np.array([0.1 * np.sin(0.7 * t + i) for i in range(count)]),
            np.array([0.07 * np.cos(0.7 * t + i) for i in range(count)]))


def separate_calls(probe: Probe, h: float, names, values, slopes) -> int:
    vrs = [probe.vr(n) for n in names]
    status = probe.call(probe.slave.setReal, vrs, list(values))
    if slopes is not None and status == OK:
        status = probe.call(probe.slave.setRealInputDerivatives, vrs, [1] * len(vrs), list(slopes))
    return probe.step(h) if status == OK else status


@pytest.fixture(scope="module")
def pairs(kind_fmus):
    """``kind -> (step, path)`` of the kinds with inputs; instances are made per test."""
    return {kind: kind_fmus[kind] for kind in KINDS_WITH_INPUTS}


@pytest.mark.parametrize("kind", KINDS_WITH_INPUTS)
@pytest.mark.parametrize("variant", ["all inputs", "reversed order", "first input only", "no derivatives",
                                     "derivatives, then none",     # the inputs recorded, then read by a step
                                     "first input only, the others interpolated"])
@pytest.mark.parametrize("form", ["batched", "planned"])
def test_the_batched_step_is_bit_for_bit_the_four_calls(pairs, kind, variant, form):
    step, path = pairs[kind]
    start = {}
    if variant == "first input only, the others interpolated":     # recorded at the step end, not its start
        variables = read_model_description(str(path)).modelVariables
        first, *others = [v.name.split("[")[0] for v in variables if v.causality == "input"]
        modes = {v.name for v in variables} & {f"{port}_interpolation" for port in others if port != first}
        start = dict.fromkeys(modes, 2)
    separate, together = Probe(path, "separate", start), Probe(path, "together", start)
    try:
        names = separate.names("input")
        if variant == "reversed order":
            names = names[::-1]
        elif variant.startswith("first input only"):
            names = names[:1]
        outputs = np.full(len(together.names("output")), np.nan)
        for k in range(STEPS):
            values, slopes = signal(k, step, len(names))
            slopes = None if variant == "no derivatives" or (variant == "derivatives, then none" and k >= STEPS // 2) \
                else slopes
            assert separate_calls(separate, step, names, values, slopes) == OK, separate.messages()
            assert call_batched(together, step, names, values, slopes, outputs, form) == OK, together.messages()
            np.testing.assert_array_equal(outputs, separate.outputs())
            np.testing.assert_array_equal(together.outputs(), separate.outputs())
        assert split_state(together.state_bytes()) == split_state(separate.state_bytes())
    finally:
        separate.free()
        together.free()


@pytest.fixture(scope="module")
def observer(kind_fmus):
    step, path = kind_fmus["luenberger-observer"]
    probe = Probe(path, "batched")
    yield probe, step
    probe.free()


def test_a_nan_input_is_discarded_naming_it_and_changes_nothing(observer):
    probe, step = observer
    names = probe.names("input")
    outputs = np.full(len(probe.names("output")), 7.0)
    before, mark = probe.state_bytes(), len(probe.log)
    values, slopes = signal(0, step, len(names))
    values[0] = np.nan
    assert call_batched(probe, step, names, values, slopes, outputs) == DISCARD
    assert f"input {names[0]} = nan is not finite" in probe.messages(mark)
    assert np.all(outputs == 7.0)                                  # not written: no step was taken
    assert split_state(probe.state_bytes())[0] == "stepFailed"     # as after fmi2DoStep's Discard
    assert probe.restore_bytes(before) == OK
    values[0] = 0.0
    assert call_batched(probe, step, names, values, slopes, outputs) == OK, probe.messages(mark)
    assert np.all(np.isfinite(outputs)) and not np.all(outputs == 7.0)


@pytest.mark.parametrize("form", ["batched", "planned"])
def test_a_step_whose_result_leaves_the_bound_is_discarded_with_outputs_untouched(kind_fmus, form):
    """Inputs within the bound whose outputs are beyond it (the controller's ``u = -K x_hat + r``): the step
    is computed, tested, rolled back and refused as by fmi2DoStep, and the caller's output vector is not
    written."""
    step, path = kind_fmus["state-feedback"]
    probe = Probe(path, "beyond")
    names = probe.names("input")
    outputs = np.full(len(probe.names("output")), 7.0)
    before, mark = probe.state_bytes(), len(probe.log)
    values, slopes = np.full(len(names), 2e99), np.zeros(len(names))   # |(values, slopes)| < 1e100: the
    assert call_batched(probe, step, names, values, slopes, outputs, form) == DISCARD   # whole-vector path
    assert "after the step output u = " in probe.messages(mark), probe.messages(mark)
    assert np.all(outputs == 7.0)
    assert split_state(probe.state_bytes())[0] == "stepFailed"     # as after fmi2DoStep's Discard
    assert probe.restore_bytes(before) == OK
    values, slopes = signal(0, step, len(names))
    assert call_batched(probe, step, names, values, slopes, outputs, form) == OK, probe.messages(mark)
    assert np.all(np.isfinite(outputs)) and not np.all(outputs == 7.0)
    probe.free()


def test_a_null_plan_is_an_error(observer):
    probe, step = observer
    mark = len(probe.log)
    assert planned(probe)(probe.slave.component, probe.t, step, None) == ERROR
    assert "obsfmuDoStepPlanned: NULL plan" in probe.messages(mark)


def test_an_unknown_value_reference_is_an_error_that_changes_nothing(observer):
    probe, step = observer
    before, mark = probe.state_bytes(), len(probe.log)
    outputs = np.zeros(len(probe.names("output")))
    vr = np.array([987654], dtype=np.uint32)
    out_vr = np.array([probe.vr(n) for n in probe.names("output")], dtype=np.uint32)
    value = np.zeros(1)
    status = batched(probe)(probe.slave.component, probe.t, step, vr.ctypes.data, 1, value.ctypes.data, None,
                            out_vr.ctypes.data, len(out_vr), outputs.ctypes.data)
    assert status == ERROR and "value reference 987654 is not a real input" in probe.messages(mark)
    probe.assert_unchanged(before)                                # refused: still stepComplete, same state
    names = probe.names("input")
    assert call_batched(probe, step, names, *signal(1, step, len(names)), outputs) == OK, probe.messages(mark)


def test_the_state_machine_and_the_communication_point_are_checked(kind_fmus):
    step, path = kind_fmus["luenberger-observer"]
    probe = Probe(path, "early", init=False)
    try:
        names = probe.names("input")
        outputs = np.zeros(len(probe.names("output")))
        mark = len(probe.log)
        assert call_batched(probe, step, names, *signal(0, step, len(names)), outputs) == ERROR
        assert "obsfmuDoStepBatched is not allowed in state initializationMode" in probe.messages(mark)
        assert call_batched(probe, step, names, *signal(0, step, len(names)), outputs, "planned") == ERROR
        assert "obsfmuDoStepPlanned is not allowed in state initializationMode" in probe.messages(mark)
        probe.slave.exitInitializationMode()
        probe.t = 1.0                                              # not the FMU's time
        assert call_batched(probe, step, names, *signal(0, step, len(names)), outputs) == ERROR
        assert "is not the FMU's current time" in probe.messages(mark)
        probe.t = 0.0
        assert call_batched(probe, -step, names, *signal(0, step, len(names)), outputs) == ERROR
        assert call_batched(probe, step, names, *signal(0, step, len(names)), outputs) == OK, probe.messages(mark)
    finally:
        probe.free()


def test_null_arrays_are_an_error_that_changes_nothing(observer):
    """A caller that gives counts without arrays is refused by name, in both forms, before anything moves."""
    probe, step = observer
    before, mark = probe.state_bytes(), len(probe.log)
    outputs = np.zeros(len(probe.names("output")))
    out_vr = np.array([probe.vr(n) for n in probe.names("output")], dtype=np.uint32)
    assert batched(probe)(probe.slave.component, probe.t, step, None, 1, None, None, out_vr.ctypes.data,
                          len(out_vr), outputs.ctypes.data) == ERROR
    assert "obsfmuDoStepBatched: NULL value references or values for 1 variables" in probe.messages(mark)
    plan = StepPlan(None, 0, None, None, out_vr.ctypes.data, len(out_vr), None)
    assert planned(probe)(probe.slave.component, probe.t, step, ctypes.byref(plan)) == ERROR
    assert f"obsfmuDoStepPlanned: NULL value references or values for {len(out_vr)} variables" in probe.messages(mark)
    probe.assert_unchanged(before)
