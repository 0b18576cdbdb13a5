"""Algebraic loops (fmus/master/loops.py): found from the FMUs' declared dependencies, solved at every
communication point, refused with their path when they have no solution -- against hand-solved values and
an exact closed-loop solution."""

import numpy as np
import pytest

import obsfmu
from obsfmu.fmus.master.errors import SimulationError


def gain(k: float, c: float) -> dict:
    """A block ``y = k u + c`` (direct feedthrough) with one dummy state."""
    return dict(kind="expression", inputs=1, parameters={"k": k, "c": c}, f=["-x[1]"], h=["k * u[1] + c"])


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("loops")


def self_loop(k: float, c: float) -> obsfmu.System:
    return obsfmu.System("selfloop", stop_time=0.005, step=1e-3).add("a", gain(k, c)).connect("a.y", "a.u")


def test_a_loop_without_a_solution_is_refused_naming_its_path(build_dir):
    """y = u + 1 fed back has no solution: an error at t = 0, not y = 2, 3, 5, ..."""
    with pytest.raises(SimulationError, match=r"algebraic loop a\.y -> a\.u -> a\.y has no unique solution"):
        obsfmu.run(self_loop(1.0, 1.0), build_dir=build_dir)


@pytest.mark.parametrize("order, fmi_version", [("gauss-seidel", 2), ("jacobi", 2), ("gauss-seidel", 3)])
def test_a_self_loop_is_solved_at_every_point(build_dir, order, fmi_version):
    """y = 0.5 u + 1 with u = y: y = 2 at every point, t = 0 included (a fixed-point settle gave 1.9375)."""
    result = obsfmu.run(self_loop(0.5, 1.0), build_dir=build_dir, order=order, fmi_version=fmi_version)
    assert np.max(np.abs(result["a.y"] - 2.0)) < 1e-12


def test_a_loop_through_two_blocks_and_its_report(build_dir, capfd):
    """a.y = 0.5 b.y + 1, b.y = 0.25 a.y + 3: a.y = 2.5 / 0.875, b.y = 0.25 a.y + 3; the run notes the loop."""
    system = (obsfmu.System("twoloop", stop_time=0.003, step=1e-3).add("a", gain(0.5, 1.0)).add("b", gain(0.25, 3.0))
              .connect("a.y", "b.u").connect("b.y", "a.u"))
    result = obsfmu.run(system, build_dir=build_dir)
    a = 2.5 / 0.875
    assert np.max(np.abs(result["a.y"] - a)) < 1e-12
    assert np.max(np.abs(result["b.y"] - (0.25 * a + 3.0))) < 1e-12
    assert "algebraic loop a.y -> b.u -> b.y -> a.u -> a.y solved at" in capfd.readouterr().err


def test_a_plant_with_feedthrough_under_proportional_control_agrees_with_the_exact_solution(build_dir):
    """x' = -x + u, y = x + 0.5 u (D != 0) under u = Kp (r - y), Kp = 4, r = 1: the loop gives
    u = Kp (r - x) / (1 + 0.5 Kp), x(t) = 4/7 (1 - exp(-7 t / 3)).  Measured: 8.9e-7 at h = 1 ms, 8.8e-5 at
    10 ms (the linear coupling's h^2); u and y consistent with x to round-off at every point."""
    system = (obsfmu.System("pcontrol", stop_time=2.0, step=1e-3)
              .add("plant", kind="lti", A=[[-1.0]], B=[[1.0]], C=[[1.0]], D=[[0.5]])
              .add("controller", kind="expression", inputs=1, parameters={"Kp": 4.0, "r": 1.0}, f=["0"],
                   h=["Kp * (r - u[1])"])
              .connect("plant.y", "controller.u").connect("controller.y", "plant.u"))
    result = obsfmu.run(system, build_dir=build_dir)
    t, x, u, y = result.time, result["plant.x[1]"], result["controller.y"], result["plant.y"]
    assert np.max(np.abs(x - 4.0 / 7.0 * (1.0 - np.exp(-7.0 * t / 3.0)))) < 2e-6
    assert np.max(np.abs(u - 4.0 * (1.0 - x) / 3.0)) < 1e-11
    assert np.max(np.abs(y - (x + 0.5 * u))) < 1e-11
