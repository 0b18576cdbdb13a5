"""FMU state bytes on every FMU kind (issue 13): exact round trips, and every kind of bad bytes refused.

Bytes of another FMU, of another format version, truncated, bit-flipped, random, forged in the
right format, or a pickle that would run a command: ``fmi2DeSerializeFMUstate`` or
``fmi2SetFMUstate`` returns fmi2Error, nothing runs, the instance is exactly as before
(the same serialized state) and keeps working.
"""

from __future__ import annotations

import hashlib
import pickle
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from faults_support import ERROR, OK, LiveProbes, Probe
from obsfmu.fmus.runtime.state_format import FORMAT_VERSION, decode, encode, pack

KINDS = ["generator-plant", "gpebo-observer", "lti-plant", "ltv-adaptive-observer", "ltv-disturbed-plant",
         "ltv-output-nonlinear-plant", "luenberger-observer", "signal-source", "state-affine-chemostat",
         "state-affine-observer", "state-affine-pendulum", "state-feedback", "uio-ftdrem-observer"]
EXAMPLES = settings(max_examples=10, derandomize=True, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def live(kind_fmus):
    probes = LiveProbes(kind_fmus)
    yield probes
    probes.free()


def identity(probe: Probe) -> str:
    return f"{probe.description.modelName} {probe.description.guid}"


def payload(data: bytes) -> dict:
    """The tree inside state bytes (the header is 24 bytes, then a 32-byte digest and the identity)."""
    identity_size = struct.unpack_from("<I", data, 12)[0]
    return decode(data[24 + 32 + identity_size:])


def refused(probe: Probe, step: float, data: bytes, expected: str | None = None) -> None:
    """Restoring ``data`` is an error that changes nothing; the instance keeps working."""
    before, outputs, mark = probe.state_bytes(), probe.outputs(), len(probe.log)
    assert probe.restore_bytes(data) == ERROR, probe.messages(mark)
    if expected:
        assert expected in probe.messages(mark), probe.messages(mark)
    assert probe.state_bytes() == before
    np.testing.assert_array_equal(probe.outputs(), outputs)
    probe.drive_inputs(int(round(probe.t / step)), step)
    assert probe.step(step) == OK, probe.messages(mark)


# ------------------------------------------------------------------------------ round trips
@pytest.mark.parametrize("kind", KINDS)
def test_a_serialized_state_continues_bit_for_bit_in_a_fresh_instance(kind_fmus, kind):
    step, path = kind_fmus[kind]
    first = Probe(path, "first")
    first.run(step, 5)
    data, t = first.state_bytes(), first.t
    expected = first.run(step, 20)
    second = Probe(path, "second")                  # never stepped: every bit comes from the bytes
    assert second.restore_bytes(data, t) == OK
    np.testing.assert_array_equal(second.run(step, 20), expected)
    assert second.state_bytes() == first.state_bytes()
    first.free()
    second.free()


def test_the_format_is_versioned_and_names_the_fmu(live):
    probe, _, data = live("luenberger-observer")
    magic, version = struct.unpack_from("<8sH", data)
    assert magic == b"OBSFMUst" and version == FORMAT_VERSION
    assert identity(probe).encode() in data[:200]
    assert hashlib.sha256(data[:24] + data[56:]).digest() == data[24:56]
    assert b"pickle" not in data and b"\x80\x04" not in data[:2]


# ------------------------------------------------------------------------------ bytes from elsewhere
@pytest.mark.parametrize("kind", KINDS)
def test_the_state_of_another_fmu_is_refused(live, kind):
    probe, step, _ = live(kind)
    other = KINDS[(KINDS.index(kind) + 1) % len(KINDS)]
    _, _, foreign = live(other)
    refused(probe, step, foreign, "belongs to another FMU")


def test_the_in_memory_state_of_another_fmu_changes_nothing(live):
    """Issue 13: fmi2SetFMUstate with another FMU's state returned Error but had changed ``C[1]``."""
    probe, step, _ = live("luenberger-observer")
    other, _, _ = live("lti-plant")
    foreign = other.slave.getFMUstate()
    before, mark = probe.state_bytes(), len(probe.log)
    assert probe.call(probe.slave.setFMUstate, foreign) == ERROR
    assert "is not a state of this FMU (another FMU's" in probe.messages(mark)  # the loader's handle check
    assert probe.state_bytes() == before
    other.slave.freeFMUstate(foreign)


def test_another_format_version_is_refused(live):
    probe, step, data = live("state-affine-observer")
    header = bytearray(data[:24])
    struct.pack_into("<H", header, 8, FORMAT_VERSION + 1)
    rest = data[56:]
    forged = bytes(header) + hashlib.sha256(bytes(header) + rest).digest() + rest
    refused(probe, step, forged, f"state format version {FORMAT_VERSION + 1}")


@pytest.mark.parametrize("kind", KINDS)
@EXAMPLES
@given(data=st.data())
def test_damaged_bytes_are_refused(live, kind, data):
    probe, step, good = live(kind)
    damage = data.draw(st.sampled_from(["flip", "truncate", "extend", "random"]))
    if damage == "flip":
        bit = data.draw(st.integers(0, 8 * len(good) - 1))
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
    elif damage == "truncate":
        bad = good[:data.draw(st.integers(0, len(good) - 1))]
    elif damage == "extend":
        bad = good + data.draw(st.binary(min_size=1, max_size=16))
    else:
        bad = data.draw(st.binary(max_size=2 * len(good)))
    refused(probe, step, bytes(bad))


def test_every_single_bit_flip_of_a_state_is_detected(live):
    """The audit found 68 of 200 single-bit flips accepted; now all of them are refused."""
    probe, _, good = live("lti-plant")
    accepted = 0
    for bit in range(8 * len(good)):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        state = None
        try:
            state = probe.slave.deSerializeFMUstate(bytes(bad))
        except Exception:
            continue
        accepted += 1
        probe.slave.freeFMUstate(state)
    assert accepted == 0


# ------------------------------------------------------------------------------ forged in the right format
def forged(probe: Probe, good: bytes, change) -> bytes:
    """``good`` with its tree changed by ``change(tree)``, re-packed with a valid checksum."""
    tree = payload(good)
    change(tree)
    return pack(identity(probe), tree)


def _first_array(tree: dict) -> tuple[dict, str]:
    for key, value in tree.items():
        if isinstance(value, np.ndarray) and value.dtype == np.float64:
            return tree, key
        if isinstance(value, dict):
            found = _first_array(value)
            if found:
                return found
    return None


def _set_block_array(value_of):
    def change(tree):
        owner, key = _first_array(tree["block"])
        owner[key] = value_of(owner[key])
    return change


FORGERIES = {
    "array of another shape": (_set_block_array(lambda a: np.zeros(a.size + 1)), "expected an array float64"),
    "string instead of an array": (_set_block_array(lambda a: "os.system('touch /tmp/x')"), "expected an array"),
    "object instead of an array": (_set_block_array(lambda a: {"__class__": "os.system"}), "expected an array"),
    "NaN in the state": (_set_block_array(lambda a: np.full_like(a, np.nan)), "is not finite"),
    "huge state": (_set_block_array(lambda a: np.full_like(a, 1e300)), "exceeds the bound"),
    "unknown attribute": (lambda tree: tree["block"].update({"__reduce__": "os.system"}), "unknown '__reduce__'"),
    "missing attribute": (lambda tree: tree["block"].popitem(), "missing"),
    "parameters of another shape": (lambda tree: tree["params"].update(
        {k: np.zeros(3 * v.size + 1) for k, v in list(tree["params"].items())[:1]}), "wrong type or shape"),
    "huge parameter": (lambda tree: tree["params"].update(
        {k: np.full_like(v, 1e300) for k, v in list(tree["params"].items())[:1]}), "parameters must be finite"),
    "another section": (lambda tree: tree.update({"code": "import os"}), "wrong sections"),
    "time not finite": (lambda tree: tree.update({"time": float("nan")}), "time"),
    "initialized without a block": (lambda tree: tree.update({"block": None}), "initialized without a block"),
    # the binary's fields, checked by the binary (the one format holds them)
    "loader fields of the FMI 3.0 binary": (lambda tree: tree.update({"loader": {"fmi": 3, "state": "stepMode"}}),
                                            "saved by the FMI 3.0 binary of this FMU; this is the FMI 2.0 binary"),
    "unknown state machine state": (lambda tree: tree.update({"loader": {"fmi": 2, "state": "running"}}),
                                    "the state machine state running of the state is unknown"),
    "state machine state before initialization": (
        lambda tree: tree.update({"loader": {"fmi": 2, "state": "instantiated"}}),
        "state machine state instantiated, but the slave was initialized"),
    "no loader fields": (lambda tree: tree.update({"loader": None}), "holds no state machine fields"),
}


@pytest.mark.parametrize("kind", ["luenberger-observer", "ltv-adaptive-observer", "uio-ftdrem-observer",
                                  "gpebo-observer", "state-affine-observer", "ltv-output-nonlinear-plant"])
@pytest.mark.parametrize("forgery", sorted(FORGERIES))
def test_forged_states_in_the_right_format_are_refused(live, kind, forgery):
    probe, step, good = live(kind)
    change, expected = FORGERIES[forgery]
    refused(probe, step, forged(probe, good, change), expected)


@pytest.mark.parametrize("kind", ["ltv-adaptive-observer", "ltv-output-nonlinear-plant"])
@pytest.mark.parametrize("sample, expected", [(np.nan, "is not finite"), (1e300, "exceeds the bound")])
def test_a_forged_input_sample_is_refused(live, kind, sample, expected):
    """The input history is an immutable object, which a rollback point shares without testing its
    numbers (observers.state); the numbers of a restored state are all tested."""
    probe, step, good = live(kind)

    def change(tree):
        samples = tree["block"]["inputs"]["samples"]
        count, times, values = samples["u"]
        assert count >= 2                                     # a history to forge
        samples["u"] = (count, times, values[:-2] + (sample, values[-1]))
    refused(probe, step, forged(probe, good, change), expected)


def test_a_state_brings_its_state_machine_state_and_whether_parameters_are_fixed(live, kind_fmus):
    """A state saved while stepping, restored into an instance still in initialization mode: stepping
    goes on and parameters are fixed; a state saved in initialization mode, restored into a running
    instance: parameters can be set again and initialization ends anew."""
    _, step, stepping_bytes = live("luenberger-observer")
    fresh = Probe(kind_fmus["luenberger-observer"][1], "fresh", init=False)
    initializing_bytes = fresh.state_bytes()
    assert fresh.restore_bytes(stepping_bytes, payload(stepping_bytes)["time"]) == OK
    mark = len(fresh.log)
    assert fresh.set("N[1]", 3.0) == ERROR and "parameters are fixed after initialization" in fresh.messages(mark)
    fresh.drive_inputs(int(round(fresh.t / step)), step)
    assert fresh.step(step) == OK, fresh.messages(mark)
    assert fresh.restore_bytes(initializing_bytes, 0.0) == OK
    assert fresh.set("N[1]", fresh.get(["N[1]"])[0]) == OK
    assert fresh.call(fresh.slave.exitInitializationMode) == OK, fresh.messages(mark)
    fresh.drive_inputs(0, step)
    assert fresh.step(step) == OK, fresh.messages(mark)
    fresh.free()


# ------------------------------------------------------------------------------ pickles that run code
def _stack_global(module: str, name: str) -> bytes:
    return (b"\x8c" + bytes([len(module)]) + module.encode() + b"\x8c" + bytes([len(name)]) + name.encode()
            + b"\x93")


def _call1(argument: str) -> bytes:
    return b"\x8c" + bytes([len(argument)]) + argument.encode() + b"\x85R"


def malicious_pickles(marker) -> dict[str, bytes]:
    """The audit's payloads: each one, unpickled, runs ``touch marker``."""
    command = f"touch {marker}"
    return {
        "pickle of os.system": pickle.dumps(_Run(command)),
        "fmus.runtime.callables.resolve('os:system')": b"\x80\x04" + _stack_global("obsfmu.fmus.runtime.callables", "resolve")
        + _call1("os:system") + _call1(command) + b".",
        "fmus.native + os.system": b"\x80\x04" + _stack_global("obsfmu.fmus.native", "os.system") + _call1(command) + b".",
        "fmus.native + subprocess.getoutput": b"\x80\x04" + _stack_global("obsfmu.fmus.native", "subprocess.getoutput")
        + _call1(command) + b".",
        "numpy.lib._datasource + os.system": b"\x80\x04" + _stack_global("numpy.lib._datasource", "os.system")
        + _call1(command) + b".",
    }


class _Run:
    def __init__(self, command):
        self.command = command

    def __reduce__(self):
        import os
        return os.system, (self.command,)


def test_the_malicious_payloads_would_run_a_command(tmp_path):
    """The payloads are real: unpickled (here, deliberately) each one creates the marker file."""
    for name, data in malicious_pickles(tmp_path / "ran").items():
        pickle.loads(data)
        assert (tmp_path / "ran").exists(), name
        (tmp_path / "ran").unlink()


@pytest.mark.parametrize("kind", ["lti-plant", "ltv-adaptive-observer", "uio-ftdrem-observer"])
def test_pickles_that_would_run_a_command_are_refused_and_run_nothing(live, kind, tmp_path):
    probe, step, _ = live(kind)
    marker = tmp_path / "ran"
    for name, data in malicious_pickles(marker).items():
        refused(probe, step, data, "not an obsfmu FMU state")
        # the same payload behind a valid header and checksum of this FMU
        header = struct.pack("<8sHHIQ", b"OBSFMUst", FORMAT_VERSION, 0, len(identity(probe).encode()), len(data))
        framed = header + hashlib.sha256(header + identity(probe).encode() + data).digest() \
            + identity(probe).encode() + data
        refused(probe, step, framed, "unknown tag")
        assert not marker.exists(), name


# ------------------------------------------------------------------------------ the decoder alone
@settings(max_examples=300, derandomize=True, deadline=None, database=None)
@given(st.binary(max_size=400))
def test_decoding_any_bytes_gives_data_or_a_clear_error(data):
    from obsfmu.fmus.runtime.state_format import StateFormatError
    try:
        decode(data)
    except StateFormatError:
        pass


@settings(max_examples=200, derandomize=True, deadline=None, database=None)
@given(st.data())
def test_decoding_mutated_payloads_gives_data_or_a_clear_error(data):
    from obsfmu.fmus.runtime.state_format import StateFormatError
    good = encode({"a": np.arange(6.0).reshape(2, 3), "b": [1, 2.5, None, True, "text"],
                   "c": (np.array([True, False]), np.zeros(0, dtype=np.int64)), "d": {"e": np.array([1 + 2j])}})
    bad = bytearray(good)
    for _ in range(data.draw(st.integers(1, 4))):
        bad[data.draw(st.integers(0, len(bad) - 1))] = data.draw(st.integers(0, 255))
    try:
        decode(bytes(bad))
    except StateFormatError:
        pass


def test_declared_lengths_beyond_the_buffer_allocate_nothing():
    from obsfmu.fmus.runtime.state_format import StateFormatError
    huge_array = b"a\x00\x02" + struct.pack("<QQ", 2 ** 40, 2 ** 40)
    huge_list = b"l" + struct.pack("<I", 2 ** 32 - 1)
    huge_string = b"s" + struct.pack("<I", 2 ** 32 - 1)
    deep = b"l\x01\x00\x00\x00" * 100 + b"N"
    for data in (huge_array, huge_list, huge_string, deep):
        with pytest.raises(StateFormatError):
            decode(data)
