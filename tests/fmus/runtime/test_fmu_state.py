"""FMU capabilities on every FMU of every scenario: state save/restore and serialisation, bit for bit."""

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu


@pytest.fixture(scope="module")
def fmus(every_fmu):
    return every_fmu


def drive(slave, description, step, start, count):
    """Feed every input a smooth deterministic signal; return all outputs after each step."""
    inputs = [v.valueReference for v in description.modelVariables if v.causality == "input" and v.type == "Real"]
    outputs = [v.valueReference for v in description.modelVariables if v.causality == "output" and v.type == "Real"]
    recorded = []
    for k in range(start, start + count):
        t = k * step
        if inputs:
            slave.setReal(inputs, [0.1 * np.sin(0.7 * t + i) for i in range(len(inputs))])
            slave.setRealInputDerivatives(inputs, [1] * len(inputs),
                                          [0.07 * np.cos(0.7 * t + i) for i in range(len(inputs))])
        slave.doStep(t, step)
        recorded.append(slave.getReal(outputs))
    return np.array(recorded)


def test_every_fmu_declares_and_validates(fmus):
    for model, (_, path) in fmus.items():
        assert validate_fmu(str(path)) == [], model
        cs = read_model_description(str(path)).coSimulation
        assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate and cs.canInterpolateInputs, model
        # canHandleVariableCommunicationStepSize differs per kind: tests/fmus/native/test_capabilities.py


def test_state_round_trip_is_bit_for_bit(fmus):
    for model, (step, path) in fmus.items():
        description = read_model_description(str(path))
        slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                          modelIdentifier=description.coSimulation.modelIdentifier, instanceName=model)
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        drive(slave, description, step, 0, 10)
        state = slave.getFMUstate()
        first = drive(slave, description, step, 10, 100)
        slave.setFMUstate(state)
        second = drive(slave, description, step, 10, 100)
        np.testing.assert_array_equal(first, second, err_msg=model)

        serialized = slave.serializeFMUstate(state)
        slave.freeFMUstate(state)
        drive(slave, description, step, 110, 5)  # move on, then come back from the bytes
        restored = slave.deSerializeFMUstate(serialized)
        slave.setFMUstate(restored)
        third = drive(slave, description, step, 10, 100)
        np.testing.assert_array_equal(first, third, err_msg=model)
        slave.freeFMUstate(restored)
        slave.terminate()
        slave.freeInstance()


def test_foreign_pickles_are_refused(fmus):
    _, path = fmus["ship_plant"]
    description = read_model_description(str(path))
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=description.coSimulation.modelIdentifier, instanceName="p")
    slave.instantiate()
    import os
    import pickle
    evil = pickle.dumps({"block": os.system})  # a global outside numpy and the project
    with pytest.raises(Exception, match="error"):
        slave.deSerializeFMUstate(evil)
    slave.freeInstance()
