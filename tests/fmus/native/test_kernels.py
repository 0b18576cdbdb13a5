"""Compiled step kernels (issue 39): linear blocks step in C inside the FMU, with the Python path's results.

The same FMUs run twice in one process, with their kernel and with ``OBSFMU_KERNELS=python`` (read by the bridge
at instantiation): every column must agree to 1e-12 of its largest value; FMU states move between the two paths;
what the kernel cannot vouch for (a NaN input, a state beyond the bound) is refused by the Python path with its
message, and the kernel takes the next good step again.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

import obsfmu
from obsfmu.fmus.cli import main as cli

from faults_support import DISCARD, ERROR, OK, Probe

ROOT = Path(__file__).resolve().parents[3]
SHIP = ROOT / "fmus" / "scenarios" / "ship" / "system.toml"

#: kernel vs Python path, relative to each column's largest magnitude (round-off of a different summation order)
AGREEMENT = 1e-12


#: what the bridge logs (logging on) when an instance first steps in C
IN_C = "steps run in the compiled kernel"    # = native_harness.KERNEL_NOTE


def both_paths(monkeypatch, run):
    """``run()`` with the kernels, then with ``OBSFMU_KERNELS=python``."""
    monkeypatch.delenv("OBSFMU_KERNELS", raising=False)
    fast = run()
    monkeypatch.setenv("OBSFMU_KERNELS", "python")
    slow = run()
    monkeypatch.delenv("OBSFMU_KERNELS")
    return fast, slow


def assert_same_columns(fast, slow, columns, tolerance=AGREEMENT):
    for column in columns:
        a, b = np.asarray(fast[column], dtype=float), np.asarray(slow[column], dtype=float)
        scale = max(float(np.max(np.abs(b))), 1e-300)
        assert np.max(np.abs(a - b)) <= tolerance * scale, (column, np.max(np.abs(a - b)) / scale)


@pytest.mark.parametrize("order, coupling, version", [("gauss-seidel", "linear", 2), ("jacobi", "linear", 2),
                                                      ("gauss-seidel", "hold", 2), ("gauss-seidel", "linear", 3)])
def test_ship_scenario_equals_python_path(monkeypatch, build_dir, order, coupling, version):
    """Paper 002 through the master (input derivatives, interpolation modes, the one-call step; FMI 2.0 and 3.0):
    plant, observer and state feedback in C equal the Python path state for state (0.2 s, 10 000 steps)."""
    fast, slow = both_paths(monkeypatch, lambda: obsfmu.run("ship", stop_time=0.2, order=order, coupling=coupling,
                                                            build_dir=build_dir, fmi_version=version))
    columns = [c for c in fast.columns if c != "time"]
    assert {"plant.x[1]", "observer.x_hat[2]", "controller.u"} <= set(columns)
    assert_same_columns(fast, slow, columns)


@pytest.mark.parametrize("example, stop", [("dcmotor", 0.5), ("chirp_noisy", 1.0), ("pendulum", 1.0),
                                           ("state_affine_vanderpol", 2.0), ("gpebo_fullgamma", 10.0),
                                           ("gpebo_shift3", 10.0), ("uio_rotating_gain", 1.0), ("uio_third_order", 1.0),
                                           ("state-affine-chemostat", 1.0), ("state-affine-pendulum", 1.0),
                                           ("discrete-gpebo", 10.0), ("uio-ftdrem", 1.0)])
def test_examples_and_scenarios_equal_python_path(monkeypatch, build_dir, example, stop):
    """Every example and scenario whose LTI plants, observers, state feedback, sources, noise and expression plants
    get a kernel, next to blocks without one (the adaptive observers of papers 000, 003, 004): the same numbers on
    both paths (paper 001's and 002's are compared below and above; measured: the others bit for bit)."""
    path = ROOT / "examples" / f"{example}.toml"
    target = path if path.is_file() else example
    fast, slow = both_paths(monkeypatch, lambda: obsfmu.run(target, stop_time=stop, build_dir=build_dir))
    assert_same_columns(fast, slow, [c for c in fast.columns if c != "time"])


# ------------------------------------------------------------------ one FMU, call by call (fmpy's FMU2Slave)

def probe(fmu, name, kernels=None, monkeypatch=None):
    """An initialised instance of ``fmu`` on the kernel path (``kernels`` None) or the Python path."""
    if kernels:
        monkeypatch.setenv("OBSFMU_KERNELS", kernels)
    else:
        monkeypatch.delenv("OBSFMU_KERNELS", raising=False)
    return Probe(fmu, name)


def stepped(fmu, step, count):
    """A run of ``fmu`` (:meth:`Probe.run`: inputs and their derivatives set every step): its outputs after each
    step, and whether the FMU said it stepped in C."""
    def run():
        instance = Probe(fmu, "stepped")
        rows = instance.run(step, count)
        instance.free()
        return {"rows": rows, "in C": IN_C in instance.messages()}
    return run


def drive(instance, first, count, step=1e-3):
    for k in range(first, first + count):
        instance.drive_inputs(k, step)
        assert instance.step(step) == OK, instance.messages()


def moved_between_paths(fmu, monkeypatch):
    """``fmu`` stepped 300 times in C (the reference), and 100 in C, 100 in Python and 100 in C again, the FMU state
    serialized and restored at each change of path (inputs and input derivatives set every step): the outputs of
    both at the end, and the reference's messages."""
    reference = probe(fmu, "reference", monkeypatch=monkeypatch)
    drive(reference, 0, 300)
    path = probe(fmu, "first", monkeypatch=monkeypatch)
    drive(path, 0, 100)
    for first, kernels in ((100, "python"), (200, None)):
        state = path.slave.serializeFMUstate(path.slave.getFMUstate())
        time = path.t
        path.free()
        path = probe(fmu, f"from{first}", kernels, monkeypatch)
        path.slave.setFMUstate(path.slave.deSerializeFMUstate(state))
        path.t = time
        drive(path, first, 100)
    outcome = path.outputs(), reference.outputs(), reference.messages()
    path.free()
    reference.free()
    return outcome


@pytest.mark.parametrize("model", ["ship_plant", "ship_observer", "ship_controller"])
def test_fmu_state_moves_between_paths(monkeypatch, ship_fmus, model):
    """A state serialized on one path restores on the other (one format): 100 steps in C, 100 in Python, 100 in C
    again equal 300 steps in C, inputs and input derivatives set every step."""
    moved, reference, messages = moved_between_paths(ship_fmus[model], monkeypatch)
    assert IN_C in messages
    np.testing.assert_allclose(moved, reference, rtol=AGREEMENT, atol=0)


def test_refusals_come_from_the_python_path(monkeypatch, ship_fmus):
    """A NaN input is refused in the Python path's words -- the kernel does not take it -- with the state kept;
    restored to before, good inputs step in C again; parameters and interpolation modes read while stepping are their values."""
    instance = probe(ship_fmus["ship_plant"], "refusals", monkeypatch=monkeypatch)
    drive(instance, 0, 10)
    before, state = instance.outputs(), instance.slave.getFMUstate()
    assert instance.set("u", float("nan")) == OK                 # remembered; the step refuses it
    assert instance.step(1e-3) == DISCARD
    assert "input u = nan is not finite" in instance.messages()
    np.testing.assert_array_equal(instance.outputs(), before)
    instance.slave.setFMUstate(state)                            # out of stepFailed (FMI 2.0), as a master does
    instance.slave.freeFMUstate(state)
    drive(instance, 10, 5)
    assert not np.array_equal(instance.outputs(), before)
    assert instance.get(["A[2,1]", "x0[2]"]) == [-2.0, 0.2]
    assert instance.slave.getInteger([instance.vr("u_interpolation")]) == [0]
    assert instance.set("A[1,1]", 5.0) == ERROR                  # fixed after initialization: refused in Python
    assert "parameters are fixed after initialization" in instance.messages()
    instance.free()


def test_step_beyond_the_bound_is_refused_naming_the_state(monkeypatch, ship_fmus):
    """The unstable ship plant (eig(A) = {1, 2}) stepped until its state would pass 1e100 (t ~ 115 s): the kernel
    does not take that step, the Python path refuses it naming the state, and the outputs stay as they were."""
    instance = probe(ship_fmus["ship_plant"], "bound", monkeypatch=monkeypatch)
    status = OK
    while status == OK and instance.t < 200:
        status = instance.step(1.0)
    assert status == DISCARD and 110 < instance.t < 120, (status, instance.t)
    assert "exceeds the bound 1e+100" in instance.messages()
    assert np.all(np.isfinite(instance.outputs()))
    instance.free()


def test_kernels_python_is_recorded_in_the_fmu(tmp_path, ship_fmus):
    """``obsfmu build --kernels python``: the FMU's record says so (its bridge then never takes an image)."""
    code = cli.main(["build", "--config", str(SHIP), "--out", str(tmp_path), "--kernels", "python"])
    assert code == 0
    fmu = tmp_path / "ship_plant.fmu"
    assert "kernels=python" in zipfile.ZipFile(fmu).read("resources/obsfmu_native.txt").decode()
    assert "kernels" not in zipfile.ZipFile(ship_fmus["ship_plant"]).read("resources/obsfmu_native.txt").decode()


# ------------------------------------------------------------------ expression plants: their expressions in C

#: a forced Duffing oscillator (benchmarks/expression_plant.py), with every kind of operation of the grammar
DUFFING = ["x[2]", "-delta * x[2] - alpha * x[1] - beta * x[1]^3 + gain * u[1]"]
OUTPUTS = ["x[1]", "where(x[1] > 0, sqrt(abs(x[1])), -log(1 + x[1]^2)) + min(x[2], 0.5) + atan2(x[2], 1 + u[1] % 2)"]


@pytest.fixture(scope="module")
def expression_fmus(tmp_path_factory):
    """A Duffing plant (RK4 sub-steps of at most 1e-3 s, an output with the awkward functions), and a stiff plant
    (x' = -2700 x + u at max_substep 1e-3: sub-steps rejected and retried) whose budget a long step exceeds."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
    folder = tmp_path_factory.mktemp("expression")
    duffing = expression_plant_definition("duffing", DUFFING, OUTPUTS, [1.0, 0.0], inputs=1,
                                          parameters={"delta": 0.2, "alpha": -1.0, "beta": 1.0, "gain": 0.3})
    stiff = expression_plant_definition("stiff", ["-2700 * x[1] + u[1]"], ["x[1]"], [1.0], inputs=1, rtol=1e-6,
                                        atol=1e-9)
    return {d.model_name: build_fmu(d, folder) for d in (duffing, stiff)}


@pytest.mark.parametrize("model, step, count", [("duffing", 1e-2, 200), ("duffing", 2.5e-4, 200), ("stiff", 1e-2, 20)])
def test_expression_plant_equals_python_path(monkeypatch, expression_fmus, model, step, count):
    """The Duffing plant over several RK4 sub-steps per step and less than one, the stiff plant through rejected
    sub-steps: the compiled expressions and integrator give the Python path's numbers, inputs and input derivatives
    set every step."""
    fast, slow = both_paths(monkeypatch, stepped(expression_fmus[model], step, count))
    assert fast["in C"] and not slow["in C"]
    assert np.all(np.isfinite(fast["rows"]))
    assert_same_columns(fast, slow, ["rows"])


def test_expression_budget_refused_by_the_python_path(monkeypatch, expression_fmus):
    """A step the stiff plant cannot take within its substep_budget: the kernel leaves it to the Python path,
    which refuses it naming substep_budget; the state is unchanged."""
    instance = probe(expression_fmus["stiff"], "budget", monkeypatch=monkeypatch)
    drive(instance, 0, 5)
    before = instance.outputs()
    assert instance.step(20.0) == DISCARD                        # 20 000 sub-steps of max_substep: > 10 000
    assert "substep_budget" in instance.messages()
    np.testing.assert_array_equal(instance.outputs(), before)
    instance.free()


def test_signal_source_equals_python_path(monkeypatch, tmp_path):
    """The signal source (two sines, a step at 0.13 s, a decaying exponential) steps in C -- its waveform compiled
    to C when the FMU is built -- with the Python path's values (numpy's sin and exp against the C library's: within
    1e-12 of the largest); with noise too, whose draws are numpy's (observers/random_stream.py): the noisy source
    minus the clean one is ``noise_std`` times ``default_rng((noise_seed, k)).standard_normal()``."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds.signals import source_definition
    waveform = {"offset": 0.5, "amplitude": [1.0, -0.3], "omega": [2.0, 31.0], "phase": [0.1, 1.0],
                "step_time": 0.13, "step_height": 2.0, "exp_amplitude": 0.7, "exp_rate": 3.0, "noise_seed": 7}
    fmus = {noise: build_fmu(source_definition(f"source_{int(noise * 10)}", sines=2, noise_std=noise, **waveform),
                             tmp_path) for noise in (0.0, 0.1)}

    fast, slow = both_paths(monkeypatch, stepped(fmus[0.0], 1e-2, 50))
    assert fast["in C"] and not slow["in C"]
    assert_same_columns(fast, slow, ["rows"])
    assert abs(fast["rows"][13, 0] - slow["rows"][12, 0]) > 1.0             # the step is in it (at t = 0.14 s)
    noisy, reference = both_paths(monkeypatch, stepped(fmus[0.1], 1e-2, 50))
    assert noisy["in C"] and not reference["in C"]
    assert_same_columns(noisy, reference, ["rows"])
    draws = [0.1 * np.random.default_rng((7, 10 * (i + 1))).standard_normal() for i in range(50)]   # noise_dt 1e-3
    np.testing.assert_allclose(noisy["rows"][:, 0] - fast["rows"][:, 0], draws, rtol=0, atol=1e-14)


@pytest.mark.parametrize("kind, settings", [
    ("noise_source", {"size": 2, "std": 0.3, "sample_interval": 2.5e-3, "seed": 11}),
    ("noise_source", {"distribution": "uniform", "std": 2.0, "sample_interval": 1e-2, "seed": 2 ** 40 + 1}),
    ("added_noise", {"size": 2, "std": 0.05, "sample_interval": 1e-2, "seed": 3}),
    ("added_noise", {"std": 0.0, "seed": 3}),
    ("noise_source", {"cutoff_hz": 5.0, "seed": 1, "sample_interval": 2e-3}),
    ("added_noise", {"cutoff_hz": 3.0, "filter_order": 2, "size": 3, "sample_interval": 5e-3,
                     "distribution": "uniform"}),
    ("added_noise", {"cutoff_hz": 3.0, "std": 0.0}),
    ("noise_source", {"cutoff_hz": 2.0, "size": 70, "sample_interval": 1e-3})])
def test_noise_equals_python_path_draw_for_draw(monkeypatch, tmp_path, kind, settings):
    """Noise steps in C, its values the Python path's to the bit: white (Gaussian and uniform, one and two streams,
    alone and added to a connection, std 0), its draws numpy's (observers/random_stream.py); band-limited (first
    and second order, three and seventy streams), its filter summed in the Python path's order
    (plants.noise.filter_step)."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds import noise
    fmu = build_fmu(getattr(noise, f"{kind}_definition")(kind, **settings), tmp_path)

    fast, slow = both_paths(monkeypatch, stepped(fmu, 1e-2, 60))
    assert fast["in C"] and not slow["in C"]
    np.testing.assert_array_equal(fast["rows"], slow["rows"])
    assert np.unique(fast["rows"]).size > 50 or settings["std"] == 0.0


@pytest.mark.parametrize("family, settings", [
    ("constant", {"value": -1.5}), ("step", {"time": 0.13, "height": 2.0, "offset": 0.5}),
    ("ramp", {"start_time": 0.1, "slope": -3.0, "offset": 1.0}),
    ("ramp", {"start_time": 0.1, "slope": 3.0, "end_time": 0.3}),
    ("sine", {"amplitude": 2.0, "frequency_hz": 3.0, "phase": 0.4, "offset": -1.0}),
    ("multisine", {"amplitudes": [1.0, 0.5, 0.25], "frequencies_hz": [0.5, 7.0, 13.0], "phases": [0, 1, 2]}),
    ("chirp", {"f0_hz": 1.0, "f1_hz": 5.0, "t1": 0.4}),
    ("chirp", {"f0_hz": 1.0, "f1_hz": 20.0, "t0": 0.1, "t1": 0.3, "sweep": "exponential", "after": "stop",
               "phase": 0.3, "offset": 0.2}),
    ("square", {"period": 0.07, "duty": 0.3, "amplitude": 2.0, "offset": 0.5}),
    ("prbs", {"seed": 3, "bit_period": 0.03}), ("prbs", {"seed": 2 ** 31 + 5, "register_length": 32, "bit_period": 0.01,
                                                         "amplitude": 0.5, "offset": 1.0}),
    ("table", {"times": [0.05, 0.1, 0.25, 0.3], "values": [1.0, -2.0, 0.5, 3.0]}),
    ("table", {"times": [0.05, 0.1, 0.25, 0.3], "values": [1.0, -2.0, 0.5, 3.0], "interpolation": "previous"}),
    ("table", {"times": [0.2], "values": [4.0]})])
def test_waveform_sources_equal_python_path(monkeypatch, tmp_path, family, settings):
    """Every waveform source steps in C with the Python path's values: those whose value is an expression (the chirp
    with both sweeps, before, during and after them; the square wave across its edges), the PRBS (its register's
    bits by the same arithmetic over GF(2), 7 and 32 bits) and the tables (numpy's interp before, at, between and
    after the break points, and the previous value) -- C of their own (Source.c_value)."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds import sources
    fmu = build_fmu(getattr(sources, f"{family}_source_definition")(f"{family}_source", **settings), tmp_path)

    fast, slow = both_paths(monkeypatch, stepped(fmu, 1e-2, 50))
    assert fast["in C"] and not slow["in C"]
    assert_same_columns(fast, slow, ["rows"])
    if family in ("prbs", "table"):
        np.testing.assert_array_equal(fast["rows"], slow["rows"])
        levels = np.unique(fast["rows"]).size           # both levels; every value a table's linear pieces pass
        assert levels == 2 if family == "prbs" else levels >= min(len(settings["times"]), 4)


def test_band_limited_noise_state_moves_between_paths_and_back_in_time(monkeypatch, tmp_path):
    """The filter's cache is no FMU state: a state restored in a fresh instance, or an earlier state restored in
    the same one (the kernel only goes forward; Python restarts from its checkpoints), gives the same noise."""
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds import noise
    fmu = build_fmu(noise.added_noise_definition("filtered", cutoff_hz=2.0, filter_order=2, size=2,
                                                 sample_interval=1e-3, seed=8), tmp_path)
    moved, reference, messages = moved_between_paths(fmu, monkeypatch)
    assert IN_C in messages
    np.testing.assert_array_equal(moved, reference)
    instance = probe(fmu, "rollback", monkeypatch=monkeypatch)
    drive(instance, 0, 100)
    state, time = instance.slave.getFMUstate(), instance.t
    drive(instance, 100, 200)
    later = instance.outputs()
    instance.slave.setFMUstate(state)
    instance.t = time
    drive(instance, 100, 200)
    np.testing.assert_array_equal(instance.outputs(), later)
    instance.free()


# ------------------------------------------------------------------ paper 001: the adaptive observer (least squares), the plant

@pytest.mark.parametrize("settings, first", [("SETTINGS", "KT_N"), ("PLANT_SETTINGS", "KQ_N")])
def test_ltv_settings_are_the_c_enum(settings, first):
    """The images' settings (observers/ltv/kernel.py) in the order of the C enums that read them (kernel_ltv.h)."""
    import re

    from obsfmu.observers.ltv import kernel
    header = (ROOT / "fmus" / "native" / "kernel_ltv.h").read_text()
    prefix = first.split("_")[0]
    enum = re.search(rf"enum \{{\s*({first},.*?){prefix}_COUNT", header, re.DOTALL).group(1)
    names = [name.strip().removeprefix(f"{prefix}_") for name in enum.split(",") if name.strip()]
    assert names == [name.upper() for name in getattr(kernel, settings)]


@pytest.mark.parametrize("target, stop, tolerance, eigenvalue", [
    ("ltv-ls", 5.0, AGREEMENT, 1e-10),                 # f_correction, cubic inputs, the start-up ramp
    (ROOT / "examples" / "ltv_mass_spring_damper.toml", None, AGREEMENT, AGREEMENT),   # known b and m, y^3
    (ROOT / "examples" / "ltv_drifting_sensor.toml", None, AGREEMENT, 1e-10),         # C(t), three f_i
    ("ltv-ls-bounded", 20.0, 1e-8, 1e-6)])             # weakly excited: F up to 1.06e6
def test_paper_001_equals_python_path(monkeypatch, build_dir, target, stop, tolerance, eigenvalue):
    """Paper 001's plant and observer step in C (polynomial inputs, RK4 filters, Gauss rows, the information-form
    step) with the Python path's numbers.  The plant to 1e-12 (measured: 1.2e-15 at most).  The observer's solve and
    the smallest eigenvalue of P are plain loops in C where numpy calls LAPACK: both are backward stable, so they
    agree to round-off times the condition number of P -- 1e-12 while P is well conditioned, 1e-8 in the weakly
    excited case (F up to 1.06e6); lambda_min(P) (F_max, excitation), which LAPACK knows to eps lambda_max(P) only,
    to 1e-10 and 1e-6 (measured: 5.1e-13, 3.3e-14, 2.6e-13, 9.0e-10; 1.3e-11, 1.9e-13, 4.4e-11, 1.6e-8).  The Python
    path parts from itself as much on another CPU (docs/portability.md: numpy's OpenBLAS with its baseline kernels,
    ltv-ls-bounded: 8.9e-10 and 1.4e-8)."""
    fast, slow = both_paths(monkeypatch, lambda: obsfmu.run(target, stop_time=stop, build_dir=build_dir))
    assert_paper_001_agrees(fast, slow, tolerance, eigenvalue)


def test_paper_001_plant_with_measurement_noise_equals_python_path(monkeypatch, build_dir, paper_001):
    """The plant's measurement noise v(t) (noise_std, noise_dt, noise_seed) is numpy's stream compiled into its kernel
    library (observers/random_stream.py): the plant steps in C, and y - C^T x is the Python path's noise, draw for
    draw, ``noise_std`` times ``default_rng((noise_seed, k)).standard_normal()``."""
    noise = {"plant.noise_std": 0.05, "plant.noise_dt": 1e-2, "plant.noise_seed": 3}
    fast, slow = both_paths(monkeypatch, lambda: obsfmu.run("ltv-ls", stop_time=1.0, set=noise, build_dir=build_dir))
    assert_paper_001_agrees(fast, slow, AGREEMENT, 1e-10)
    v = np.asarray(fast["plant.y"]) - np.asarray(fast["plant.x[1]"])          # C = [1, 0]
    k = np.maximum(np.floor(fast.time / 1e-2 + 1e-9), 0).astype(int)
    draws = [0.05 * np.random.default_rng((3, int(i))).standard_normal() for i in k]
    np.testing.assert_allclose(v, draws, rtol=0, atol=1e-12)
    monkeypatch.delenv("OBSFMU_KERNELS", raising=False)
    plant = Probe(paper_001["ltv_ls_plant"], "noisy", start={n.removeprefix("plant."): v for n, v in noise.items()})
    drive(plant, 0, 50)
    assert IN_C in plant.messages()
    y, x1 = plant.get(["y", "x[1]"])
    assert y - x1 == pytest.approx(0.05 * np.random.default_rng((3, 5)).standard_normal(), abs=1e-12)   # t = 0.05
    plant.free()


def assert_paper_001_agrees(fast, slow, tolerance, eigenvalue):
    observer = [c for c in fast.columns if c.startswith("observer.")]
    assert {"observer.theta_hat[1]", "observer.x_hat[2]", "observer.converged", "plant.y"} <= set(fast.columns)
    smallest = {"observer.F_max", "observer.excitation"}
    assert_same_columns(fast, slow, [c for c in fast.columns if c.startswith("plant.")])
    assert_same_columns(fast, slow, [c for c in observer if c not in smallest], tolerance)
    assert_same_columns(fast, slow, smallest, eigenvalue)
    assert not np.array_equal(fast["observer.theta_hat"], slow["observer.theta_hat"])   # not the same path twice


#: a stranger's plant of paper 001's class: third order, two nonlinearities (one varying in time), b known
THIRD_ORDER = """
name = "ltv3"
connections = ["force.y -> plant.u", "force.y -> observer.u", "plant.y -> observer.y"]

[experiment]
stop_time = 5.0
step = 1e-2
master = "gauss-seidel"
coupling = "linear"

[components.force]
kind = "multisine"
amplitudes = [1.0, 0.5]
frequencies_hz = [0.2, 0.7]

[components.plant]
kind = "ltv-plant"
A = [[0, 1, 0], [0, 0, 1], [0, 0, 0]]
C = [1, 0, 0]
f = ["sin(y)", "y * cos(t)"]
k = [-3, -3, -1]
b = [0, 0, 1]
m = [[0.1, 0.0], [0.2, -0.1], [-0.3, 0.2]]
x0 = [0.5, -0.2, 0.1]
input_degree = 2
max_substep = 5e-3

[components.observer]
kind = "ltv-adaptive-observer"
A = [[0, 1, 0], [0, 0, 1], [0, 0, 0]]
C = [1, 0, 0]
L = [3, 3, 1]                # A0 = A - L C^T: (s + 1)^3
f = ["sin(y)", "y * cos(t)"]
unknowns = "k, m"
b = [0, 0, 1]
gamma = 1000.0
beta = 0.5
f0 = 0.1
input_degree = 2
max_substep = 5e-3
"""


def test_a_third_order_plant_with_two_nonlinearities_equals_python_path(monkeypatch, build_dir, tmp_path):
    """The kernels' sizes are the file's: n = 3, p = 2 with f(y, t), 9 unknowns with b known (measured: plant
    1.6e-16, observer 1.9e-13, F_max 1.5e-12)."""
    path = tmp_path / "ltv3.toml"
    path.write_text(THIRD_ORDER)
    fast, slow = both_paths(monkeypatch, lambda: obsfmu.run(path, build_dir=build_dir))
    assert len([c for c in fast.columns if c.startswith("observer.theta_hat")]) == 3 + 3 + 6
    assert_paper_001_agrees(fast, slow, AGREEMENT, 1e-10)


@pytest.fixture(scope="module")
def paper_001(build_dir):
    from obsfmu.fmus.scenarios import ensure_fmus, get
    return ensure_fmus(get("ltv-ls"), build_dir)


@pytest.mark.parametrize("model", ["ltv_ls_observer", "ltv_ls_plant"])
def test_paper_001_steps_in_c_and_its_state_moves_between_paths(monkeypatch, paper_001, model):
    """Each FMU on its own (inputs and their derivatives set every step): it says it steps in C, and a state
    serialized after 100 steps in C, continued 100 in Python and 100 in C again, equals 300 steps in C."""
    moved, reference, messages = moved_between_paths(paper_001[model], monkeypatch)
    assert IN_C in messages and "paper 001" in messages
    np.testing.assert_allclose(moved, reference, rtol=AGREEMENT, atol=1e-14)


@pytest.mark.parametrize("model, port", [("ltv_ls_observer", "y"), ("ltv_ls_plant", "u")])
def test_paper_001_refusals_come_from_the_python_path(monkeypatch, paper_001, model, port):
    """A NaN input is refused in the Python path's words with the state kept, and a step beyond the sub-step budget
    names substep_budget; good steps go on in C."""
    instance = probe(paper_001[model], "refusals", monkeypatch=monkeypatch)
    drive(instance, 0, 10)
    before = instance.outputs()
    state = instance.slave.getFMUstate()
    assert instance.set(port, float("nan")) == OK
    assert instance.step(1e-3) == DISCARD
    assert f"input {port} = nan is not finite" in instance.messages()
    np.testing.assert_array_equal(instance.outputs(), before)
    instance.slave.setFMUstate(state)                            # out of stepFailed (FMI 2.0), as a master does
    assert instance.step(1e3) == DISCARD                        # 1e6 sub-steps of max_substep 1e-3
    assert "substep_budget" in instance.messages()
    np.testing.assert_array_equal(instance.outputs(), before)
    instance.slave.setFMUstate(state)
    instance.slave.freeFMUstate(state)
    drive(instance, 10, 5)
    assert not np.array_equal(instance.outputs(), before)
    instance.free()
