"""The generic slave and the builder: validity, naming, units, portability, errors, interpolation."""

import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2LastSuccessfulTime
from fmpy.validation import validate_fmu
from scipy.linalg import expm

from obsfmu.fmus.builder import build_fmu, is_current
from obsfmu.fmus.scenarios.ship.reference import K
from obsfmu.fmus.runtime.kinds.linear import plant_definition
from obsfmu.observers.lti_model import StateSpace


def open_slave(path, name="instance"):
    description = read_model_description(str(path))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=description.coSimulation.modelIdentifier, instanceName=name)
    slave.instantiate(loggingOn=True)
    references = {v.name: v.valueReference for v in description.modelVariables}
    return slave, references


def test_every_ship_fmu_is_valid(ship_fmus):
    for path in ship_fmus.values():
        assert validate_fmu(str(path)) == [], path


def test_model_description_names_units_and_structure(ship_fmus):
    description = read_model_description(str(ship_fmus["ship_observer"]))
    names = {v.name: v for v in description.modelVariables}
    for name in ["A[1,1]", "A[2,2]", "B[2]", "C[1]", "N[1]", "N[2]", "x_hat0[1]", "x_hat0[2]",
                 "u", "y", "x_hat[1]", "x_hat[2]", "y_hat", "u_interpolation", "y_interpolation"]:
        assert name in names, name
    assert float(names["N[2]"].start) == pytest.approx(1847.0)
    assert names["N[1]"].causality == "parameter" and names["N[1]"].description
    assert [names[o.variable.name].name for o in description.outputs] == ["x_hat[1]", "x_hat[2]", "y_hat"]
    assert all(o.dependencies == [] for o in description.outputs)  # strictly proper observer
    assert {u.variable.name for u in description.initialUnknowns} == {"x_hat[1]", "x_hat[2]", "y_hat"}

    controller = read_model_description(str(ship_fmus["ship_controller"]))
    (u,) = controller.outputs
    assert {d.name for d in u.dependencies} == {"x_hat[1]", "x_hat[2]", "r"}  # direct feedthrough
    assert "x_hat_interpolation" not in {v.name for v in controller.modelVariables}  # static block

    plant = read_model_description(str(ship_fmus["ship_plant"]))
    assert {"x0[1]", "x0[2]", "x[1]", "x[2]"} <= {v.name for v in plant.modelVariables}


def test_units_are_declared(tmp_path):
    model = StateSpace.checked([[0, 1], [0, -1]], [[0], [1]], [[1, 0]])
    definition = plant_definition("units_plant", model, [0, 0],
                                  {"state_units": ["rad", "rad/s"], "input_units": ["N.m"]}, "")
    path = build_fmu(definition, tmp_path)
    assert validate_fmu(str(path)) == []
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    assert (variables["x[1]"].unit, variables["x[2]"].unit, variables["u"].unit) == ("rad", "rad/s", "N.m")
    root = ElementTree.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))
    assert {u.get("name") for u in root.find("UnitDefinitions")} == {"rad", "rad/s", "N.m"}


def test_fmu_runs_without_the_checkout(ship_fmus, tmp_path):
    """Only numpy/scipy/fmpy are importable in the child process; the FMU brings its own code."""
    site = sysconfig.get_paths()["purelib"]
    script = textwrap.dedent(f"""
        import sys
        sys.path.append({site!r})          # packages only: no .pth files, so no editable obsfmu
        try:
            from obsfmu import observers
        except ImportError:
            pass
        else:
            raise SystemExit("observers is importable: the test is not isolated")
        from fmpy import simulate_fmu
        result = simulate_fmu({str(ship_fmus['ship_plant'])!r}, stop_time=0.1, output_interval=0.1,
                              start_values={{'x0[1]': 1.0}})
        bundled = [m for name, m in sys.modules.items() if name.endswith(".observers")]
        assert "observers" not in sys.modules and len(bundled) == 1, sorted(sys.modules)
        print(result['x[1]'][-1], result['x[2]'][-1], bundled[0].__file__)
    """)
    completed = subprocess.run([sys.executable, "-I", "-S", "-c", script], capture_output=True, text=True,
                               cwd=tmp_path, timeout=120)
    assert completed.returncode == 0, completed.stderr + completed.stdout
    x1, x2, location = completed.stdout.split()
    expected = expm(np.array([[0, 1], [-2, 3]]) * 0.1) @ [1.0, 0.2]
    np.testing.assert_allclose([float(x1), float(x2)], expected, rtol=1e-12)
    assert "/resources/_obsfmu_" in location and "/observers/" in location  # the bundled copy, not a checkout


def test_nan_input_is_refused_logged_and_the_state_kept(ship_fmus, capfd):
    slave, vr = open_slave(ship_fmus["ship_observer"])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.setReal([vr["y"]], [0.05])
    slave.doStep(0.0, 1e-3)
    before = slave.getReal([vr["x_hat[1]"], vr["x_hat[2]"]])
    saved = slave.getFMUstate()
    slave.setReal([vr["y"]], [float("nan")])
    with pytest.raises(FMICallException, match="discard"):
        slave.doStep(1e-3, 1e-3)
    assert "input y = nan is not finite" in capfd.readouterr().out
    assert slave.getReal([vr["x_hat[1]"], vr["x_hat[2]"]]) == before  # untouched
    assert slave.getRealStatus(fmi2LastSuccessfulTime) == 1e-3
    slave.setFMUstate(saved)  # FMI 2.0: a failed step is redone from a saved state
    slave.freeFMUstate(saved)
    slave.setReal([vr["y"]], [0.05])
    slave.doStep(1e-3, 1e-3)  # the instance keeps working
    assert np.all(np.isfinite(slave.getReal([vr["x_hat[1]"], vr["x_hat[2]"]])))
    slave.terminate()
    slave.freeInstance()


def test_invalid_parameters_are_an_error_not_fatal(ship_fmus, capfd):
    slave, vr = open_slave(ship_fmus["ship_observer"])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    good = slave.getReal([vr["N[1]"], vr["N[2]"]])
    slave.setReal([vr["N[1]"], vr["N[2]"]], [-1.0, 0.0])  # A - N C no longer Hurwitz
    with pytest.raises(FMICallException, match=r"status 3 \(error\)"):
        slave.exitInitializationMode()
    assert "N: not Hurwitz" in capfd.readouterr().out
    with pytest.raises(FMICallException, match="error"):  # the instance refuses to step, and stays alive
        slave.doStep(0.0, 1e-3)
    # refused, not failed: still in initialization mode (docs/faults.md), where the parameters can be fixed
    assert "fmi2DoStep is not allowed in state initializationMode" in capfd.readouterr().out
    slave.setReal([vr["N[1]"], vr["N[2]"]], good)
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-3)
    slave.reset()  # and a reset starts over from the default parameters
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.doStep(0.0, 1e-3)
    slave.freeInstance()


def test_python_exceptions_become_fmi2error(ship_fmus, capfd):
    slave, vr = open_slave(ship_fmus["ship_observer"])
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()  # fmi2GetReal is not allowed before (FMI 2.0 state machine)
    with pytest.raises(FMICallException, match=r"status 3 \(error\)"):
        slave.getReal([10_000])  # no such value reference
    assert "get_real" in capfd.readouterr().out
    slave.freeInstance()


def test_one_fmu_instantiated_many_times_in_one_process(ship_fmus):
    """pythonfmu 0.7's stock binary released a borrowed reference per instantiation and crashed
    the host after a few; the project's native binary must not."""
    path = ship_fmus["ship_controller"]
    description = read_model_description(str(path))
    directory = extract(str(path))
    references = {v.name: v.valueReference for v in description.modelVariables}
    for k in range(40):
        slave = FMU2Slave(guid=description.guid, unzipDirectory=directory,
                          modelIdentifier=description.coSimulation.modelIdentifier, instanceName=f"c{k}")
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.setReal([references["x_hat[1]"], references["x_hat[2]"], references["r"]], [k, 1.0, 0.5])
        slave.doStep(0.0, 1e-3)
        # every instance is alive and its own: u = -K x_hat + r with this instance's inputs
        assert slave.getReal([references["u"]]) == pytest.approx([-(K[0, 0] * k + K[0, 1]) + 0.5], rel=1e-12)
        slave.terminate()
        slave.freeInstance()


@pytest.mark.parametrize("mode, tolerance", [(0, None), (1, 1e-12), (2, 1e-12)])
def test_input_interpolation_modes(ship_fmus, mode, tolerance):
    """A ramp input u = t: hold lags (O(h) error), extrapolate/interpolate are exact for it."""
    slave, vr = open_slave(ship_fmus["ship_plant"], f"ramp{mode}")
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setInteger([vr["u_interpolation"]], [mode])
    slave.setReal([vr["x0[1]"], vr["x0[2]"], vr["u"]], [0.0, 0.0, 0.0])
    slave.exitInitializationMode()
    h, steps = 0.01, 20
    for k in range(steps):
        t = k * h
        slave.setReal([vr["u"]], [t + h if mode == 2 else t])  # mode 2: the value at the step end
        slave.doStep(t, h)
    x = np.array(slave.getReal([vr["x[1]"], vr["x[2]"]]))
    A, B, T = np.array([[0.0, 1.0], [-2.0, 3.0]]), np.array([0.0, 1.0]), steps * h
    # x(T) = int_0^T expm(A (T - s)) B s ds, by the augmented exponential of [[A, B, 0], [0, 0, 1], [0, 0, 0]]
    M = np.zeros((4, 4))
    M[:2, :2], M[:2, 2], M[2, 3] = A, B, 1.0
    if mode == 1:  # no slope is known on the first step: u = 0 on [0, h], then u = t exactly
        exact = (expm(M * (T - h)) @ [0, 0, h, 1])[:2]
    else:
        exact = (expm(M * T) @ [0, 0, 0, 1])[:2]
    error = np.max(np.abs(x - exact))
    if tolerance is None:
        assert error > 1e-4  # holding u = t lags by h/2: a visible error
    else:
        assert error < tolerance
    slave.terminate()
    slave.freeInstance()


def test_builder_detects_stale_fmus(tmp_path):
    model = StateSpace.checked([[-1.0]], [[1.0]], [[1.0]])
    definition = plant_definition("stale_plant", model, [0.0], {}, "")
    path = build_fmu(definition, tmp_path)
    assert is_current(path, definition)
    definition.parameters[-1].value = [1.0]  # another x0
    assert not is_current(path, definition)


def test_logging_after_a_master_run_does_not_crash_the_host(ship_fmus, capfd):
    """fmpy's logger proxy keeps one global Python logger; the master must not leave it dangling."""
    import gc

    from obsfmu.fmus.master import Component, System, cosimulate
    cosimulate(System([Component("plant", ship_fmus["ship_plant"], {"u": 0.0})], []), 0.01, 1e-3)
    gc.collect()
    slave, _ = open_slave(ship_fmus["ship_observer"], "after")
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    with pytest.raises(FMICallException, match="error"):
        slave.getReal([10_000])  # logs an error through fmpy's default callbacks
    assert "get_real refused: value reference 10000 does not exist" in capfd.readouterr().out
    slave.freeInstance()


def test_bad_interpolation_mode_is_refused_and_logged(ship_fmus, capfd):
    slave, vr = open_slave(ship_fmus["ship_observer"], "mode")
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setInteger([vr["u_interpolation"], vr["y_interpolation"]], [1, 2])
    with pytest.raises(FMICallException, match=r"status 3 \(error\)"):   # nothing of the call is set
        slave.setInteger([vr["u_interpolation"], vr["y_interpolation"]], [0, 7])
    assert "y_interpolation: 7 is not 0 (hold), 1 (extrapolate) or 2 (interpolate)" in capfd.readouterr().out
    assert slave.getInteger([vr["u_interpolation"], vr["y_interpolation"]]) == [1, 2]
    slave.freeInstance()


def test_an_fmu_bundles_only_the_runtime_part_of_fmus(ship_fmus):
    """Master, CLI, scenarios and campaigns stay out: editing them changes no FMU's code hash."""
    names = zipfile.ZipFile(ship_fmus["ship_observer"]).namelist()
    bundled = {n.split("/", 2)[2] for n in names if n.startswith("resources/_obsfmu_") and "/fmus/" in n}
    assert "fmus/runtime/slave/__init__.py" in bundled and "fmus/runtime/kinds/linear.py" in bundled
    assert all(name == "fmus/__init__.py" or name.startswith("fmus/runtime/") for name in bundled), sorted(bundled)
    assert not {"fmus/master/__init__.py", "fmus/master/session.py", "fmus/cli/main.py",
                "fmus/scenarios/__init__.py"} & bundled


def test_an_instance_context_ignores_floating_point_errors_and_leaves_the_callers_setting():
    """The slave runs its entry points in a context of its own where numpy ignores floating-point
    errors (numpy >= 2 keeps that setting per context); the caller's setting stays as it was."""
    from obsfmu.fmus.runtime.slave.numerics import numerics_context
    old = np.seterr(all="raise")
    try:
        context = numerics_context()
        if np.lib.NumpyVersion(np.__version__) >= "2.0.0":
            assert context is not None
        if context is not None:
            inside = context.run(np.geterr)
            assert inside == {"divide": "ignore", "over": "ignore", "under": "ignore", "invalid": "ignore"}
            assert context.run(lambda: float(np.float64(1e308) * 10)) == np.inf     # no FloatingPointError
        assert np.geterr() == {"divide": "raise", "over": "raise", "under": "raise", "invalid": "raise"}
    finally:
        np.seterr(**old)


def test_an_fmu_edited_after_its_build_is_rebuilt_with_a_note_and_a_current_one_is_kept(tmp_path, capsys):
    """Issue 37: an expression edited inside the FMU's JSON was run as it was (the hash the FMU carries
    about itself was trusted).  Judged by the build record beside it, the edit is noticed and the FMU
    rebuilt; a second ensure of an untouched FMU writes nothing."""
    import zipfile

    from obsfmu.fmus.builder import record_path, why_not_current
    from obsfmu.fmus.runtime.kinds.expression import expression_plant_definition
    from obsfmu.fmus.scenarios import ensure_definitions

    definition = expression_plant_definition("edited_plant", ["-x[1]"], ["x[1]"], [1.0])
    path, = ensure_definitions([(definition, ())], tmp_path, False, 2).values()
    assert why_not_current(path, definition) is None and record_path(path).is_file()
    before = path.stat().st_mtime_ns
    assert ensure_definitions([(definition, ())], tmp_path, False, 2)["edited_plant"] == path
    assert path.stat().st_mtime_ns == before                          # a second build builds nothing

    edited = tmp_path / "edited.fmu"                                   # -x[1] -> +x[1] in its JSON, same hash
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(edited, "w") as target:
        for entry in source.infolist():
            data = source.read(entry)
            if entry.filename == "resources/edited_plant.json":
                assert b'"-x[1]"' in data
                data = data.replace(b'"-x[1]"', b'"x[1]"')
            target.writestr(entry, data)
    edited.replace(path)
    assert why_not_current(path, definition).startswith("edited since it was built")
    capsys.readouterr()
    ensure_definitions([(definition, ())], tmp_path, False, 2)
    assert "edited since it was built" in capsys.readouterr().err
    with zipfile.ZipFile(path) as archive:
        assert b'"-x[1]"' in archive.read("resources/edited_plant.json")
    assert why_not_current(path, definition) is None
    record_path(path).unlink()                                         # no record: not trusted, rebuilt
    assert why_not_current(path, definition) == "no build record"
