"""Every capability each scenario FMU declares is true of its behaviour (issue 12, item 4).

The declarations come from the definition (``FmuDefinition.variable_step``) and the binary; the
discrete GPEBO FMUs take one sample per step and declare ``canHandleVariableCommunicationStepSize
= false``.  ``canNotUseMemoryManagementFunctions`` is exercised by the C importer, which gives
no allocator (tests/fmus/native/importer.c).
"""

import zipfile
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

CHECKED = {"modelIdentifier", "needsExecutionTool", "canHandleVariableCommunicationStepSize", "canInterpolateInputs",
           "maxOutputDerivativeOrder", "canRunAsynchronuously", "canBeInstantiatedOnlyOncePerProcess",
           "canNotUseMemoryManagementFunctions", "canGetAndSetFMUstate", "canSerializeFMUstate",
           "providesDirectionalDerivative"}


class Running:
    """One initialized instance, inputs driven by small smooth signals."""

    def __init__(self, path, name):
        self.description = read_model_description(str(path))
        self.slave = FMU2Slave(guid=self.description.guid, unzipDirectory=extract(str(path)), instanceName=name,
                               modelIdentifier=self.description.coSimulation.modelIdentifier)
        variables = self.description.modelVariables
        self.inputs = [v.valueReference for v in variables if v.causality == "input" and v.type == "Real"]
        self.outputs = [v.valueReference for v in variables if v.causality == "output" and v.type == "Real"]
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()
        self.time = 0.0

    def step(self, h):
        if self.inputs:
            self.slave.setReal(self.inputs, [0.1 * np.sin(0.7 * self.time + i) for i in range(len(self.inputs))])
        self.slave.doStep(self.time, h)
        self.time += h
        return self.slave.getReal(self.outputs)

    def free(self):
        self.slave.freeInstance()


def declared(path) -> dict[str, str]:
    root = ElementTree.fromstring(zipfile.ZipFile(path).read("modelDescription.xml"))
    return dict(root.find("CoSimulation").attrib)


def test_only_checked_capabilities_are_declared(every_fmu):
    for model, (_, path) in every_fmu.items():
        assert set(declared(path)) <= CHECKED, (model, set(declared(path)) - CHECKED)


def test_variable_step_declaration_matches_behaviour(every_fmu):
    fixed = set()
    for model, (step, path) in every_fmu.items():
        running = Running(path, model)
        running.step(step)
        try:
            for h in (step / 2, 1.5 * step):
                running.step(h)
            accepts = True
        except FMICallException as exc:
            assert "discard" in str(exc), (model, exc)
            accepts = False
        running.free()
        assert declared(path)["canHandleVariableCommunicationStepSize"] == str(accepts).lower(), model
        fixed |= {model} if not accepts else set()
    assert fixed == set()                    # the discrete GPEBO blocks sample at k Ts at any step (issue 36)


#: scenario FMUs whose output has a declared time derivative (a sine source of a system file)
DERIVATIVE_SOURCES = {"ltv_ls_source", "ltv_ls_bounded_source"}


def test_state_input_and_instance_capabilities_hold(every_fmu):
    for model, (step, path) in every_fmu.items():
        capabilities = declared(path)
        first, second = Running(path, f"{model}-1"), Running(path, f"{model}-2")
        # canBeInstantiatedOnlyOncePerProcess = false: two live instances do not share state
        assert capabilities["canBeInstantiatedOnlyOncePerProcess"] == "false"
        before = second.slave.getReal(second.outputs)
        first.step(step)
        assert second.slave.getReal(second.outputs) == before, model
        # canGetAndSetFMUstate / canSerializeFMUstate: a step redone from a saved (and serialized) state
        assert capabilities["canGetAndSetFMUstate"] == capabilities["canSerializeFMUstate"] == "true"
        state = first.slave.getFMUstate()
        data = first.slave.serializeFMUstate(state)
        time, expected = first.time, first.step(step)
        restored = first.slave.deSerializeFMUstate(data)
        first.slave.setFMUstate(restored)
        first.time = time
        assert first.step(step) == expected, model
        first.slave.freeFMUstate(state)
        first.slave.freeFMUstate(restored)
        # canInterpolateInputs: first-order input derivatives are taken
        assert capabilities["canInterpolateInputs"] == "true"
        if first.inputs:
            first.slave.setRealInputDerivatives(first.inputs, [1] * len(first.inputs), [0.01] * len(first.inputs))
        # maxOutputDerivativeOrder = 0 (1: the sine sources of the paper-001 system files export dy/dt),
        # providesDirectionalDerivative = false, canRunAsynchronuously = false
        order = "1" if model in DERIVATIVE_SOURCES else "0"
        assert (capabilities["maxOutputDerivativeOrder"], capabilities["providesDirectionalDerivative"],
                capabilities["canRunAsynchronuously"]) == (order, "false", "false"), model
        unsupported = [lambda: first.slave.getDirectionalDerivative(first.outputs[:1], first.outputs[:1], [1.0]),
                       lambda: first.slave.cancelStep()]
        derivative = lambda: first.slave.getRealOutputDerivatives(first.outputs[:1], [1])   # noqa: E731
        if order == "1":
            assert len(derivative()) == 1, model
        else:
            unsupported.append(derivative)
        for call in unsupported:
            with pytest.raises(FMICallException, match="error"):
                call()
        # needsExecutionTool = true: the execution tool is a Python interpreter (see docs/portability.md)
        assert capabilities["needsExecutionTool"] == "true"
        first.free()
        second.free()
