"""FMI 3.0 FMUs of every scenario, from the same definitions as the FMI 2.0 ones (issue 17).

* every FMI 3.0 FMU is valid (fmpy.validation), its arrays are the FMI 2.0 FMU's scalars (names,
  order, start values, units, the slave's value references -- read from the FMI 2.0 description
  pythonfmu writes, independently of fmus/fmi3);
* every declared capability holds: FMU states (get/set, serialize into a fresh instance),
  variable steps (not the discrete GPEBO FMUs), no event mode, the intermediate update (inputs at
  t + h give the same step as FMI 2.0's input derivatives);
* the master runs FMI 3.0 FMUs and mixed FMI 2.0 / 3.0 systems: every scenario gives the FMI 2.0
  results to round-off (short runs).
"""

import zipfile
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.fmi3.elements import elements
from obsfmu.fmus.master import cosimulate
from obsfmu.fmus.scenarios import SCENARIOS, ensure_fmus, get, run, system

#: fixed-step runs of every scenario: 25 steps of its own step, its own order and coupling
STEPS = 25


def declared(path) -> dict[str, str]:
    root = ElementTree.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))
    return dict(root.find("CoSimulation").attrib)


def test_every_fmi3_fmu_is_valid(every_fmu3):
    problems = {model: validate_fmu(str(path)) for model, (_, path) in every_fmu3.items()}
    assert len(problems) == 20 and not any(problems.values()), problems   # ltv-ls-bounded: its own 3
    assert all(read_model_description(str(path)).fmiVersion == "3.0" for _, path in every_fmu3.values())


def test_arrays_are_the_fmi2_scalars(every_fmu, every_fmu3):
    """Element names, order, causality, start values and units equal the FMI 2.0 FMU's; the loader's
    table sends each element to the slave's value reference of the FMI 2.0 variable of that name."""
    for model, (_, path3) in every_fmu3.items():
        fmi2 = read_model_description(str(every_fmu[model][1]))
        fmi3 = read_model_description(str(path3))
        scalars = {v.name: v for v in fmi2.modelVariables}
        mapped = elements(fmi3)
        assert list(mapped) == list(scalars), model
        table = {}
        for line in zipfile.ZipFile(path3).read("resources/obsfmu_fmi3.txt").decode().splitlines():
            if line and not line.startswith("#"):
                vr, _, _, name, count, *references = line.split()
                table[name] = [int(r) for r in references]
                assert len(references) == int(count)
        for name, element in mapped.items():
            scalar = scalars[name]
            assert (element.causality, element.type) == (scalar.causality, scalar.type), (model, name)
            if scalar.start is not None:
                assert float(element.start) == float(scalar.start), (model, name)
            # mixed-unit arrays too (issue 38: FMI 3 summaries dropped them): FMI 3.0 gives a variable one unit,
            # so the description lists them by element and the loader reads them back
            assert element.unit == scalar.unit, (model, name, element.unit, scalar.unit)
            assert table[element.variable][element.index] == scalar.valueReference, (model, name)


def test_states_are_arrays_and_matrices_have_two_dimensions(every_fmu3):
    def shape(model, name):
        variable = next(v for v in read_model_description(str(every_fmu3[model][1])).modelVariables
                        if v.name == name)
        return variable.type, tuple(int(d.start) for d in variable.dimensions)

    assert shape("ship_observer", "x_hat") == ("Float64", (2,))
    assert shape("ship_observer", "A") == ("Float64", (2, 2))
    assert shape("ship_plant", "x") == ("Float64", (2,))
    assert shape("ship_plant", "u") == ("Float64", ())  # a size-one signal stays a scalar, as in FMI 2.0
    assert shape("ltv_ls_observer", "theta_hat") == ("Float64", (8,))
    assert shape("ship_observer", "u_interpolation") == ("Int32", ())


def test_units_and_descriptions(every_fmu3):
    variables = {v.name: v for v in read_model_description(str(every_fmu3["ltv_ls_plant"][1])).modelVariables}
    assert variables["noise_dt"].unit == "s" and variables["x0"].description == "unknown initial state x(0)"
    described = [v for _, path in every_fmu3.values() for v in read_model_description(str(path)).modelVariables]
    assert all(v.description for v in described)


CHECKED = {"modelIdentifier", "needsExecutionTool", "canBeInstantiatedOnlyOncePerProcess", "canGetAndSetFMUState",
           "canSerializeFMUState", "providesDirectionalDerivatives", "providesAdjointDerivatives",
           "providesPerElementDependencies", "canHandleVariableCommunicationStepSize", "maxOutputDerivativeOrder",
           "providesIntermediateUpdate", "recommendedIntermediateInputSmoothness", "mightReturnEarlyFromDoStep",
           "canReturnEarlyAfterIntermediateUpdate", "hasEventMode", "providesEvaluateDiscreteStates"}


def test_declarations_follow_the_definition(every_fmu, every_fmu3):
    for model, (_, path) in every_fmu3.items():
        capabilities = declared(path)
        assert set(capabilities) <= CHECKED, (model, set(capabilities) - CHECKED)
        assert (capabilities["canHandleVariableCommunicationStepSize"]
                == declared(every_fmu[model][1])["canHandleVariableCommunicationStepSize"]), model
        has_inputs = any(v.causality == "input" for v in read_model_description(str(path)).modelVariables)
        assert capabilities.get("providesIntermediateUpdate", "false") == str(has_inputs).lower(), model
        assert {capabilities[k] for k in ("hasEventMode", "mightReturnEarlyFromDoStep", "providesDirectionalDerivatives",
                                          "providesAdjointDerivatives", "providesPerElementDependencies")} == {"false"}


class Running:
    """One initialized FMI 3.0 instance (fmpy's FMU3Slave); inputs driven by small smooth signals."""

    def __init__(self, path, name, intermediate=None, required=(), logging_on=True):
        self.description = read_model_description(str(path))
        self.messages = []
        self.slave = FMU3Slave(guid=self.description.instantiationToken, unzipDirectory=extract(str(path)),
                               instanceName=name, modelIdentifier=self.description.coSimulation.modelIdentifier)
        variables = self.description.modelVariables
        self.inputs = [v for v in variables if v.causality == "input"]
        self.outputs = [v.valueReference for v in variables if v.causality == "output"]
        self.count = sum(len(elements_of(v)) for v in variables if v.causality == "output")
        self.slave.instantiate(loggingOn=logging_on, logMessage=self._log, intermediateUpdate=intermediate,
                               requiredIntermediateVariables=list(required))
        self.slave.enterInitializationMode(startTime=0.0)
        self.slave.exitInitializationMode()
        self.time = 0.0

    def _log(self, environment, status, category, message):
        self.messages.append((status, message.decode()))

    def step(self, h):
        if self.inputs:
            count = sum(len(elements_of(v)) for v in self.inputs)
            values = [0.1 * np.sin(0.7 * self.time + i) for i in range(count)]
            self.slave.setFloat64([v.valueReference for v in self.inputs], values)
        self.slave.doStep(self.time, h)
        self.time += h
        return self.slave.getFloat64(self.outputs, nValues=self.count)

    def free(self):
        self.slave.freeInstance()


def elements_of(variable):
    return [None] * int(np.prod([int(d.start) for d in variable.dimensions])) if variable.dimensions else [None]


def test_state_and_variable_step_capabilities_hold(every_fmu3):
    fixed = set()
    for model, (step, path) in every_fmu3.items():
        first, second = Running(path, f"{model}-1"), Running(path, f"{model}-2")
        # canBeInstantiatedOnlyOncePerProcess = false: two live instances do not share state
        before = second.slave.getFloat64(second.outputs, nValues=second.count)
        first.step(step)
        assert second.slave.getFloat64(second.outputs, nValues=second.count) == before, model
        # canGetAndSetFMUState / canSerializeFMUState: a step redone from a saved state and, bit for
        # bit, in a fresh instance from the serialized bytes
        state = first.slave.getFMUState()
        data = first.slave.serializeFMUState(state)
        time, expected = first.time, first.step(step)
        first.slave.setFMUState(state)
        first.time = time
        assert first.step(step) == expected, model
        restored = second.slave.deserializeFMUState(data)
        second.slave.setFMUState(restored)
        second.time = time
        assert second.step(step) == expected, model
        first.slave.freeFMUState(state)
        second.slave.freeFMUState(restored)
        # canHandleVariableCommunicationStepSize: other step lengths are taken, or refused (discard)
        accepts = True
        for h in (step / 2, 1.5 * step):
            try:
                first.step(h)
            except Exception as exc:
                assert "status 2" in str(exc) or "Discard" in str(exc) or "discard" in str(exc), (model, exc)
                accepts = False
                break
        assert declared(path)["canHandleVariableCommunicationStepSize"] == str(accepts).lower(), model
        fixed |= set() if accepts else {model}
        first.free()
        second.free()
    assert fixed == set()                    # the discrete GPEBO blocks sample at k Ts at any step (issue 36)


def test_a_discarded_step_says_why_with_logging_off(every_fmu3):
    """fmusim instantiates with logging off: a discarded step said nothing (rc 2, no message); debug messages
    stay off, but warnings, discards and errors are always given (issue 35, as the FMI 2.0 binary does)."""
    running = Running(every_fmu3["ship_observer"][1], "quiet", logging_on=False)
    try:
        assert running.messages == []          # nothing at instantiation and initialization (OK-level only)
        inputs = [(v.valueReference, len(elements_of(v))) for v in running.inputs]
        running.slave.setFloat64([vr for vr, _ in inputs], [float("nan")] * sum(n for _, n in inputs))
        with pytest.raises(Exception, match="2|Discard|discard"):
            running.slave.doStep(0.0, 1e-3)
        assert any(status == 2 and "not finite" in message for status, message in running.messages), running.messages
    finally:
        running.free()


def test_no_event_mode_and_no_model_exchange(every_fmu3, tmp_path):
    path = every_fmu3["ship_plant"][1]
    description = read_model_description(str(path))
    slave = FMU3Slave(guid=description.instantiationToken, unzipDirectory=extract(str(path), str(tmp_path)),
                      instanceName="plant", modelIdentifier="ship_plant")
    messages = []
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(eventModeUsed=True, logMessage=lambda env, status, category, message: messages.append(message))
    assert b"eventModeUsed = true, but this FMU has no event mode" in messages[0]
    assert not slave.fmi3InstantiateModelExchange(b"me", description.instantiationToken.encode(),
                                                  str(tmp_path / "resources").encode(), False, False, None,
                                                  slave.logMessage)


def test_intermediate_update_gives_the_fmi2_input_derivatives(every_fmu, every_fmu3):
    """The plant driven by u(t) = 0.3 + 2 t: FMI 3.0 with u(t + h) set in the intermediate update =
    FMI 2.0 with du/dt = 2; without the update, the FMI 3.0 plant holds u (a different result)."""
    h, steps, ramp = 1e-2, 20, (lambda t: 0.3 + 2.0 * t)
    calls = []

    def intermediate(environment, time, set_requested, get_allowed, finished, can_return_early, early, early_time):
        calls.append((time, set_requested, get_allowed, finished, can_return_early))
        running3.slave.setFloat64([u3], [ramp(time)])

    description2 = read_model_description(str(every_fmu["ship_plant"][1]))
    fmi2 = FMU2Slave(guid=description2.guid, unzipDirectory=extract(str(every_fmu["ship_plant"][1])),
                     instanceName="plant2", modelIdentifier="ship_plant")
    fmi2.instantiate()
    fmi2.setupExperiment(startTime=0.0)
    fmi2.enterInitializationMode()
    fmi2.exitInitializationMode()
    names2 = {v.name: v.valueReference for v in description2.modelVariables}
    u3 = next(v.valueReference for v in read_model_description(str(every_fmu3["ship_plant"][1])).modelVariables
              if v.name == "u")
    running3 = Running(every_fmu3["ship_plant"][1], "plant3", intermediate=intermediate, required=[u3])
    held = Running(every_fmu3["ship_plant"][1], "held")
    x3 = [v.valueReference for v in running3.description.modelVariables if v.name == "x"]
    results = {"fmi2": [], "fmi3": [], "held": []}
    for k in range(steps):
        t = k * h
        fmi2.setReal([names2["u"]], [ramp(t)])
        fmi2.setRealInputDerivatives([names2["u"]], [1], [2.0])
        fmi2.doStep(t, h)
        results["fmi2"].append(fmi2.getReal([names2["x[1]"], names2["x[2]"]]))
        for name, running in (("fmi3", running3), ("held", held)):
            running.slave.setFloat64([u3], [ramp(t)])
            running.slave.doStep(t, h)
            results[name].append(running.slave.getFloat64(x3, nValues=2))
    assert [c[0] for c in calls] == pytest.approx([(k + 1) * h for k in range(steps)], rel=0, abs=1e-15)
    assert all(c[1:] == (True, False, False, False) for c in calls)  # set requested; no get, tentative, no early return
    fmi2_x, fmi3_x, held_x = (np.array(results[k]) for k in ("fmi2", "fmi3", "held"))
    assert np.max(np.abs(fmi3_x - fmi2_x)) < 1e-15 * np.max(np.abs(fmi2_x)) + 1e-17
    assert np.max(np.abs(held_x - fmi2_x)) > 1e-6  # the update is what makes the difference
    for slave in (fmi2, running3.slave, held.slave):
        slave.freeInstance()


# ------------------------------------------------------------------ the master, FMI 3.0 and mixed

def _short(name):
    scenario = get(name)
    return dict(stop_time=STEPS * scenario.step, step=scenario.step)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_scenario_gives_the_fmi2_results(name, build_dir, every_fmu, every_fmu3):
    """The scenario's own order and coupling; FMI 2.0 vs FMI 3.0 FMUs under the same master."""
    fmi2, _ = run(name, build_dir, **_short(name))
    fmi3, _ = run(name, build_dir, **_short(name), fmi_version=3)
    assert fmi3.columns == fmi2.columns and np.array_equal(fmi3.time, fmi2.time)
    scale = max(1.0, float(np.max(np.abs(fmi2.values))))
    assert np.max(np.abs(fmi3.values - fmi2.values)) <= 1e-13 * scale  # measured: 0 to 9e-15


@pytest.mark.parametrize("order", ["gauss-seidel", "jacobi"])
def test_linear_coupling_reaches_the_fmi3_fmus(order, build_dir, every_fmu3):
    """With linear coupling the FMI 3.0 ship loop differs from the held one, and equals FMI 2.0's."""
    settings = dict(stop_time=0.05, step=1e-3, order=order)
    linear3, _ = run("ship", build_dir, **settings, fmi_version=3)
    held3, _ = run("ship", build_dir, **settings, coupling="hold", fmi_version=3)
    linear2, _ = run("ship", build_dir, **settings)
    assert np.max(np.abs(linear3.values - held3.values)) > 1e-4
    assert np.max(np.abs(linear3.values - linear2.values)) < 1e-13


def test_mixed_fmi2_and_fmi3_systems(build_dir, every_fmu, every_fmu3):
    scenario = get("ship")
    fmus2, fmus3 = ensure_fmus(scenario, build_dir), ensure_fmus(scenario, build_dir, fmi_version=3)
    reference = cosimulate(system(scenario, fmus2), 0.05, 1e-3)
    for fmi3_models in ({"ship_observer"}, {"ship_plant", "ship_controller"}):
        mixed = {model: (fmus3 if model in fmi3_models else fmus2)[model] for model in fmus2}
        result = cosimulate(system(scenario, mixed), 0.05, 1e-3)
        assert result.columns == reference.columns
        assert np.max(np.abs(result.values - reference.values)) < 1e-13, fmi3_models


def test_the_adaptive_master_rolls_fmi3_fmus_back(build_dir, every_fmu3):
    fmi2, _ = run("ship", build_dir, stop_time=0.02, step=1e-3, order="adaptive", tolerance=1e-5)
    fmi3, _ = run("ship", build_dir, stop_time=0.02, step=1e-3, order="adaptive", tolerance=1e-5, fmi_version=3)
    assert np.array_equal(fmi3.time, fmi2.time) and np.max(np.abs(fmi3.values - fmi2.values)) < 1e-13


def test_command_line_builds_and_runs_fmi3(tmp_path, capsys, build_dir, every_fmu3):
    assert cli.main(["build", "--fmi-version", "3", "--config", "examples/nomoto3.toml", "--out", str(tmp_path)]) == 0
    built = sorted(p.name for p in (tmp_path / "fmi3").glob("*.fmu"))
    assert built == ["nomoto3_observer.fmu", "nomoto3_plant.fmu"]
    assert "(valid)" in capsys.readouterr().out
    assert cli.main(["run", "ship", "--fmi-version", "3", "--stop-time", "0.01", "--build-dir", str(build_dir)]) == 0
    assert "ship: 500 steps to t = 0.01" in capsys.readouterr().out
