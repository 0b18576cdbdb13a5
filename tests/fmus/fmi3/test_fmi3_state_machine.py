"""The FMI 3.0 co-simulation state machine, enforced by the FMI 3.0 loader (fmus/native/loader_fmi3.c).

Every (state, call) pair of the table in docs/fmi3.md, on the ship plant's FMI 3.0 binary, called
through ctypes (the same binary as in any host): an allowed call is not refused; a refused one
returns fmi3Error, logs the call and the reason, and changes nothing -- a probe after it passes only
in the expected state.  Then the refused arguments, the intermediate update mode, calls the slave
refuses (the state is kept) against a call that fails inside it (a bug in a user's function:
-> terminated), a wrong instantiationToken, damaged, foreign and forged serialized states.
"""

import math
import struct
from ctypes import c_double, c_float, c_int32, c_uint32

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from fmi3_support import DISCARD, ERROR, OK, WARNING, Raw
from obsfmu.fmus.runtime.state_format import decode, pack

STATES = ["instantiated", "initializationMode", "stepMode", "terminated"]
EVERY = set(STATES)

#: call -> states where the state machine lets it through (docs/fmi3.md)
ALLOWED = {
    "enterInitializationMode": {"instantiated"},
    "exitInitializationMode": {"initializationMode"},
    "doStep": {"stepMode"},
    "terminate": {"stepMode"},
    "reset": EVERY,
    "getFloat64": EVERY,
    "getInt32": EVERY,
    "getBoolean": EVERY,
    "setFloat64:input": {"instantiated", "initializationMode", "stepMode"},
    "setFloat64:parameter": {"instantiated", "initializationMode"},
    "setInt32": {"instantiated", "initializationMode"},
    "getFMUState": EVERY,
    "setFMUState": EVERY,
    "serializedFMUStateSize": EVERY,
    "enterEventMode": set(),
    "enterStepMode": set(),
    "enterConfigurationMode": set(),
    "getOutputDerivatives": set(),
    "getDirectionalDerivative": set(),
    "updateDiscreteStates": set(),
}
#: where an allowed call leads
LEADS_TO = {"enterInitializationMode": "initializationMode", "exitInitializationMode": "stepMode",
            "terminate": "terminated", "reset": "instantiated"}


@pytest.fixture(scope="module")
def plant(every_fmu3, tmp_path_factory):
    path = every_fmu3["ship_plant"][1]
    return path, extract(str(path), str(tmp_path_factory.mktemp("plant3")))


@pytest.mark.parametrize("state", STATES)
@pytest.mark.parametrize("call", list(ALLOWED))
def test_state_machine_table(plant, state, call):
    raw = Raw(*plant)
    raw.reach(state)
    before = len(raw.messages)
    status = raw.call(call)
    if state in ALLOWED[call]:
        assert status <= WARNING, (status, raw.messages[before:])
        assert raw.is_in(LEADS_TO.get(call, state)), raw.messages
    else:
        assert status == ERROR, status
        (message,) = raw.messages[before:]
        if not ALLOWED[call]:
            reason = "is not supported"
        elif call in ("setFloat64:parameter", "setInt32") and state == "stepMode":
            reason = "is a fixed parameter: it can be set only before fmi3ExitInitializationMode"
        else:
            reason = f"is not allowed in state {state}"
        assert reason in message, message
        assert raw.is_in(state), raw.messages  # nothing changed
    raw.free()


@pytest.mark.parametrize("t, h, why", [(1.0, 1e-3, "is not the FMU's current time"),
                                       (math.nan, 1e-3, "is not the FMU's current time"),
                                       (0.0, 0.0, "is not a positive finite number"),
                                       (0.0, -1e-3, "is not a positive finite number"),
                                       (0.0, math.nan, "is not a positive finite number"),
                                       (0.0, math.inf, "is not a positive finite number")])
def test_refused_steps_change_nothing(plant, t, h, why):
    raw = Raw(*plant)
    raw.reach("stepMode")
    _, before = raw.get("x", 2)
    assert raw.step(t, h) == ERROR and why in raw.messages[-1]
    assert raw.get("x", 2)[1] == before and raw.time == 0.0
    assert raw.step(1e-12, 1e-3) == OK  # within 1e-9 of the current time: taken, on the importer's time
    assert raw.last.value == 1e-12 + 1e-3
    raw.free()


def test_refused_values_calls(plant):
    raw = Raw(*plant)
    raw.reach("initializationMode")
    values = (c_double * 3)()
    checks = [
        (lambda: raw.f["fmi3GetFloat64"](raw.c, raw.refs("x"), 1, values, 3), "nValues is 3, but"),
        (lambda: raw.f["fmi3GetFloat64"](raw.c, (c_uint32 * 1)(9999), 1, values, 1), "value reference 9999 does not"),
        (lambda: raw.f["fmi3GetInt32"](raw.c, raw.refs("x"), 1, (c_int32 * 2)(), 2), "x (value reference"),
        (lambda: raw.set("y", [1.0]), "y is an output: it cannot be set"),
        (lambda: raw.set("time", [1.0]), "time is the independent variable"),
        (lambda: raw.f["fmi3GetFloat32"](raw.c, raw.refs("u"), 1, (c_float * 1)(), 1), "fmi3GetFloat32: u"),
    ]
    for call, message in checks:
        assert call() == ERROR and message in raw.messages[-1], raw.messages[-1]
    assert raw.is_in("initializationMode")
    time = (c_double * 1)()
    assert raw.f["fmi3GetFloat64"](raw.c, raw.refs("time"), 1, time, 1) == OK and time[0] == 0.0
    raw.free()


def test_calls_the_slave_refuses_keep_the_state(plant):
    """fmi3Error from the slave for a call it refused (it changed nothing): the FMU stays where it was."""
    raw = Raw(*plant)
    raw.reach("initializationMode")
    status = raw.f["fmi3SetInt32"](raw.c, raw.refs("u_interpolation"), 1, (c_int32 * 1)(7), 1)
    assert status == ERROR and "u_interpolation: 7 is not 0 (hold), 1 (extrapolate) or 2" in raw.messages[-1]
    assert raw.is_in("initializationMode")
    raw.free()


def test_a_failure_in_the_slave_terminates(faulty_fmus, tmp_path):
    """A step that fails inside the slave (a bug in the user's function; the slave logs it at Error level
    and returns, so fmi3Error by the status rule) leads to terminated; reset (or a saved state) goes on."""
    path = faulty_fmus[3]
    raw = Raw(path, extract(str(path), str(tmp_path)), name="faulty")
    raw.reach("initializationMode")
    assert raw.set("x0", [0.0, -0.2]) == OK
    assert raw.call("exitInitializationMode") == OK
    assert raw.step() == ERROR
    assert "RuntimeError: deliberate bug of the test FMU: f(0) is not implemented (a bug: please report)" \
        in raw.messages[-1]
    assert raw.is_in("terminated")
    assert raw.call("reset") == OK and raw.is_in("instantiated")
    raw.free()


def test_discarded_step_stays_in_step_mode(plant):
    """fmi3Discard: the slave kept its state; the FMU is still in step mode at the same time."""
    raw = Raw(*plant)
    raw.reach("stepMode")
    assert raw.step() == OK
    _, before = raw.get("x", 2)
    assert raw.set("u", [math.nan]) == OK
    assert raw.step() == DISCARD and raw.last.value == pytest.approx(1e-3)
    assert raw.get("x", 2)[1] == before
    assert raw.set("u", [0.0]) == OK and raw.step() == OK and raw.time == pytest.approx(2e-3)
    raw.free()


def test_intermediate_update_mode(every_fmu3, tmp_path):
    """Inside the callback only the required inputs can be set; everything else is refused."""
    path = every_fmu3["ship_observer"][1]
    directory = extract(str(path), str(tmp_path))
    seen = {}

    def intermediate(environment, time, set_requested, get_allowed, finished, can_return_early, early, early_time):
        seen["statuses"] = {name: raw.call(name) for name in ("doStep", "terminate", "reset", "getFloat64",
                                                              "getFMUState", "setFloat64:parameter")}
        seen["required"] = raw.set("u", [1.0])
        seen["other"] = raw.set("y", [1.0])

    variables = {v.name: v.valueReference for v in read_model_description(str(path)).modelVariables}
    raw = Raw(path, directory, name="observer", intermediate=intermediate, required=[variables["u"]],
              state="x_hat", parameter="x_hat0")
    raw.reach("stepMode")
    assert raw.step() == OK
    assert set(seen["statuses"].values()) == {ERROR}, seen
    assert seen["required"] == OK and seen["other"] == ERROR
    assert any("not in requiredIntermediateVariables" in m for m in raw.messages)
    assert any("is not allowed in state intermediateUpdateMode" in m for m in raw.messages)
    raw.free()
    messages = []
    slave = FMU3Slave(guid=read_model_description(str(path)).instantiationToken, unzipDirectory=directory,
                      instanceName="o", modelIdentifier="ship_observer")
    with pytest.raises(Exception, match="Failed to instantiate"):  # only inputs can be intermediate variables
        slave.instantiate(logMessage=lambda *a: messages.append(a[3]), requiredIntermediateVariables=[variables["x_hat"]],
                          intermediateUpdate=lambda *a: None)
    assert b"only inputs have intermediateUpdate = true" in messages[0]


def test_wrong_token_and_damaged_states(plant):
    path, directory = plant
    messages = []
    slave = FMU3Slave(guid="{not-the-token}", unzipDirectory=directory, instanceName="p", modelIdentifier="ship_plant")
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(logMessage=lambda *a: messages.append(a[3]))
    assert b"instantiationToken {not-the-token} is not this FMU's" in messages[0]
    raw = Raw(path, directory)
    raw.reach("stepMode")
    state = raw.slave.getFMUState()
    data = bytearray(raw.slave.serializeFMUState(state))
    data[len(data) // 2] ^= 0x10
    with pytest.raises(FMICallException, match="error"):
        raw.slave.deserializeFMUState(bytes(data))
    assert "checksum mismatch: the state bytes are damaged" in raw.messages[-1]
    assert raw.is_in("stepMode")
    raw.slave.freeFMUState(state)
    raw.free()


def fmi2_state_of_the_ship_plant(ship_fmus) -> bytes:
    description = read_model_description(str(ship_fmus["ship_plant"]))
    fmu2 = FMU2Slave(guid=description.guid, unzipDirectory=extract(str(ship_fmus["ship_plant"])), instanceName="p2",
                     modelIdentifier="ship_plant")
    fmu2.instantiate()
    fmu2.setupExperiment(startTime=0.0)
    fmu2.enterInitializationMode()
    fmu2.exitInitializationMode()
    state = fmu2.getFMUstate()
    data = bytes(fmu2.serializeFMUstate(state))
    fmu2.freeFMUstate(state)
    fmu2.freeInstance()
    return data


def tree_of(data: bytes) -> tuple[str, dict]:
    """The identity and the tree of serialized state bytes (fmus/runtime/state_format.py: 24-byte header, digest)."""
    size = struct.unpack_from("<I", data, 12)[0]
    return data[56:56 + size].decode(), decode(data[56 + size:])


def test_states_of_the_fmi2_fmu_and_forged_loader_fields_are_refused(plant, ship_fmus):
    """One serialized format for both FMI versions: the FMI 2.0 FMU's state is another FMU's (its GUID is
    not this instantiationToken); a state of this FMU whose loader fields were forged (valid checksum) is
    refused by the loader: another FMI version's, an unknown state, a state machine state that does not
    agree with the slave's initialization, no loader fields.  Nothing changes; the FMU keeps stepping."""
    raw = Raw(*plant)
    raw.reach("stepMode")
    state = raw.slave.getFMUState()
    identity, tree = tree_of(bytes(raw.slave.serializeFMUState(state)))
    raw.slave.freeFMUState(state)
    assert tree["loader"] == {"fmi": 3, "state": "stepMode"} and tree["initialized"] is True
    assert identity == f"ship_plant {raw.description.instantiationToken}"
    forgeries = {
        "belongs to another FMU": fmi2_state_of_the_ship_plant(ship_fmus),
        "was saved by the FMI 2.0 binary of this FMU; this is the FMI 3.0 binary": {"fmi": 2, "state": "stepMode"},
        "the state machine state stepComplete of the state is unknown": {"fmi": 3, "state": "stepComplete"},
        "state machine state initializationMode, but the slave was initialized":
            {"fmi": 3, "state": "initializationMode"},
        "the state holds no state machine fields": None,
    }
    for message, forged in forgeries.items():
        data = forged if isinstance(forged, bytes) else pack(identity, {**tree, "loader": forged})
        with pytest.raises(FMICallException, match="error"):
            raw.slave.deserializeFMUState(data)
        assert message in raw.messages[-1], raw.messages[-1]
        assert raw.is_in("stepMode")
    raw.free()
