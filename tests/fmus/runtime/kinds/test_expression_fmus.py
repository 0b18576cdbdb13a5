"""The expression plant kind (fmus/runtime/kinds/expression.py) and the discrete LTI plant as FMUs,
against solutions written here: scipy's solve_ivp of the same equations, hand loops of the recurrences."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import read_model_description
from scipy.integrate import solve_ivp

from obsfmu.fmus.master import Component, Connection, System, cosimulate
from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
from obsfmu.fmus.runtime.kinds.linear import plant_definition
from obsfmu.fmus.runtime.kinds.sources import sine_source_definition
from faults_support import DISCARD, OK, Probe
from kinds_support import build_all, simulate, started
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import ExpressionError
from obsfmu.observers.lti_model import StateSpace

G, L, C = 9.81, 0.5, 0.2
DISCRETE_A = [[0.9, 0.1], [0.0, 0.8]]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build_all([
        expression_plant_definition("pendulum", ["x[2]", "-g / l * sin(x[1]) - c * x[2] + u[1]"], ["x[1]"], [0.5, 0.0],
                                    inputs=1, parameters={"g": G, "l": L, "c": C},
                                    parameter_units={"g": "m/s2", "l": "m", "c": "1/s"},
                                    state_units=["rad", "rad/s"], output_units=["rad"], input_units=["rad/s2"]),
        expression_plant_definition("logistic", ["r * x[1] * (1 - x[1]) + 0.01 * u[1]"], ["x[1]", "p[1] * x[1]"],
                                    [0.2], inputs=1, parameters={"r": 3.7}, sample_time=0.1),
        expression_plant_definition("falling", ["-1"], ["log(x[1])"], [0.45]),
        plant_definition("dlti", StateSpace.checked(DISCRETE_A, [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]], dt=0.1),
                         [1.0, 0.0], {}, ""),
        sine_source_definition("drive", amplitude=0.8, frequency_hz=0.7, unit="rad/s2"),
    ], tmp_path_factory.mktemp("expressions"))


def pendulum(t, x, c=C, u=lambda t: 0.0):
    return [x[1], -G / L * math.sin(x[0]) - c * x[1] + u(t)]


def reference(stop, times, **options):
    solution = solve_ivp(lambda t, x: pendulum(t, x, **options), (0.0, stop), [0.5, 0.0], method="DOP853",
                         rtol=1e-12, atol=1e-13, t_eval=times)
    return solution.y.T


def test_a_damped_pendulum_fmu_follows_scipy(fmus):
    result = simulate(fmus["pendulum"], 3.0, 0.01)
    x = np.column_stack([result["x[1]"], result["x[2]"]])
    np.testing.assert_allclose(x, reference(3.0, result["time"]), rtol=0, atol=1e-9)   # RK4, sub-steps of 1e-3
    np.testing.assert_array_equal(result["y"], result["x[1]"])
    changed = simulate(fmus["pendulum"], 3.0, 0.01, c=1.0)                 # a named parameter, set as a start value
    np.testing.assert_allclose(changed["x[1]"], reference(3.0, changed["time"], c=1.0)[:, 0], rtol=0, atol=1e-9)


def test_a_driven_pendulum_cosimulated_with_a_sine_source_follows_scipy(fmus):
    """Gauss-Seidel, linear coupling: the plant's input is the sine interpolated over each step h = 1e-3 s,
    an error of at most h^2/8 max|u''| = 1.9e-6 in u, which the velocity integrates over T = 3 s: the stated
    tolerance on x is T h^2/8 max|u''| = 5.8e-6 (RK4's own error is below 1e-9)."""
    system = System([Component("drive", fmus["drive"]), Component("plant", fmus["pendulum"])],
                    [Connection("drive.y", "plant.u")])
    result = cosimulate(system, 3.0, 1e-3)
    drive = lambda t: 0.8 * math.sin(2 * math.pi * 0.7 * t)
    expected = reference(3.0, result.time, u=drive)
    bound = 3.0 * 1e-3 ** 2 / 8 * 0.8 * (2 * math.pi * 0.7) ** 2
    np.testing.assert_allclose(result.vector("plant.x"), expected, rtol=0, atol=bound)


def test_parameters_and_units_in_the_model_description(fmus):
    description = read_model_description(str(fmus["pendulum"]))
    variables = {v.name: v for v in description.modelVariables}
    assert {name for name, v in variables.items() if v.causality == "parameter"} == \
        {"g", "l", "c", "x0[1]", "x0[2]", "max_substep", "rtol", "atol", "substep_budget", "u_interpolation"}
    assert (variables["g"].unit, variables["x[2]"].unit, variables["y"].unit, variables["u"].unit) == \
        ("m/s2", "rad/s", "rad", "rad/s2")
    assert not description.outputs[0].dependencies                         # h does not read u
    assert "sample_time" in {v.name for v in read_model_description(str(fmus["logistic"])).modelVariables}


@pytest.mark.parametrize("settings, message", [
    ({"f": ["x[2]", "__import__('os')"]}, r"^components\.p\.f\[2\].*unknown function"),
    ({"f": ["x[2]", "-k * x[1]"]}, r"^components\.p\.f\[2\].*unknown name"),
    ({"h": ["x[3]"]}, r"^components\.p\.h\[1\].*index out of range"),
    ({"h": ["x.real"]}, r"^components\.p\.h\[1\].*not allowed"),
    ({"f": ["x[2]"]}, r"^components\.p\.f: expected 2 expressions"),
    ({"parameters": {"x0": 1.0}}, r"^components\.p\.parameters: 'x0' cannot name"),
    ({"parameters": {"c": "fast"}}, r"^components\.p\.parameters\.c: expected a finite number"),
    ({"max_substep": 0.0}, r"^components\.p\.max_substep"),
    ({"parameters": {"y": 1.0}}, r"^components\.p\.parameters: 'y' cannot name"),
    ({"state_units": ["m", "m/s", "s"]}, r"^components\.p\.state_units: expected 2 units"),
])
def test_a_bad_expression_or_setting_is_refused_at_build_time_naming_the_field(settings, message):
    arguments = {"f": ["x[2]", "-c * x[2]"], "h": ["x[1]"], "x0": [0.0, 1.0], "parameters": {"c": 1.0},
                 "field_prefix": "components.p.", **settings}
    with pytest.raises((ExpressionError, ParameterError), match=message):
        expression_plant_definition("p", **arguments)


def test_a_nan_at_run_time_is_a_discarded_step_naming_the_output(fmus):
    probe = Probe(fmus["falling"], "falling")
    try:
        assert [probe.step(0.1) for _ in range(5)] == [OK, OK, OK, OK, DISCARD]   # x(0.5) = -0.05: log gives NaN
        assert probe.get(["x[1]"]) == [pytest.approx(0.05)]                      # the state as before the step
    finally:
        probe.free()
    assert "do_step(t=0.4, h=0.1) refused, state unchanged: after the step output y = nan is not finite" \
        in probe.messages()


def _log_of_steps(path, h: float, count: int) -> str:
    """The log of an instance of ``path`` that takes ``count`` steps of length ``h``, all accepted."""
    probe = Probe(path, "discrete")
    try:
        assert [probe.step(h) for _ in range(count)] == [OK] * count
    finally:
        probe.free()
    return probe.messages()


def test_a_discrete_expression_plant_steps_whole_samples_as_a_hand_loop(fmus):
    result = simulate(fmus["logistic"], 2.0, 0.2, u=0.5)
    x, expected = 0.2, []
    for k in range(21):
        if k % 2 == 0:
            expected.append(x)
        x = 3.7 * x * (1 - x) + 0.01 * 0.5
    np.testing.assert_allclose(result["x[1]"], expected, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(result["y[2]"], 3.7 * np.array(expected), rtol=1e-14)
    finer = simulate(fmus["logistic"], 2.0, 0.025, u=0.5)           # four steps per sample: held in between
    np.testing.assert_allclose(finer["x[1]"][::8], expected, rtol=1e-14, atol=1e-15)
    assert "lies inside" not in _log_of_steps(fmus["logistic"], 0.025, 8)   # every instant a communication point
    assert "sample instant t = 0.1 lies inside the communication step [0, 0.15]" \
        in _log_of_steps(fmus["logistic"], 0.15, 2)                    # taken, with a warning (issue 36)


def test_a_discrete_lti_plant_steps_whole_samples_as_a_hand_loop(fmus):
    result = simulate(fmus["dlti"], 2.0, 0.2, u=1.0)
    A, B = np.array(DISCRETE_A), np.array([0.0, 1.0])
    x, expected = np.array([1.0, 0.0]), []
    for k in range(21):
        if k % 2 == 0:
            expected.append(x)
        x = A @ x + B
    np.testing.assert_allclose(np.column_stack([result["x[1]"], result["x[2]"]]), expected, rtol=1e-13, atol=1e-15)
    finer = simulate(fmus["dlti"], 2.0, 0.05, u=1.0)
    np.testing.assert_allclose(np.column_stack([finer["x[1]"], finer["x[2]"]])[::4], expected, rtol=1e-13,
                               atol=1e-15)
    assert "sample instant t = 0.1 lies inside the communication step [0, 0.25]" in _log_of_steps(fmus["dlti"], 0.25, 2)
    names = {v.name for v in read_model_description(str(fmus["dlti"])).modelVariables}
    assert {"sample_time", "substep_budget"} <= names


def test_a_continuous_lti_definition_is_unchanged_by_the_discrete_option():
    model = StateSpace.checked([[0.0, 1.0], [-2.0, -0.5]], [[0.0], [1.0]], [[1.0, 0.0]], [[0.0]])
    definition = plant_definition("plant", model, [1.0, 0.0], {}, "")
    assert [p.name for p in definition.parameters] == ["A", "B", "C", "D", "x0"]
    assert definition.description == "LTI plant x' = A x + B u, y = C x + D u (exact step for linear inputs)"


def test_an_fmu_state_saved_serialized_and_restored_gives_the_same_steps_again(fmus):
    slave, refs = started(fmus["pendulum"], "pendulum")
    outputs = [refs["x[1]"], refs["x[2]"]]

    def run(t):
        values = []
        for k in range(20):
            slave.setReal([refs["u"]], [math.cos(t)])
            slave.doStep(t, 0.01)
            t += 0.01
            values.append(slave.getReal(outputs))
        return values
    try:
        run(0.0)
        saved = slave.getFMUstate()
        data = slave.serializeFMUstate(saved)
        first = run(0.2)
        slave.setFMUstate(slave.deSerializeFMUstate(data))
        assert run(0.2) == first
        slave.freeFMUstate(saved)
    finally:
        slave.terminate()
        slave.freeInstance()


def test_fmus_without_output_derivatives_refuse_them(fmus):
    slave, refs = started(fmus["pendulum"], "pendulum")
    try:
        slave.doStep(0.0, 0.01)
        with pytest.raises(Exception, match="status 3"):
            slave.getRealOutputDerivatives([refs["y"]], [1])
        slave.doStep(0.01, 0.01)                                   # refused, nothing changed: it goes on
    finally:
        slave.terminate()
        slave.freeInstance()
    assert read_model_description(str(fmus["pendulum"])).coSimulation.maxOutputDerivativeOrder == 0
