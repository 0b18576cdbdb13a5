"""The block state of :mod:`observers.state` on every block kind, without FMI.

* The sharing rule: ``advance`` rebinds its state attributes and never writes into a state
  array (``self.x += ...``, ``self.x[0] = ...``); the FMU layer's cheap rollback depends on it.
  :func:`mutated_in_place` finds any violation; it is shown to catch one.
* A captured state restores the block exactly (rollback) and fits a fresh block (round trip).
* Restoring checks everything first and names the mismatch; nothing changes on an error.
* The sub-step budget of :func:`observers.integrators.substep_count`.
"""

from __future__ import annotations

import copy
from collections import deque

import numpy as np
import pytest

from obsfmu.fmus.runtime.kinds import create_block
from obsfmu.fmus.scenarios import SCENARIOS
from obsfmu.observers.block import Block, Segment
from obsfmu.observers.integrators import BudgetError, require_budget, substep_count
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.ltv.stepping import IntegralSamples, PolynomialInputs
from obsfmu.observers.state import Leaves, StateError, capture, plain, restore


def definitions() -> dict[str, tuple[float, object]]:
    """``kind -> (scenario step, definition)`` of the scenarios (the first of each kind)."""
    found = {}
    for scenario in SCENARIOS.values():
        for item in scenario.definitions():
            definition = item[0] if isinstance(item, tuple) else item
            found.setdefault(definition.kind, (scenario.step, definition))
    return found


DEFINITIONS = definitions()


def new_block(kind: str) -> Block:
    _, d = DEFINITIONS[kind]
    return create_block(d.kind, {p.name: p.array(p.value) for p in d.parameters}, d.options, d.kind_module)


def inputs(block: Block, k: int, h: float) -> dict[str, Segment]:
    t = k * h
    return {name: Segment(np.full(size, 0.1 * np.sin(0.7 * t + i)), np.full(size, 0.07 * np.cos(0.7 * t + i)))
            for i, (name, size) in enumerate(sorted(block.input_sizes.items()))}


def arrays_of(tree, path="state"):
    if isinstance(tree, dict):
        for key, value in tree.items():
            yield from arrays_of(value, f"{path}.{key}")
    elif isinstance(tree, (list, tuple)):
        for i, value in enumerate(tree):
            yield from arrays_of(value, f"{path}[{i}]")
    elif isinstance(tree, np.ndarray):
        yield path, tree


def mutated_in_place(block: Block, step) -> list[str]:
    """Paths of the state arrays that ``step()`` changed in place (instead of rebinding)."""
    tree = block.get_state()
    copies = {path: array.copy() for path, array in arrays_of(tree)}
    step()
    return [path for path, array in arrays_of(tree) if not np.array_equal(array, copies[path], equal_nan=True)]


def outputs_of(block: Block, t: float) -> dict[str, np.ndarray]:
    return block.outputs(t, {name: np.full(size, 0.1) for name, size in block.input_sizes.items()})


@pytest.mark.parametrize("kind", sorted(DEFINITIONS))
def test_no_block_writes_into_its_state_arrays(kind):
    block = new_block(kind)
    h = DEFINITIONS[kind][0]
    for k in range(25):
        assert mutated_in_place(block, lambda: block.advance(k * h, h, inputs(block, k, h))) == [], (kind, k)


class _Bad(Block):
    """A block that breaks the rule: it adds to its state array in place."""

    def __init__(self):
        self.x = np.zeros(2)
        self.input_sizes, self.output_sizes = {}, {"x": 2}

    def outputs(self, t, inputs):
        return {"x": self.x.copy()}

    def advance(self, t, h, inputs):
        self.x += h


def test_the_in_place_check_catches_a_block_that_breaks_the_rule():
    block = _Bad()
    assert mutated_in_place(block, lambda: block.advance(0.0, 1.0, {})) == ["state.x"]


@pytest.mark.parametrize("kind", sorted(DEFINITIONS))
def test_a_captured_state_is_a_rollback_and_fits_a_fresh_block(kind):
    block, h = new_block(kind), DEFINITIONS[kind][0]
    for k in range(5):
        block.advance(k * h, h, inputs(block, k, h))
    saved, expected = block.get_state(), outputs_of(block, 5 * h)
    point = capture(block, rollback=True)                    # the FMU layer's rollback point
    for k in range(5, 12):
        block.advance(k * h, h, inputs(block, k, h))
    block.set_state(point, check=False)
    np.testing.assert_equal(capture(block), saved)
    for k in range(5, 12):
        block.advance(k * h, h, inputs(block, k, h))
    block.set_state(saved, check=False)                     # the rollback of a refused step
    after = outputs_of(block, 5 * h)
    for name in expected:
        np.testing.assert_array_equal(after[name], expected[name], err_msg=name)
    continued = []
    for k in range(5, 12):
        block.advance(k * h, h, inputs(block, k, h))
        continued.append(outputs_of(block, (k + 1) * h))
    fresh = new_block(kind)                                  # a state of a later time, checked
    fresh.set_state(copy.deepcopy(saved))
    for k, expected_k in zip(range(5, 12), continued):
        fresh.advance(k * h, h, inputs(fresh, k, h))
        for name, value in outputs_of(fresh, (k + 1) * h).items():
            np.testing.assert_array_equal(value, expected_k[name], err_msg=name)


class _Halfway(Block):
    """A block whose step rebinds part of its state and then fails."""

    def __init__(self):
        self.x, self.count = np.zeros(2), 0
        self.input_sizes, self.output_sizes = {}, {"x": 2}

    def advance(self, t, h, inputs):
        self.atomically(self._step)

    def _step(self):
        self.x, self.count = self.x + 1.0, self.count + 1
        raise FloatingPointError("not finite")


@pytest.mark.parametrize("caller_rolls_back", [False, True])
def test_atomically_leaves_the_state_as_it_was_unless_the_caller_rolls_back(caller_rolls_back):
    """Standalone, a block's ``atomically`` step puts the state back itself; under a caller that rolls
    back every failed step (the FMU slave) it saves nothing, and the caller's saved state is the rollback."""
    block = _Halfway()
    block.caller_rolls_back = caller_rolls_back
    saved = block.get_state()
    assert "caller_rolls_back" not in saved                  # a setting of the caller, not state
    with pytest.raises(FloatingPointError):
        block.advance(0.0, 1.0, {})
    assert block.count == (1 if caller_rolls_back else 0)
    block.set_state(saved, check=False)                       # what the caller does
    assert block.count == 0 and np.array_equal(block.x, np.zeros(2))


class _Shrinking(Block):
    """A block whose step shortens a list in place (allowed: containers are copied both ways)."""

    def __init__(self):
        self.history = [1.0, 2.0, 3.0]
        self.pairs = [(0.0, np.zeros(2))]
        self.input_sizes, self.output_sizes = {}, {}

    def advance(self, t, h, inputs):
        self.history.pop()
        self.pairs.clear()
        raise FloatingPointError("not finite")


def test_a_rollback_restores_items_a_failed_step_removed_from_a_container():
    block = _Shrinking()
    saved = block.get_state()
    with pytest.raises(FloatingPointError):
        block.advance(0.0, 1.0, {})
    block.set_state(saved, check=False)                       # the slave's rollback
    assert block.history == [1.0, 2.0, 3.0]
    assert len(block.pairs) == 1 and block.pairs[0][0] == 0.0 and np.array_equal(block.pairs[0][1], np.zeros(2))


# --------------------------------------------------------------------------- immutable objects
class _Samples:
    """An immutable object (observers.state): new ones from ``after``, numbers checked when built."""

    immutable = True

    def __init__(self, values=(0.0, 0.0)):
        self.values = values                                  # the last two samples

    def after(self, value):
        if not abs(value) <= 1e100:
            raise SignalError(f"sample {value}")
        return _Samples((self.values[-1], value))


class _WithSamples(Block):
    def __init__(self):
        self.x, self.samples = np.zeros(2), _Samples()
        self.input_sizes, self.output_sizes = {}, {}

    def advance(self, t, h, inputs):
        self.x, self.samples = self.x + h, self.samples.after(t + h)


class _OptionalSamples(_WithSamples):
    state_optional = {"samples": None}

    def __init__(self):
        super().__init__()
        self.samples = None


def test_a_rollback_point_shares_immutable_objects_and_a_checked_restore_never_writes_into_them():
    block = _WithSamples()
    block.advance(0.0, 1.0, {})
    leaves = Leaves()
    point = capture(block, leaves, rollback=True)
    assert point["samples"] is block.samples                 # kept as it is, its numbers not collected
    assert [a.tolist() for a in leaves.arrays] == [[1.0, 1.0]] and leaves.floats == []
    data = capture(block)
    assert data["samples"] == {"values": (0.0, 1.0)}         # the plain tree has them as data
    with pytest.raises(SignalError):
        block.advance(1.0, np.inf, {})
    block.advance(1.0, 1.0, {})
    restore(block, point, check=False)                       # the rollback
    assert block.samples is point["samples"] and block.samples.values == (0.0, 1.0)
    other = _WithSamples()
    restore(block, capture(other))                           # a checked restore builds a new object
    assert block.samples.values == (0.0, 0.0) and block.samples is not point["samples"]
    assert point["samples"].values == (0.0, 1.0)             # the rollback point is intact
    restore(block, point, check=False)
    np.testing.assert_array_equal(block.x, [1.0, 1.0])
    assert block.samples.values == (0.0, 1.0)
    np.testing.assert_equal(plain(point), capture(block))    # as data: what leaves the process
    block.advance(1.0, 1.0, {})
    restore(block, point)                                    # a checked restore takes the object as it is
    assert block.samples is point["samples"]
    with pytest.raises(StateError, match="_WithSamples.samples: expected the attributes of a _Samples, got a tuple of 2"):
        restore(block, {**point, "samples": (0.0, 1.0)})
    with pytest.raises(StateError, match="_WithSamples.x: expected an array float64.2., got a _Samples"):
        restore(block, {**point, "x": point["samples"]})
    fresh = _WithSamples()
    fresh.samples = None                                     # not set yet, and not declared optional
    with pytest.raises(StateError, match="_WithSamples.samples: expected a NoneType, got a _Samples"):
        restore(fresh, point)
    optional = _OptionalSamples()                            # declared optional
    restore(optional, point)
    assert optional.samples is point["samples"]


def test_the_immutable_input_histories_refuse_numbers_they_cannot_hold():
    history = PolynomialInputs(2)
    polynomials, history = history.step(0.0, 0.1, {"y": Segment(np.array([1.0]), np.array([2.0]))})
    assert history.samples["y"][2][-1] == pytest.approx(1.2)
    with pytest.raises(SignalError, match="input y: not finite or beyond 1e\\+100"):
        history.step(0.1, 0.1, {"y": Segment(np.array([1.2]), np.array([2e101]))})    # ends at 2e100
    with pytest.raises(SignalError, match="input y"):
        history.step(0.1, 0.1, {"y": Segment(np.array([np.inf]), np.array([0.0]))})
    integral = IntegralSamples(2).after(0.0, 0.1, 0.5)
    assert integral.samples[2][-1] == 0.5
    for change in (np.nan, np.inf, 2e100):
        with pytest.raises(SignalError, match="int f\\(y\\) over the step to t = 0.2"):
            integral.after(0.1, 0.1, change)


# --------------------------------------------------------------------------- restore checks
class _Inner:
    def __init__(self):
        self.history = deque([np.zeros(2)] * 3, maxlen=3)
        self.pair = (1.0, np.ones(2))
        self.delta = np.float64(0.5)
        self.switch_time = None

    state_optional = {"switch_time": None}


class _Outer(Block):
    not_state = ("model",)
    state_optional = {"stage": "_blank_stage"}

    def __init__(self):
        self.model = lambda y: y              # not state: a callable
        self.x = np.zeros(3)
        self.count = 0
        self.inner = _Inner()
        self.stage = None
        self.input_sizes, self.output_sizes = {}, {"x": 3}

    def _blank_stage(self):
        return _Inner()


def test_capture_and_restore_keep_containers_numpy_scalars_and_optional_objects():
    source = _Outer()
    source.x = np.arange(3.0)
    source.count = 7
    source.inner.history.append(np.full(2, 5.0))
    source.inner.switch_time = 1.5
    source.stage = _Inner()
    source.stage.pair = (2.0, np.full(2, 3.0))
    tree = capture(source)
    assert "model" not in tree
    target = _Outer()
    restore(target, copy.deepcopy(tree))
    assert isinstance(target.inner.history, deque) and target.inner.history.maxlen == 3
    np.testing.assert_array_equal(target.inner.history[-1], [5.0, 5.0])
    assert isinstance(target.inner.delta, np.float64) and target.inner.switch_time == 1.5
    assert isinstance(target.stage, _Inner) and target.stage.pair[0] == 2.0   # built by _blank_stage
    restore(target, capture(_Outer()))                      # and back to "not started"
    assert target.stage is None and target.inner.switch_time is None


@pytest.mark.parametrize("change, message", [
    (lambda tree: tree.pop("count"), "missing count"),
    (lambda tree: tree.update({"evil": "os.system"}), "unknown 'evil'"),
    (lambda tree: tree.update({"x": np.zeros(4)}), "_Outer.x: expected an array float64[3], got an array float64[4]"),
    (lambda tree: tree.update({"x": None}), "_Outer.x: expected an array"),
    (lambda tree: tree.update({"count": 1.5}), "_Outer.count: expected an int, got a float"),
    (lambda tree: tree["inner"].update({"history": [np.zeros(2)] * 2}), "history: expected a deque of 3"),
    (lambda tree: tree.update({"inner": [1, 2]}), "_Outer.inner: expected the attributes of a _Inner"),
    (lambda tree: tree.update({"stage": {"history": 1}}), "_Outer.stage: attributes do not match"),
])
def test_restore_checks_everything_first_and_names_the_mismatch(change, message):
    target = _Outer()
    target.x = np.arange(3.0)
    tree = capture(_Outer())
    change(tree)
    with pytest.raises(StateError, match=message.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")):
        restore(target, tree)
    np.testing.assert_array_equal(target.x, [0.0, 1.0, 2.0])   # nothing changed


def test_capture_refuses_what_is_not_state_data():
    block = _Outer()
    block.callback = print
    with pytest.raises(StateError, match="_Outer.callback: a builtin_function_or_method is not state data"):
        capture(block)


# --------------------------------------------------------------------------- the sub-step budget
def test_substep_count_refuses_before_any_work_beyond_the_budget():
    assert substep_count(1e-3, 1e-3) == 1
    assert substep_count(1.0, 1e-3, budget=1000) == 1000
    assert substep_count(1.0, rate=50.0, max_change=0.01, budget=10_000) == 5000
    with pytest.raises(BudgetError, match=r"the step h = 1e\+06 needs 1e\+09 sub-steps of at most "
                                          r"max_substep = 0.001, more than substep_budget = 10000"):
        substep_count(1e6, 1e-3)
    for h in (float("nan"), float("inf")):
        with pytest.raises(BudgetError, match="substep_budget"):
            substep_count(h, 1e-3)
    with pytest.raises(BudgetError, match="changing at"):
        substep_count(1.0, 1.0, rate=float("nan"), max_change=0.1)
    for bad in (0, -1, 2.5, float("nan"), "many"):
        with pytest.raises(ParameterError, match="substep_budget: expected an integer >= 1"):
            require_budget(bad)
