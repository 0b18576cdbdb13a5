"""The FMI 3.0 co-simulation state machine, enforced by the FMI 3.0 loader (fmus/native/loader_fmi3.c).

Every (state, call) pair of the table in docs/fmi3.md, on the ship plant's FMI 3.0 binary, called
through ctypes (the same binary as in any host): an allowed call is not refused; a refused one
returns fmi3Error, logs the call and the reason, and changes nothing -- a probe after it passes only
in the expected state.  Then the refused arguments, the intermediate update mode, a failure inside
the slave (-> terminated), a wrong instantiationToken and damaged serialized states.
"""

import math
from ctypes import byref, c_bool, c_double, c_float, c_int32, c_size_t, c_uint32, c_void_p

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi3 import FMU3Slave

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
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


class Raw:
    """An FMI 3.0 instance whose calls return their status (fmpy's wrappers would raise)."""

    def __init__(self, path, directory, name="plant", intermediate=None, required=(), state="x", parameter="x0"):
        self.description = read_model_description(str(path))
        self.vr = {v.name: v.valueReference for v in self.description.modelVariables}
        self.state, self.parameter = state, parameter  # an output array of 2, a parameter array of 2
        self.messages = []
        self.slave = FMU3Slave(guid=self.description.instantiationToken, unzipDirectory=directory,
                               instanceName=name, modelIdentifier=self.description.coSimulation.modelIdentifier)
        self.slave.instantiate(loggingOn=True, logMessage=self._log, intermediateUpdate=intermediate,
                               requiredIntermediateVariables=list(required))
        self.f = self.slave._functions
        self.c = self.slave.component
        self.time = 0.0
        self.last = c_double(float("nan"))

    def _log(self, environment, status, category, message):
        self.messages.append(message.decode())

    def refs(self, *names):
        return (c_uint32 * len(names))(*(self.vr[n] for n in names))

    def step(self, t=None, h=1e-3):
        flags = [c_bool() for _ in range(3)]
        t = self.time if t is None else t
        status = self.f["fmi3DoStep"](self.c, t, h, True, *map(byref, flags), byref(self.last))
        if status <= WARNING:
            self.time = t + h
        return status

    def get(self, name, count):
        values = (c_double * count)()
        return self.f["fmi3GetFloat64"](self.c, self.refs(name), 1, values, count), list(values)

    def set(self, name, values):
        return self.f["fmi3SetFloat64"](self.c, self.refs(name), 1, (c_double * len(values))(*values), len(values))

    def call(self, name: str) -> int:
        f, c, empty = self.f, self.c, (c_uint32 * 1)()
        if name == "enterInitializationMode":
            return f["fmi3EnterInitializationMode"](c, False, 0.0, 0.0, False, 0.0)
        if name == "exitInitializationMode":
            return f["fmi3ExitInitializationMode"](c)
        if name == "doStep":
            return self.step()
        if name == "terminate":
            return f["fmi3Terminate"](c)
        if name == "reset":
            status = f["fmi3Reset"](c)
            self.time = 0.0 if status <= WARNING else self.time
            return status
        if name == "getFloat64":
            return self.get(self.state, 2)[0]
        if name == "getInt32":
            return f["fmi3GetInt32"](c, self.refs("u_interpolation"), 1, (c_int32 * 1)(), 1)
        if name == "getBoolean":
            return f["fmi3GetBoolean"](c, empty, 0, (c_bool * 1)(), 0)
        if name == "setFloat64:input":
            return self.set("u", [0.5])
        if name == "setFloat64:parameter":
            return self.set(self.parameter, [0.1, 0.2])
        if name == "setInt32":
            return f["fmi3SetInt32"](c, self.refs("u_interpolation"), 1, (c_int32 * 1)(1), 1)
        if name in ("getFMUState", "setFMUState", "serializedFMUStateSize"):
            state = c_void_p()
            status = f["fmi3GetFMUState"](c, byref(state))
            if name == "setFMUState" and status <= WARNING:
                status = f["fmi3SetFMUState"](c, state)
            elif name == "serializedFMUStateSize" and status <= WARNING:
                status = f["fmi3SerializedFMUStateSize"](c, state, byref(c_size_t()))
            if state:
                f["fmi3FreeFMUState"](c, byref(state))
            return status
        if name == "enterEventMode":
            return f["fmi3EnterEventMode"](c)
        if name == "enterStepMode":
            return f["fmi3EnterStepMode"](c)
        if name == "enterConfigurationMode":
            return f["fmi3EnterConfigurationMode"](c)
        if name == "getOutputDerivatives":
            return f["fmi3GetOutputDerivatives"](c, self.refs("y"), 1, (c_int32 * 1)(1), (c_double * 1)(), 1)
        if name == "getDirectionalDerivative":
            return f["fmi3GetDirectionalDerivative"](c, self.refs("y"), 1, self.refs("u"), 1, (c_double * 1)(1.0), 1,
                                                     (c_double * 1)(), 1)
        if name == "updateDiscreteStates":
            flags = [c_bool() for _ in range(5)]
            return f["fmi3UpdateDiscreteStates"](c, *map(byref, flags), byref(c_double()))
        raise KeyError(name)

    def reach(self, state: str) -> None:
        for call in {"instantiated": [], "initializationMode": ["enterInitializationMode"],
                     "stepMode": ["enterInitializationMode", "exitInitializationMode"],
                     "terminated": ["enterInitializationMode", "exitInitializationMode", "doStep", "terminate"]}[state]:
            assert self.call(call) <= WARNING, (call, self.messages)

    def is_in(self, state: str) -> bool:
        """A probe that only ``state`` passes (the state machine's state)."""
        if state == "instantiated":
            return self.call("enterInitializationMode") == OK
        if state == "initializationMode":
            return self.call("exitInitializationMode") == OK
        if state == "stepMode":
            return self.step() == OK
        return self.call("setFloat64:input") == ERROR and self.call("getFloat64") == OK and self.step() == ERROR

    def free(self):
        self.f["fmi3FreeInstance"](self.c)


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


def test_a_failure_in_the_slave_terminates(plant):
    raw = Raw(*plant)
    raw.reach("initializationMode")
    status = raw.f["fmi3SetInt32"](raw.c, raw.refs("u_interpolation"), 1, (c_int32 * 1)(7), 1)
    assert status == ERROR and any("u_interpolation" in m for m in raw.messages)
    assert raw.is_in("terminated")
    assert raw.call("reset") == OK and raw.is_in("instantiated")  # the way on: reset (or a saved state)
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
    assert "damaged (checksum mismatch)" in raw.messages[-1]
    data[len(data) // 2] ^= 0x10
    data[7] = 1  # the FMI 2.0 loader's magic: another version's state
    with pytest.raises(FMICallException, match="error"):
        raw.slave.deserializeFMUState(bytes(data))
    assert "not a serialized state of an obsfmu FMU of this version" in raw.messages[-1]
    assert raw.is_in("stepMode")
    raw.slave.freeFMUState(state)
    raw.free()
