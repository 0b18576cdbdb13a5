"""An FMI 3.0 instance driven through ctypes, every call returning its status (tests of the FMI 3.0 binary:
``test_fmi3_state_machine.py``, ``test_faults_fmi3.py``)."""

from ctypes import byref, c_bool, c_double, c_int32, c_size_t, c_uint32, c_void_p

from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3


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
