"""plants/expression.py against independent solutions of the same equations written by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import SignalError
from obsfmu.observers.expressions import Names, Source, compile_vector
from obsfmu.plants.expression import ExpressionPlant

DUFFING = Names(x=2, u=1, p=4, parameters={"delta": 1, "alpha": 2, "beta": 3, "gain": 4})
P = np.array([0.3, -1.0, 1.0, 0.8])


def duffing_plant(**options) -> ExpressionPlant:
    f = compile_vector(["x[2]", "-delta * x[2] - alpha * x[1] - beta * x[1] ** 3 + gain * u[1]"], DUFFING,
                       Source("plant.f"))
    h = compile_vector(["x[1]"], DUFFING, Source("plant.h"))
    return ExpressionPlant(f, h, P, [1.0, 0.0], inputs=1, **options)


def test_a_duffing_oscillator_follows_an_accurate_scipy_solution_with_a_linear_input():
    u = lambda t: 0.5 * math.sin(1.2 * t)                        # the input the master interpolates linearly
    delta, alpha, beta, gain = P

    def rhs(t, x, t0, h):                                       # the same input: linear between samples
        s = (t - t0) / h
        v = (1 - s) * u(t0) + s * u(t0 + h)
        return [x[1], -delta * x[1] - alpha * x[0] - beta * x[0] ** 3 + gain * v]

    plant, step, x_ref = duffing_plant(max_substep=1e-3), 0.01, np.array([1.0, 0.0])
    worst = 0.0
    for k in range(500):
        t = k * step
        plant.advance(t, step, {"u": Segment.between([u(t)], [u(t + step)], step)})
        x_ref = solve_ivp(rhs, (t, t + step), x_ref, args=(t, step), method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
        worst = max(worst, float(np.max(np.abs(plant.x - x_ref))))
    assert worst < 1e-9, worst
    np.testing.assert_allclose(plant.outputs(5.0, {"u": np.array([0.0])})["y"], [plant.x[0]])


def test_a_discrete_plant_steps_sample_by_sample_as_a_hand_loop():
    names = Names(x=2, u=1, p=1, parameters={"r": 1})
    f = compile_vector(["r * x[1] * (1 - x[1]) + 0.01 * u[1]", "0.5 * x[2] + x[1]"], names, Source("plant.f"))
    plant = ExpressionPlant(f, compile_vector(["x[2]"], names, Source("plant.h")), [3.7], [0.2, 0.0], inputs=1,
                            sample_time=0.1)
    x = [0.2, 0.0]
    for k in range(0, 40, 4):                                   # four samples per communication step
        t = k * 0.1
        plant.advance(t, 0.4, {"u": Segment(np.array([math.cos(t)]), np.array([2.0]))})
        for j in range(4):
            uj = math.cos(t) + (j * 0.1) * 2.0
            x = [3.7 * x[0] * (1 - x[0]) + 0.01 * uj, 0.5 * x[1] + x[0]]
        np.testing.assert_allclose(plant.x, x, rtol=1e-14, atol=1e-15)
    # any step (issue 36): [4, 4.15) latches u at 4.0 and 4.1, [4.15, 4.4) at 4.2 and 4.3, each from its own line;
    # the update of t_k is applied when t_(k+1) is reached
    def sample(x, uj):
        return [3.7 * x[0] * (1 - x[0]) + 0.01 * uj, 0.5 * x[1] + x[0]]
    plant.advance(4.0, 0.15, {"u": Segment(np.array([0.3]), np.array([-1.0]))})
    x = sample(x, 0.3)                                         # the instant 4.0, applied at 4.1; 4.1 pending
    np.testing.assert_allclose(plant.x, x, rtol=1e-14, atol=1e-15)
    plant.advance(4.15, 0.25, {"u": Segment(np.array([0.7]), np.array([4.0]))})
    for uj in (0.3 - 0.1, 0.7 + 0.05 * 4.0, 0.7 + 0.15 * 4.0):  # 4.1 (latched in the step before), 4.2, 4.3
        x = sample(x, uj)
    np.testing.assert_allclose(plant.x, x, rtol=1e-14, atol=1e-15)


def test_feedthrough_exactly_when_the_output_reads_the_input():
    assert not duffing_plant().feedthrough
    f = compile_vector(["-x[1]"], Names(x=1, u=1), Source("plant.f"))
    plant = ExpressionPlant(f, compile_vector(["x[1] + 2 * u[1]"], Names(x=1, u=1), Source("plant.h")), [], [1.0], 1)
    assert plant.feedthrough
    assert plant.outputs(0.0, {"u": np.array([3.0])})["y"][0] == 7.0
    assert plant.output_sizes == {"y": 1, "x": 1} and plant.input_sizes == {"u": 1}


def test_a_plant_without_inputs_and_bad_sizes():
    f = compile_vector(["-x[1] + sin(t)"], Names(x=1), Source("plant.f"))
    plant = ExpressionPlant(f, compile_vector(["x[1]"], Names(x=1), Source("plant.h")), [], [0.0], 0)
    assert plant.input_sizes == {}
    plant.advance(0.0, 1.0, {})
    exact = 0.5 * (math.sin(1.0) - math.cos(1.0) + math.exp(-1.0))     # x' = -x + sin t, x(0) = 0
    assert abs(plant.x[0] - exact) < 1e-12
    with pytest.raises(ValueError, match="x0: expected 1 entries, got 2"):
        ExpressionPlant(f, f, [], [0.0, 1.0], 0)


def test_a_stiff_expression_plant_is_right_or_refused_by_name(tmp_path):
    """f = -2700 x (issue 37: plain RK4 at max_substep 1e-3 gave x(0.05) = 1.6e-3, exact 2e-59): within
    1e-7 relative + 1e-11 of exp(-2700 t) at every point (measured: 1.1e-8 relative at 1 ms, 1.5e-15 at the end); with a budget too small for the tolerance, refused naming substep_budget."""
    import obsfmu
    from obsfmu.fmus.master.errors import SimulationError
    system = obsfmu.System("stiff", stop_time=0.05, step=1e-3).add(
        "plant", kind="expression", f=["-2700 * x[1]"], h=["x[1]"], x0=[1.0])
    result = obsfmu.run(system, build_dir=tmp_path)
    exact = np.exp(-2700.0 * result.time)
    assert np.all(np.abs(result["plant.x[1]"] - exact) <= 1e-7 * exact + 1e-11)
    with pytest.raises(SimulationError, match="substep_budget = 20 sub-steps to keep the local error within rtol"):
        obsfmu.run(system, build_dir=tmp_path, set={"plant.rtol": 1e-14, "plant.substep_budget": 20})
