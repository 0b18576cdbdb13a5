"""The FMI 2.0 co-simulation state machine, enforced by the FMU binary, checked from a C host.

The table of allowed calls per state is the standard's (FMI 2.0.4, section 4.2.4, "State
Machine of Calling Sequence from Master to Slave"; stepInProgress and stepCanceled never occur:
steps are synchronous).  Every (state, call) pair runs in ONE importer process (``importer.c``,
empty environment) on fresh instances of the ship observer: a refused call returns fmi2Error,
logs the call and the state, and leaves the instance in its state -- shown by a probe that only
that state passes.  The error state is reached the only way it can be, by a call that fails inside
the slave: a step of the test FMU ``faulty_plant`` whose user function has a bug (``faulty_fmus``);
calls the slave refuses leave the instance in its state (docs/faults.md).
"""

import pytest

from obsfmu.fmus.scenarios import ensure_fmus, get
from native_harness import Unzipped, parse_calls, run

OK, DISCARD, ERROR = 0, 2, 3

STATES = ["instantiated", "initializationMode", "stepComplete", "stepFailed", "terminated", "error"]
ALL = set(STATES)
READABLE = ALL - {"instantiated"}
SETTABLE = {"instantiated", "initializationMode", "stepComplete"}
STATUS = {"stepComplete", "stepFailed", "terminated"}
ALLOWED = {
    "setDebugLogging": ALL,
    "setupExperiment": {"instantiated"},
    "enterInitializationMode": {"instantiated"},
    "exitInitializationMode": {"initializationMode"},
    "terminate": {"stepComplete", "stepFailed"},
    "reset": ALL,
    **{f"get{t}": READABLE for t in ("Real", "Integer", "Boolean", "String")},
    **{f"set{t}": SETTABLE for t in ("Real", "Integer", "Boolean", "String")},
    **{call: ALL for call in ("getFMUstate", "setFMUstate", "freeFMUstate", "serializedFMUstateSize",
                              "serializeFMUstate", "deSerializeFMUstate")},
    "getDirectionalDerivative": READABLE,
    "setRealInputDerivatives": SETTABLE,
    "getRealOutputDerivatives": {"stepComplete", "stepFailed", "terminated", "error"},
    "doStep": {"stepComplete"},
    "cancelStep": set(),  # stepInProgress only
    **{f"get{t}Status": STATUS for t in ("", "Real", "Integer", "Boolean", "String")},
}

INIT = ["setupExperiment", "enterInitializationMode"]
STEPPING = INIT + ["exitInitializationMode"]
#: calls that bring a fresh instance into each state, with their expected statuses
PREFIX = {
    "instantiated": [],
    "initializationMode": [(c, OK) for c in INIT],
    "stepComplete": [(c, OK) for c in STEPPING + ["doStep"]],
    "stepFailed": [(c, OK) for c in STEPPING + ["setReal:nan"]] + [("doStep", DISCARD)],
    "terminated": [(c, OK) for c in STEPPING + ["doStep", "terminate"]],
    # on faulty_plant: x0[1] = 0 (its "setReal"), and the first step hits the bug of its user function
    "error": [(c, OK) for c in INIT + ["setReal", "exitInitializationMode"]] + [("doStep", ERROR)],
}
#: the instance the cases of each state run on
INSTANCE = {**{state: "observer" for state in STATES}, "error": "faulty"}
#: call sequences that only the given state passes (from the table above)
PROBE = {
    "instantiated": [("setupExperiment", OK)],
    "initializationMode": [("exitInitializationMode", OK)],
    "stepComplete": [("doStep", OK)],
    "stepFailed": [("doStep", ERROR), ("terminate", OK)],
    "terminated": [("terminate", ERROR), ("getBooleanStatus", OK)],
    "error": [("getBooleanStatus", ERROR), ("exitInitializationMode", ERROR), ("getReal", OK)],
}
#: refused arguments (state stepComplete): the loader's refusals, and the slave's (damaged state bytes,
#: a value reference that does not exist)
EXTRA = {
    "late-step": (["getRealStatus", "getReal", "doStep:late", "getRealStatus", "getReal", "doStep"],
                  [OK, OK, ERROR, OK, OK, OK]),
    "nan-time": (["doStep:tnan", "doStep"], [ERROR, OK]),
    "zero-step": (["doStep:h0", "doStep"], [ERROR, OK]),
    "negative-step": (["doStep:hneg", "doStep"], [ERROR, OK]),
    "nan-step": (["doStep:hnan", "doStep"], [ERROR, OK]),
    "infinite-step": (["doStep:hinf", "doStep"], [ERROR, OK]),
    "round-off-time": (["doStep:tnear", "doStep"], [OK, OK]),
    "order-2-derivative": (["setRealInputDerivatives:order2", "doStep"], [ERROR, OK]),
    "first-order-derivative": (["setRealInputDerivatives", "doStep"], [OK, OK]),
    "damaged-state-bytes": (["deSerializeFMUstate:flipped", "doStep"], [ERROR, OK]),
    "unknown-value-reference": (["getReal:bad", "doStep"], [ERROR, OK]),
}
#: what the slave makes of a call, and what the state machine does with it: instance, calls from a fresh
#: instance, their statuses, the state it is in then (checked by its probe).  A call the slave REFUSES
#: returns fmi2Error and leaves the instance in its state; a call that FAILS inside the slave -- a bug in
#: a user's function, which the slave logs at Error level and returns from (the step itself says Discard:
#: fmi2Error by the status rule) -- leads to the error state.
SLAVE = {
    "slave-refuses-an-interpolation-mode": ("observer", INIT + ["setInteger:7"], [OK, OK, ERROR], "initializationMode"),
    "slave-refuses-a-fixed-parameter": ("observer", STEPPING + ["doStep", "setInteger"], [OK] * 4 + [ERROR],
                                        "stepComplete"),
    "slave-logs-an-error": ("faulty", INIT + ["setReal", "exitInitializationMode", "doStep"], [OK] * 4 + [ERROR],
                            "error"),
}
#: the message of the last call of each SLAVE case, and the level it is logged at
SLAVE_SAYS = {"slave-refuses-an-interpolation-mode": "3 set_integer refused: y_interpolation: 7 is not 0",
              "slave-refuses-a-fixed-parameter": "3 set_integer refused: y_interpolation (in use: 0): parameters are "
                                                 "fixed after initialization",
              "slave-logs-an-error": "3 do_step(t=0, h=0.001) refused, state unchanged: RuntimeError: deliberate bug"}


def case_id(state, call):
    return f"{state}/{call}"


@pytest.fixture(scope="module")
def table(importer, build_dir, faulty_fmus, tmp_path_factory):
    """Every case of this module, run by one importer process; ``case id -> [(call, status, value, logs)]``."""
    fmus = ensure_fmus(get("ship"), build_dir)
    work = tmp_path_factory.mktemp("state_machine")
    observer = Unzipped.of("observer", fmus["ship_observer"], work)
    faulty = Unzipped.of("faulty", faulty_fmus[2], work)
    vrs = {"observer": f"{observer.vr('y')} {observer.vr('x_hat[1]')} {observer.vr('y_interpolation')}",
           "faulty": f"{faulty.vr('x0[1]')} {faulty.vr('y')} {faulty.vr('u_interpolation')}"}  # in, out, mode
    lines = [observer.declaration(), faulty.declaration()]
    for state in STATES:
        for call in ALLOWED:
            probe = [] if state in ALLOWED[call] else [c for c, _ in PROBE[state]]
            tokens = [c for c, _ in PREFIX[state]] + [call] + probe
            instance = INSTANCE[state]
            lines.append(f"calls {case_id(state, call)} {instance} {vrs[instance]} {' '.join(tokens)}")
    step_complete = " ".join(c for c, _ in PREFIX["stepComplete"])
    for name, (tokens, _) in EXTRA.items():
        lines.append(f"calls {name} observer {vrs['observer']} {step_complete} {' '.join(tokens)}")
    for name, (instance, tokens, _, state) in SLAVE.items():
        probe = [c for c, _ in PROBE[state]]
        lines.append(f"calls {name} {instance} {vrs[instance]} {' '.join(tokens + probe)}")
    lines.append(f"calls bad-guid observer {vrs['observer']} instantiate:badguid")
    completed = run(importer, lines, work)
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr
    return parse_calls(completed.stdout)


def check_prefix(results, state):
    expected = PREFIX[state]
    assert [(c, s) for c, s, _, _ in results[:len(expected)]] == expected
    return results[len(expected):]


@pytest.mark.parametrize("call", sorted(ALLOWED))
@pytest.mark.parametrize("state", STATES)
def test_state_machine_table(table, state, call):
    (name, status, _, logs), *probe = check_prefix(table[case_id(state, call)], state)
    assert name == call
    refusal = f"fmi2{call[0].upper()}{call[1:]} is not allowed in state {state}"
    if state in ALLOWED[call]:
        assert not any("is not allowed in state" in line for line in logs), logs
    else:
        assert status == ERROR and any(refusal in line for line in logs), logs
        assert [(c, s) for c, s, _, _ in probe] == PROBE[state]  # the state is unchanged


@pytest.mark.parametrize("name", sorted(EXTRA))
def test_refused_arguments_change_nothing(table, name):
    results = check_prefix(table[name], "stepComplete")
    tokens, statuses = EXTRA[name]
    assert [(c, s) for c, s, _, _ in results] == list(zip(tokens, statuses))
    for call, status, _, logs in results:
        if status == ERROR:
            assert logs, f"{call} returned fmi2Error without saying why"
    if name == "late-step":  # time and outputs before and after the refused step are identical
        values = [value for _, _, value, _ in results]
        assert values[0] == values[3] == pytest.approx(1e-3) and values[1] == values[4]
        assert "currentCommunicationPoint" in results[2][3][0]
    if name == "unknown-value-reference":
        assert "value reference 999999 does not exist" in results[0][3][0]


@pytest.mark.parametrize("name", sorted(SLAVE))
def test_refused_calls_keep_the_state_failed_calls_lead_to_error(table, name):
    _, tokens, statuses, state = SLAVE[name]
    results = table[name]
    assert [(c, s) for c, s, _, _ in results] == list(zip(tokens, statuses)) + PROBE[state]
    logs = results[len(tokens) - 1][3]
    assert any(line.startswith(SLAVE_SAYS[name]) for line in logs), logs


def test_wrong_guid_is_refused(table):
    ((name, status, _, logs),) = table["bad-guid"]
    assert status == -1 and any("GUID {not-the-guid} is not this FMU's" in line for line in logs), logs
