"""A block's state as plain data: capture it, check it, put it back (FMU state, step rollback).

The *state* of a block is found generically: its attributes and, recursively, those of the
objects it holds (estimators, extensions, detectors, ...), except the attributes a class
declares in ``not_state`` -- things built from the parameters that ``advance`` never changes,
or changes only as a cache of a pure function (models, user callables, propagators).  No block
writes its own ``get_state``; a class declares once what is not state:

.. code-block:: python

    class LuenbergerObserver(Block):
        not_state = ("model", "N", "H", "_propagator")

:func:`capture` turns the state into a *tree* of plain data: ``dict`` (one per object, keyed by
attribute), ``list``, ``tuple``, numpy arrays of the dtypes in :data:`DTYPES`, ``float``,
``int``, ``bool``, ``str`` and ``None``.  Nothing else is accepted, so a tree can always be
written by :mod:`fmus.runtime.state_format` and never names a class.

:func:`restore` puts a tree back by assigning into the *existing* objects of the block: every
object, list length, array shape and dtype must match what the block has.  An attribute that
may be ``None`` (an estimator not yet frozen, a stage not yet started) is declared in the
class's ``state_optional``: ``{"switch_time": None}`` for plain data, or
``{"state_stage": "_state_stage_template"}`` naming a method that returns a blank object of the
right shape (built from the block's own parameters, never from the tree) to restore into.

Sharing rule (``TEAM.md``): ``advance`` computes the new state completely and then *rebinds*
the attributes; it never writes into a state array.  A captured tree therefore shares the
block's arrays without copying them, and restoring it is a complete rollback.  Containers
(``list``, ``dict``, ``deque``) are copied both ways, since blocks append to them.

Immutable objects: a class whose instances never change once built (its methods return new
ones, as :class:`~observers.ltv.stepping.PolynomialInputs` does) and that checks the numbers it
is built from -- finite and within :data:`~observers.block.MAGNITUDE_BOUND`, else
:class:`~observers.checks.SignalError` -- declares ``immutable = True``.  A *rollback point*
(``capture(block, rollback=True)``, the FMU layer's point to return to after a refused step, and
the block part of its in-memory FMU states) then keeps such an object as it is instead of walking
it, and its numbers are not collected for the bound test: they were checked when it was built.
:func:`plain` turns them into data where a tree leaves the process (the bytes of an FMU state).
"""

from __future__ import annotations

import copy
from collections import deque
from typing import Any

import numpy as np

__all__ = ["StateError", "DTYPES", "Leaves", "capture", "restore", "plain", "within", "within_bound",
           "unchanged_skipped", "out_of_bounds", "is_plain"]

#: dtypes a state array may have (little-endian on every supported platform)
DTYPES = (np.dtype(np.float64), np.dtype(np.int64), np.dtype(np.bool_), np.dtype(np.complex128))
_SCALARS = (type(None), bool, int, float, str)
_CONTAINERS = (list, tuple, deque)
#: float and complex dtypes: the arrays whose entries are checked against the bound
_NUMBER_DTYPES = frozenset(dtype for dtype in DTYPES if dtype.kind in "fc")
_IMMUTABLE, _FLOAT, _STR = frozenset((type(None), int, float, str)), frozenset((float,)), frozenset((str,))
#: items of a container kept as they are, with nothing to check (no float: the bound applies to those)
_PASSED = frozenset((type(None), bool, int, str))
#: deepest nesting a tree may have
MAX_DEPTH = 48


class StateError(ValueError):
    """A state cannot be captured, or does not fit the block it is restored into."""


def _declared(cls: type, attribute: str) -> dict | tuple:
    """``not_state`` (tuple) or ``state_optional`` (dict) of ``cls`` merged along its MRO."""
    key = (cls, attribute)
    cached = _DECLARED.get(key)
    if cached is None:
        if attribute == "not_state":
            cached = frozenset(name for klass in cls.__mro__ for name in vars(klass).get(attribute, ()))
        else:
            cached = {}
            for klass in reversed(cls.__mro__):
                cached.update(vars(klass).get(attribute, {}))
        _DECLARED[key] = cached
    return cached


_DECLARED: dict[tuple[type, str], Any] = {}
#: class -> (the attribute names of its instance last captured, those of them that are state)
_LAYOUTS: dict[type, tuple[tuple[str, ...], tuple[str, ...]]] = {}
#: the classes found to be objects
_OBJECTS: set[type] = set()
#: the classes found to declare ``immutable = True``
_IMMUTABLE_OBJECTS: set[type] = set()


def _is_object(value) -> bool:
    """An object whose attributes are walked (an estimator, a detector, a block)."""
    return hasattr(value, "__dict__") and not callable(value) and not isinstance(value, type)


# ---------------------------------------------------------------------------------------- capture
class Leaves:
    """The numbers of a tree, collected by :func:`capture` for :func:`within_bound`."""

    __slots__ = ("arrays", "floats")

    def __init__(self):
        self.arrays: list[np.ndarray] = []     # float and complex arrays
        self.floats: list[float] = []


def capture(obj, leaves: Leaves | None = None, rollback: bool = False) -> dict:
    """The state of ``obj`` as a tree (arrays shared, containers copied); :class:`StateError`
    names an attribute whose value cannot be kept in a state.  ``leaves`` collects its numbers.

    ``rollback``: a rollback point of this very block -- immutable objects (module docstring) are
    kept as they are and their numbers not collected; :func:`plain` makes it plain data."""
    attributes = vars(obj)
    names = tuple(attributes)
    layout = _LAYOUTS.get(type(obj))
    if layout is None or layout[0] != names:          # the attributes less not_state, by class
        skip = _declared(type(obj), "not_state")
        layout = _LAYOUTS[type(obj)] = (names, tuple(name for name in names if name not in skip))
    tree = {}
    for name in layout[1]:
        value = attributes[name]
        kind = type(value)
        if kind is np.ndarray and value.dtype in _NUMBER_DTYPES:    # the common leaves, without a call
            if leaves is not None:
                leaves.arrays.append(value)
            tree[name] = value
        elif kind is float:
            if leaves is not None:
                leaves.floats.append(value)
            tree[name] = value
        else:
            try:
                tree[name] = _capture(value, leaves, rollback)
            except StateError as exc:
                raise StateError(f"{type(obj).__name__}.{name}: {exc}") from None
    return tree


def _capture(value, leaves, rollback=False):
    kind = type(value)
    if kind in _OBJECTS:                               # an object met before (an estimator, a detector)
        return capture(value, leaves, rollback)
    if kind in _IMMUTABLE_OBJECTS:                     # checked when built, never changed
        return value if rollback else capture(value, leaves)
    if kind is np.ndarray:
        if value.dtype not in DTYPES:
            raise StateError(f"arrays of dtype {value.dtype} cannot be kept in a state")
        if leaves is not None and value.dtype.kind in "fc":
            leaves.arrays.append(value)
        return value
    if kind is float:
        if leaves is not None:
            leaves.floats.append(value)
        return value
    if kind in _SCALARS:
        return value
    if kind is tuple:
        kinds = set(map(type, value))
        if kinds <= _IMMUTABLE:            # plain numbers (a history of samples): shared, as arrays are
            if leaves is not None and float in kinds:
                leaves.floats.extend(value if kinds == _FLOAT else [item for item in value if type(item) is float])
            return value
        return tuple([item if type(item) in _PASSED else _capture(item, leaves, rollback) for item in value])
    if kind is list or kind is deque:
        return [_capture(item, leaves, rollback) for item in value]
    if kind is dict:
        if not set(map(type, value)) <= _STR:
            raise StateError("dictionary keys must be strings")
        return {key: _capture(item, leaves, rollback) for key, item in value.items()}
    if isinstance(value, np.generic) and value.dtype in DTYPES:
        return _capture(value.item(), leaves)
    if _is_object(value):                              # a class met the first time
        (_IMMUTABLE_OBJECTS if getattr(kind, "immutable", False) is True else _OBJECTS).add(kind)
        return _capture(value, leaves, rollback)
    raise StateError(f"a {kind.__name__} is not state data; declare the attribute in not_state of its class")


# ---------------------------------------------------------------------------------------- restore
def restore(obj, tree, check: bool = True) -> None:
    """Put ``tree`` back into ``obj``.

    With ``check`` (trees from outside) everything is verified first and :class:`StateError`
    names the first mismatch; nothing is changed then.  ``check=False`` is the rollback of a
    tree :func:`capture` made of this very block.
    """
    plan: list[tuple[object, str, Any]] = []
    _plan_object(obj, tree, type(obj).__name__, plan, check, 0)
    for target, name, value in plan:
        setattr(target, name, value)


def _plan_object(obj, tree, path: str, plan: list, check: bool, depth: int) -> None:
    if type(tree) is not dict:
        raise StateError(f"{path}: expected the attributes of a {type(obj).__name__}, got {_kind(tree)}")
    live = vars(obj)
    if check:
        expected = set(live) - _declared(type(obj), "not_state")
        if set(tree) != expected:
            missing, extra = sorted(expected - set(tree)), sorted(set(tree) - expected)
            raise StateError(f"{path}: attributes do not match a {type(obj).__name__}"
                             + (f"; missing {', '.join(missing)}" if missing else "")
                             + (f"; unknown {', '.join(map(repr, extra[:5]))}" if extra else ""))
    optional = _declared(type(obj), "state_optional")
    for name, data in tree.items():
        current = live.get(name)
        value = _plan_value(obj, name, current, data, f"{path}.{name}", plan, check, depth + 1,
                            name in optional)
        if value is not current or not _is_object(current):
            plan.append((obj, name, value))


def _plan_value(owner, name, live, data, path, plan, check, depth, optional):
    if depth > MAX_DEPTH:
        raise StateError(f"{path}: nested deeper than {MAX_DEPTH}")
    if type(data) in _IMMUTABLE_OBJECTS:               # kept as it is by a rollback point
        if check and type(live) is not type(data) and not (live is None and optional):
            raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
        return data
    if data is None or live is None:
        if data is None and live is None:
            return None
        if check and not optional:
            raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
        if data is None:
            return None
        template = _declared(type(owner), "state_optional").get(name)
        if template is not None:                       # an object that starts later (a stage)
            blank = getattr(owner, template)()
            _plan_object(blank, data, path, plan, check, depth)
            return blank
        if check and not is_plain(data):
            raise StateError(f"{path}: expected plain data, got {_kind(data)}")
        return _copy_containers(data)
    if _is_object(live):
        if type(live) in _IMMUTABLE_OBJECTS:           # never written into: a new one (trees may share it)
            live = copy.copy(live)
        _plan_object(live, data, path, plan, check, depth)
        return live
    if type(live) is np.ndarray:
        if check and not (type(data) is np.ndarray and data.dtype == live.dtype and data.shape == live.shape):
            raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
        return data
    if isinstance(live, _CONTAINERS):
        if check and not (isinstance(data, (list, tuple)) and len(data) == len(live)):
            raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
        items = [_plan_value(owner, name, old, new, f"{path}[{i}]", plan, check, depth + 1, False)
                 for i, (old, new) in enumerate(zip(live, data))]
        extra = data[len(live):]                       # a rollback after a step that shortened the container
        if not all(map(is_plain, extra)):
            raise StateError(f"{path}: {len(data)} items to restore into {_kind(live)}: the missing ones are objects")
        items += [_copy_containers(item) for item in extra]
        if type(live) is deque:
            return deque(items, maxlen=live.maxlen)
        return tuple(items) if type(live) is tuple else items
    if type(live) is dict:
        if check and type(data) is not dict:
            raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
        result = {}
        for key, new in data.items():
            if key in live:
                result[key] = _plan_value(owner, name, live[key], new, f"{path}[{key!r}]", plan, check, depth + 1,
                                          False)
            elif check and not (type(key) is str and is_plain(new)):
                raise StateError(f"{path}[{key!r}]: expected plain data, got {_kind(new)}")
            else:
                result[key] = _copy_containers(new)
        return result
    if check and not _same_scalar_kind(live, data):
        raise StateError(f"{path}: expected {_kind(live)}, got {_kind(data)}")
    if isinstance(live, np.generic) and type(data) is not type(live):
        return live.dtype.type(data)                   # numpy scalars stay numpy scalars
    return data


def _same_scalar_kind(live, data) -> bool:
    if isinstance(live, bool) or isinstance(data, bool):
        return type(data) is bool and isinstance(live, (bool, np.bool_))
    if isinstance(live, (int, np.integer)):
        return type(data) is int
    if isinstance(live, (float, np.floating)):
        return type(data) is float
    return type(data) is type(live)


def _copy_containers(data):
    kind = type(data)
    if kind is list:
        return [_copy_containers(item) for item in data]
    if kind is tuple:
        return tuple(_copy_containers(item) for item in data)
    if kind is dict:
        return {key: _copy_containers(item) for key, item in data.items()}
    return data


def plain(tree):
    """``tree`` (of :func:`capture`) with the immutable objects a rollback point keeps as they are
    replaced by their plain trees: data that names no class."""
    kind = type(tree)
    if kind in _IMMUTABLE_OBJECTS:
        return capture(tree)
    if kind is dict:
        return {key: plain(value) for key, value in tree.items()}
    if kind is list or kind is tuple:
        return kind(plain(value) for value in tree)
    return tree


def is_plain(data, depth: int = 0) -> bool:
    """True for leaves and lists/tuples/dicts of leaves (no object trees) -- what may appear
    where the live block has nothing to compare with."""
    kind = type(data)
    if kind in _SCALARS or (kind is np.ndarray and data.dtype in DTYPES):
        return True
    if depth >= 8:
        return False
    if kind is list or kind is tuple:
        return all(is_plain(item, depth + 1) for item in data)
    return False


def _kind(value) -> str:
    if type(value) is np.ndarray:
        return f"an array {value.dtype}{list(value.shape)}"
    name = type(value).__name__
    article = "an" if name[0] in "aeiouAEIOU" else "a"
    if isinstance(value, (list, tuple, deque)):
        return f"{article} {name} of {len(value)}"
    return f"{article} {name}"


# ---------------------------------------------------------------------------------------- checks
def within(values: np.ndarray, bound: float) -> bool:
    """True when every entry of ``values`` (1-D) is finite and at most ``bound`` in magnitude."""
    square = values.dot(values) if values.dtype.kind == "f" else np.vdot(values, values).real
    if square <= bound * bound:                        # one cheap call decides almost always
        return True
    return bool(np.all(np.abs(values) <= bound))


def unchanged_skipped(leaves: Leaves, previous: Leaves | None) -> list[np.ndarray]:
    """The arrays of ``leaves`` that ``previous`` does not hold (by identity): those a step rebound."""
    arrays, old = leaves.arrays, () if previous is None else previous.arrays
    if len(old) == len(arrays):             # the same attributes in the same order: compare in place
        return [a for a, b in zip(arrays, old) if a is not b]
    if old:
        known = set(map(id, old))
        return [a for a in arrays if id(a) not in known]
    return list(arrays)


def within_bound(leaves: Leaves | None, bound: float, previous: Leaves | None = None, arrays=()) -> bool:
    """:func:`within` for ``arrays`` and every number of ``leaves`` (None: none), skipping arrays that
    ``previous`` (the leaves of an earlier, checked capture) holds too -- by the sharing rule they did
    not change -- all in one vector (one 1-D array alone as it is): one test."""
    arrays = list(arrays)
    if leaves is not None:
        arrays += unchanged_skipped(leaves, previous)
        if leaves.floats:
            arrays.append(leaves.floats)
    if not arrays:
        return True
    one = arrays[0]
    vector = one if len(arrays) == 1 and type(one) is np.ndarray and one.ndim == 1 else \
        np.concatenate(arrays, axis=None)
    return within(vector, bound)


def out_of_bounds(tree, bound: float, path: str = "") -> tuple[str, Any] | None:
    """``(path, value)`` of the first number (or array) of ``tree`` that is not finite or exceeds
    ``bound`` in magnitude; ``None`` if there is none (slow: for the message of a refusal)."""
    kind = type(tree)
    if kind is np.ndarray:
        if tree.dtype.kind in "fc" and not within(tree.ravel(), bound):
            return path, tree
    elif kind is float:
        if not -bound <= tree <= bound:
            return path, tree
    elif kind is dict:
        for key, value in tree.items():
            found = out_of_bounds(value, bound, f"{path}.{key}" if path else key)
            if found:
                return found
    elif kind is list or kind is tuple:
        for i, value in enumerate(tree):
            found = out_of_bounds(value, bound, f"{path}[{i}]")
            if found:
                return found
    return None
