"""The binary's test of numbers (``native_within``, fmus/native/bridge.c) against observers.state's.

The bridge gives each slave instance ``native_within(bound, vector, arrays, previous, floats)``: the test of a
batched step's outputs and new state (``within`` and ``within_bound``) in one C call.  Only its True decides
(the slave tests anything else in numpy), so it must never say True where numpy says False, and it must say
True on the common case -- finite float64 or complex128 arrays within the bound -- or it saves nothing.
"""

from __future__ import annotations

import gc

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from obsfmu.fmus.master import Component, Session, System
from obsfmu.fmus.scenarios import get
from obsfmu.observers.state import Leaves, within, within_bound

BOUND = 1e100


def ship_session(ship_fmus) -> Session:
    scenario = get("ship")
    components = [Component(i, ship_fmus[m], dict(s)) for i, m, s in scenario.components]
    return Session(System(components, list(scenario.connections)), echo_log=False)


def holders() -> dict[int, object]:
    """The objects of this process that hold a ``native_within`` of their own: the live slave instances."""
    return {id(o): o for o in gc.get_objects()
            if isinstance(getattr(o, "__dict__", None), dict) and "native_within" in o.__dict__}


@pytest.fixture(scope="module")
def native_within(ship_fmus):
    """``native_within`` of a live slave instance of an FMU loaded in this process (through fmpy)."""
    with ship_session(ship_fmus) as session:
        session.run(0.002, 1e-3)
        yield next(iter(holders().values())).native_within


def test_every_live_instance_has_it_and_a_freed_one_has_not(native_within, ship_fmus):
    """The bridge gives it to each instance, also those fmi2Reset makes, and takes it back when it lets
    an instance go: it points into the binary, which may be unloaded before a cycle is collected."""
    before = holders()
    with ship_session(ship_fmus) as session:
        for _ in range(3):                       # fmi2Reset before the second and third run: new instances
            session.run(0.002, 1e-3)
        gc.collect()
        new = [o for key, o in holders().items() if key not in before]
        assert sorted(o.instance_name for o in new) == ["controller", "observer", "plant"]
    del new
    gc.collect()
    assert holders().keys() <= before.keys()


def reference(vector, arrays, previous, floats) -> bool:
    """observers.state's test of the same numbers (what the slave falls back to)."""
    leaves = Leaves()
    leaves.arrays, leaves.floats = list(arrays or []), list(floats or [])
    earlier = None
    if previous is not None:
        earlier = Leaves()
        earlier.arrays = list(previous)
    with np.errstate(all="ignore"):                         # as in the slave (its numerics context)
        return (vector is None or within(vector, BOUND)) and within_bound(leaves, BOUND, earlier)


x, z = np.array([1.0, -2.0, 3.0]), np.array([1 + 2j, -3j])
CASES = {       # name: (vector, arrays, previous, floats, what native_within says)
    "finite vector": (x, None, None, None, True),
    "finite state": (x, [x.copy(), np.eye(3), z], None, [0.5, -4.0], True),
    "empty": (np.zeros(0), [], [], [], True),
    "NaN output": (np.array([1.0, np.nan]), None, None, None, False),
    "inf in a matrix": (x, [np.array([[1.0, np.inf]])], None, None, False),
    "beyond the bound": (np.array([2e100]), None, None, None, False),
    "complex NaN": (x, [np.array([complex(0, np.nan)])], None, None, False),
    "NaN float": (x, [], None, [1.0, float("nan")], False),
    "far beyond the bound: its square overflows": (np.array([1e160]), None, None, None, False),
    "float32: numpy decides": (x, [np.ones(2, dtype=np.float32)], None, None, None),
    "strided: numpy decides": (x, [np.ones(6)[::2]], None, None, None),
    "previous of another length: numpy decides": (x, [x], [x, x], None, None),
}


@pytest.mark.parametrize("name", CASES)
def test_it_says_what_numpy_says_or_leaves_it_to_numpy(native_within, name):
    vector, arrays, previous, floats, expected = CASES[name]
    assert native_within(BOUND, vector, arrays, previous, floats) is expected
    if expected is not None:
        assert reference(vector, arrays, previous, floats) is expected


def test_arrays_not_rebound_since_the_last_test_are_skipped_as_numpy_skips_them(native_within):
    tested, rebound = np.array([np.nan]), np.array([1.0])        # a NaN tested before cannot be there
    assert native_within(BOUND, None, [tested, rebound], [tested, np.array([0.0])], None) is True
    assert reference(None, [tested, rebound], [tested, np.array([0.0])], None) is True
    assert native_within(BOUND, None, [tested.copy(), rebound], [tested, rebound], None) is False


def test_a_wrong_call_is_a_type_error(native_within):
    with pytest.raises(TypeError, match="native_within"):
        native_within(1, x, None, None, None)


NUMBERS = st.floats(allow_nan=True, allow_infinity=True, min_value=None, max_value=None)


@settings(max_examples=200, derandomize=True, deadline=None, database=None)
@given(st.lists(NUMBERS, max_size=6), st.lists(st.lists(NUMBERS, max_size=4), max_size=3),
       st.lists(NUMBERS, max_size=3))
def test_it_never_says_true_where_numpy_says_false(native_within, vector, arrays, floats):
    vector, arrays = np.array(vector, dtype=float), [np.array(a, dtype=float) for a in arrays]
    says, truth = native_within(BOUND, vector, arrays, None, floats), reference(vector, arrays, None, floats)
    assert says is not True or truth
    numbers = np.concatenate([vector, *arrays, np.array(floats, dtype=float)])
    if truth and np.sum(np.square(numbers, dtype=float)) <= BOUND ** 2:   # the common case is decided in C
        assert says is True
