"""The rows of the fault table (docs/faults.md) through the FMI 3.0 binary, called with ctypes.

The slave is the one of the FMI 2.0 FMUs (``tests/faults/test_faults_*.py`` try every row on every kind
through the FMI 2.0 binary); what the FMI 3.0 binary adds is the way it treats each status: a
refused step (fmi3Discard) leaves the FMU in step mode at the same time with its state, and the next
step works; a call the slave refuses (fmi3Error, nothing changed) leaves the FMU in its state; a call
that fails inside the slave leads to terminated (``test_fmi3_state_machine.py``, with the loader's
own refusals).  One representative per row.
"""

from __future__ import annotations

import math
import pickle
import struct
from ctypes import byref, c_ubyte, c_void_p

import pytest
from fmpy import extract, read_model_description

from fmi3_support import DISCARD, ERROR, OK, Raw
from obsfmu.fmus.fmi3.elements import elements
from obsfmu.fmus.runtime.state_format import FORMAT_VERSION, decode, pack


@pytest.fixture(scope="module")
def fmu(every_fmu3, tmp_path_factory):
    """``model -> (path, unzipped directory)``, each FMI 3.0 FMU extracted once."""
    unzipped = {}

    def get(model: str):
        if model not in unzipped:
            path = every_fmu3[model][1]
            unzipped[model] = (path, extract(str(path), str(tmp_path_factory.mktemp(model))))
        return unzipped[model]
    return get


def size(raw: Raw, variable: str) -> int:
    return sum(e.variable == variable for e in elements(raw.description).values())


def output(raw: Raw) -> tuple[str, int]:
    name = next(v.name for v in raw.description.modelVariables if v.causality == "output")
    return name, size(raw, name)


def instance(fmu, model: str, state: str = "stepMode") -> Raw:
    raw = Raw(*fmu(model), name=model)
    raw.reach(state)
    return raw


def state_bytes(raw: Raw) -> bytes:
    state = c_void_p()
    assert raw.f["fmi3GetFMUState"](raw.c, byref(state)) == OK
    data = bytes(raw.slave.serializeFMUState(state))
    raw.slave.freeFMUState(state)
    return data


def restore(raw: Raw, data: bytes) -> tuple[int, str]:
    """Deserialize and set ``data``: the first non-OK status (or OK) and the last message."""
    state = c_void_p()
    status = raw.f["fmi3DeserializeFMUState"](raw.c, (c_ubyte * len(data)).from_buffer_copy(data), len(data),
                                              byref(state))
    if status == OK:
        status = raw.f["fmi3SetFMUState"](raw.c, state)
        raw.f["fmi3FreeFMUState"](raw.c, byref(state))
    return status, raw.messages[-1] if raw.messages else ""


# ------------------------------------------------------------------------------ refused steps: fmi3Discard
#: row -> (model, inputs set before the step, step, what the log says, the step that works afterwards)
DISCARDED = {
    "input NaN": ("ship_observer", {"y": math.nan}, 1e-3, "input y = nan is not finite", 1e-3),
    "input beyond the bound": ("ship_observer", {"u": 1e308}, 1e-3, "input u = 1e+308 exceeds the bound 1e+100",
                               1e-3),
    "new state not finite": ("ship_plant", {}, 400.0, "after the step state x", 1e-3),
    "failure inside the block": ("state_affine_chemostat_observer", {"u": 9e99, "y": 9e99}, 1e-3,
                                 "SignalError: Delta, Y: det overflowed", 1e-3),
    "sub-step budget": ("ltv_ls_observer", {}, 1e6, "substep_budget: the step h = 1e+06", 1e-3),
    "discrete block, more samples than its budget": ("gpebo_observer", {}, 1e6,
                                                      "substep_budget: the step h = 1e+06 contains 1e+06 samples", 1.0),
}


@pytest.mark.parametrize("row", sorted(DISCARDED))
def test_a_refused_step_is_discarded_and_the_next_step_works(fmu, row):
    model, inputs, h, message, good_step = DISCARDED[row]
    raw = instance(fmu, model)
    name, count = output(raw)
    for variable, value in inputs.items():
        assert raw.set(variable, [value]) == OK
    for _ in range(8):                             # some failures take a few steps to build up
        before, outputs = state_bytes(raw), raw.get(name, count)[1]
        status = raw.step(h=h)
        if status != OK:
            break
    assert status == DISCARD and any(message in m for m in raw.messages), raw.messages[-3:]
    assert raw.last.value == raw.time                          # lastSuccessfulTime: the step start
    assert raw.get(name, count)[1] == outputs and state_bytes(raw) == before   # step mode, state unchanged
    for variable in inputs:
        assert raw.set(variable, [0.0]) == OK
    assert raw.step(h=good_step) == OK, raw.messages[-3:]
    raw.free()


def test_an_intermediate_input_beyond_the_bound_is_discarded(fmu):
    """FMI 3.0 has no input derivatives: the inputs the importer gives in the intermediate update at
    t + h are checked as FMI 2.0's derivatives are (the slope they define, and the value at the end);
    the step is discarded and changes nothing, and the next one works."""
    path, directory = fmu("ship_observer")
    given = {"y": math.nan}

    def intermediate(environment, time, set_requested, get_allowed, finished, can_return_early, early, early_time):
        raw.set("y", [given["y"]])

    y = next(v.valueReference for v in read_model_description(str(path)).modelVariables if v.name == "y")
    raw = Raw(path, directory, name="observer", intermediate=intermediate, required=[y])
    raw.reach("stepMode")
    before = state_bytes(raw)
    assert raw.step() == DISCARD and "input derivative der(y) = nan is not finite" in raw.messages[-1]
    assert state_bytes(raw) == before                  # the slopes of the discarded step are given back
    assert raw.set("y", [9e99]) == OK                  # 9e99 at t, 1.8e100 at t + h: the slope is within
    given["y"] = 1.8e100                               # the bound, the value at the step end is not
    before = state_bytes(raw)
    assert raw.step(h=1.0) == DISCARD
    assert "input y at the step end (value + h * derivative) = 1.8e+100 exceeds" in raw.messages[-1]
    assert state_bytes(raw) == before
    given["y"] = 0.5
    assert raw.set("y", [0.0]) == OK and raw.step() == OK
    raw.free()


# ------------------------------------------------------------------------------ refused by the slave: fmi3Error, state kept
def test_an_invalid_parameter_set_is_refused_at_exit_and_can_be_corrected(fmu):
    raw = instance(fmu, "ship_observer", "initializationMode")
    n = size(raw, "N")
    _, good = raw.get("N", n)
    for bad, message in (([math.nan] * n, "N[1] = nan"), ([1e308] * n, "N[1] = 1e+308"), ([0.0] * n, "N: not Hurwitz")):
        assert raw.set("N", bad) == OK
        assert raw.call("exitInitializationMode") == ERROR and message in raw.messages[-1], raw.messages[-1]
        assert raw.get("x_hat", size(raw, "x_hat"))[0] == ERROR   # outputs of no valid block: refused too
        assert "cannot be computed: the parameters do not define a valid block" in raw.messages[-1]
    assert raw.set("N", good) == OK                              # still in initialization mode
    assert raw.call("exitInitializationMode") == OK and raw.step() == OK
    raw.free()


def test_first_outputs_beyond_the_bound_are_refused_at_exit(fmu):
    raw = instance(fmu, "ship_plant", "initializationMode")
    assert raw.set("x0", [9e99] * size(raw, "x0")) == OK
    assert raw.set("C", [100.0] * size(raw, "C")) == OK
    assert raw.call("exitInitializationMode") == ERROR
    assert "the first outputs are not usable: output y = 1.8e+102 exceeds the bound 1e+100" in raw.messages[-1]
    assert raw.set("x0", [0.0] * size(raw, "x0")) == OK and raw.call("exitInitializationMode") == OK
    raw.free()


def test_the_state_of_another_fmu_is_refused_in_memory_and_as_bytes(fmu):
    observer, plant = instance(fmu, "ship_observer"), instance(fmu, "ship_plant")
    foreign = c_void_p()
    assert plant.f["fmi3GetFMUState"](plant.c, byref(foreign)) == OK
    before = state_bytes(observer)
    assert observer.f["fmi3SetFMUState"](observer.c, foreign) == ERROR
    assert "is not a state of this FMU (another FMU's" in observer.messages[-1]  # the loader's handle check
    assert restore(observer, state_bytes(plant)) == (ERROR, observer.messages[-1])
    assert "belongs to another FMU" in observer.messages[-1]
    assert state_bytes(observer) == before and observer.step() == OK
    plant.f["fmi3FreeFMUState"](plant.c, byref(foreign))
    plant.free()
    observer.free()


def _forged(good: bytes, change) -> bytes:
    size_ = struct.unpack_from("<I", good, 12)[0]
    tree = decode(good[56 + size_:])
    change(tree)
    return pack(good[56:56 + size_].decode(), tree)


def _first_block_array(tree):
    return next(key for key, value in tree["block"].items() if getattr(value, "dtype", None) == "float64")


BAD_BYTES = {
    "another format version": (lambda good: good[:8] + struct.pack("<H", FORMAT_VERSION + 1) + good[10:],
                               f"state format version {FORMAT_VERSION + 1}"),
    "truncated": (lambda good: good[:-3], "truncated or extended"),
    "bit-flipped": (lambda good: good[:100] + bytes([good[100] ^ 4]) + good[101:], "checksum mismatch"),
    "a pickle": (lambda good: pickle.dumps({"x_hat": [1.0] * 20}), "not an obsfmu FMU state"),
    "forged: wrong shape": (lambda good: _forged(good, lambda t: t["block"].update(
        {_first_block_array(t): [1.0]})), "expected an array float64"),
    "forged: NaN in the state": (lambda good: _forged(good, lambda t: t["block"].update(
        {_first_block_array(t): t["block"][_first_block_array(t)] * math.nan})), "is not finite"),
}


@pytest.mark.parametrize("row", sorted(BAD_BYTES))
def test_bad_state_bytes_are_refused_and_change_nothing(fmu, row):
    make, message = BAD_BYTES[row]
    raw = instance(fmu, "ship_observer")
    assert raw.step() == OK
    before = state_bytes(raw)
    status, said = restore(raw, make(before))
    assert status == ERROR and message in said, said
    assert state_bytes(raw) == before and raw.step() == OK
    raw.free()


def test_a_valid_state_with_other_parameters_is_taken(fmu):
    """The state of an instance of the same FMU with another N: OK, the block is rebuilt from it."""
    other = instance(fmu, "ship_observer", "initializationMode")
    n = size(other, "N")
    _, good = other.get("N", n)
    assert other.set("N", [1.5 * value for value in good]) == OK and other.call("exitInitializationMode") == OK
    raw = instance(fmu, "ship_observer")
    assert restore(raw, state_bytes(other))[0] == OK
    assert raw.get("N", n)[1] == pytest.approx([1.5 * value for value in good], rel=1e-15)
    assert raw.step() == OK
    other.free()
    raw.free()
