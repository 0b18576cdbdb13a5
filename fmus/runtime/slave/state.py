"""FMU states (``fmi2GetFMUstate`` and its kin): plain data in one serialized form, checked when they come back.

A state holds everything that evolves -- time, parameters, inputs, the block's state, the input
history, whether initialization is over -- and the native binary's own fields (FMI version, state
machine state), as plain data (:mod:`observers.state`) in an explicit, versioned, checksummed format
(:mod:`fmus.runtime.state_format`).  A state of another FMU or version, or damaged or forged bytes,
are refused (:class:`~.common.Refused`) and change nothing (docs/faults.md).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from xml.etree.ElementTree import ParseError, iterparse

import numpy as np

from obsfmu.observers.block import Block
from obsfmu.observers.state import Leaves, StateError, capture, plain, within

from ..state_format import StateFormatError, pack, unpack
from .common import InputMode, Refused
from .numerics import host_independent_numerics

__all__ = ["FmuState", "FmuStates"]


class FmuState:
    """An FMU state (``fmi2GetFMUstate``): plain data, tagged with the FMU it belongs to."""

    __slots__ = ("identity", "tree")

    def __init__(self, identity: str, tree: dict):
        self.identity, self.tree = identity, tree


#: the sections of an FMU state's tree (``loader``: the native binary's fields, see get_fmu_state)
_SECTIONS = {"time", "params", "inputs", "modes", "derivatives", "last_inputs", "block_error", "block", "initialized",
             "loader"}


@functools.lru_cache(maxsize=None)
def _guid(model_description: str) -> str:
    """The token of the FMU unpacked around ``resources``: its GUID (FMI 2.0) or instantiationToken
    (FMI 3.0); "" when not run from an FMU."""
    try:
        for _, element in iterparse(model_description, events=("start",)):
            return element.get("guid") or element.get("instantiationToken") or ""
    except (OSError, ParseError):
        pass
    return ""


class FmuStates:
    """The FMU states of :class:`~fmus.runtime.slave.BlockSlave`: get, set, serialize, deserialize."""

    @property
    def identity(self) -> str:
        """``"<model name> <GUID or instantiationToken>"``: the FMU a state belongs to."""
        guid = _guid(str(Path(self.resources).parent / "modelDescription.xml"))
        return f"{self.definition.model_name} {guid}"

    def _own(self, state) -> FmuState:
        """``state`` if it is a state of this FMU; :class:`Refused` otherwise."""
        if not isinstance(state, FmuState):
            raise Refused(f"not an FMU state of {self.definition.model_name} (a {type(state).__name__})")
        if state.identity != self.identity:
            raise Refused(f"this state belongs to another FMU ({state.identity!r}), not to {self.identity!r}")
        return state

    def get_fmu_state(self, loader: dict | None = None) -> FmuState:
        """Everything that evolves, as plain data: time, parameters, inputs, block state, history,
        whether initialization is over, and ``loader``: the native binary's own fields (its FMI
        version and state machine state, ``{"fmi": 2, "state": "stepComplete"}``), kept in the state
        and its bytes for the binary (:meth:`loader_fields`); None without the binary."""
        block = None
        if self._block is not None:
            if self._snapshot is None:
                leaves = Leaves()
                self._snapshot = (capture(self._block, leaves, rollback=True), leaves)
            block = self._snapshot[0]       # immutable objects kept as they are: plain data in its bytes
        return FmuState(self.identity, {
            "time": self._time,
            "params": {name: value.copy() for name, value in self._params.items()},
            "inputs": {name: value.copy() for name, value in self._inputs.items()},
            "modes": {name: value.astype(np.int64) for name, value in self._modes.items()},
            "derivatives": {name: value.copy() for name, value in self._derivatives.items()},
            "last_inputs": {name: (value, at) for name, (value, at) in self._last_inputs.items()},
            "block_error": self._block_error,
            "block": block,
            "initialized": self._stepping,
            "loader": None if loader is None else dict(loader),
        })

    def loader_fields(self, state) -> tuple[dict | None, float, bool]:
        """The native binary's fields of a state of this FMU, with its time and whether it was saved
        after initialization (the binary validates them against its state machine)."""
        tree = self._own(state).tree
        return tree["loader"], tree["time"], tree["initialized"]

    @host_independent_numerics
    def set_fmu_state(self, state) -> None:
        """Restore a state of this FMU; anything else is refused (:class:`Refused`) and changes nothing."""
        tree = self._own(state).tree
        try:
            self._check_tree(tree)
            block = snapshot = outputs = None
            if tree["block"] is not None:
                block, snapshot, outputs = self._restored_block(tree)
        except StateError as exc:
            raise Refused(str(exc)) from None
        # nothing can fail from here on
        for name in ("params", "inputs", "modes"):          # the variable getters hold these arrays
            for key, values in tree[name].items():
                getattr(self, f"_{name}")[key][:] = values
        self._derivatives = {name: np.array(value, dtype=float) for name, value in tree["derivatives"].items()}
        self._last_inputs = {name: (np.array(value, dtype=float), float(at))
                             for name, (value, at) in tree["last_inputs"].items()}
        self._time = tree["time"]
        self._stepping = tree["initialized"]
        self._use_block(block)
        self._block_error = tree["block_error"] if block is None else None
        self._snapshot, self._outputs_cache = snapshot, outputs

    def _restored_block(self, tree: dict) -> tuple[Block, tuple[dict, Leaves], dict | None]:
        """The block with the saved state, its snapshot and outputs, all checked; the live block is
        changed only if all is well.  The outputs are None (computed when read) when the saved inputs
        are not usable: a state saved after a bad input was set is a state like any other."""
        live = self._block
        same = live is not None and all(np.array_equal(tree["params"][name], value)
                                        for name, value in self._params.items())
        if same:
            block, rollback = live, (self._snapshot[0] if self._snapshot else capture(live, rollback=True))
        else:
            try:
                block, rollback = self._new_block(tree["params"]), None
            except Exception as exc:
                raise StateError(f"the parameters of the state do not define a valid block: "
                                 f"{type(exc).__name__}: {exc}") from None
        block.set_state(tree["block"])                         # checked: raises before any change
        try:
            leaves, bound = Leaves(), block.magnitude_bound
            snapshot = (capture(block, leaves, rollback=True), leaves)
            # every number restored; an immutable object (only in a state of this process) was checked when built
            fault = self._state_fault(tree["block"], None, None, bound)
            outputs = None                 # inputs that are not usable: the next step refuses, naming them
            if all(within(value, bound) for value in tree["inputs"].values()):
                outputs = block.outputs(tree["time"], tree["inputs"])
                fault = fault or self._output_fault(outputs, bound)
            if fault:
                raise StateError(f"the state is not usable: {fault}")
        except Exception as exc:
            if rollback is not None:
                block.set_state(rollback, check=False)
            if isinstance(exc, StateError):
                raise
            raise StateError(f"the state is not usable: {type(exc).__name__}: {exc}") from None
        return block, snapshot, outputs

    def _check_tree(self, tree) -> None:
        """The slave's part of a state must have exactly this FMU's variables and shapes."""
        def require(condition, what):
            if not condition:
                raise StateError(f"not a state of {self.definition.model_name}: {what}")

        require(type(tree) is dict and set(tree) == _SECTIONS, "wrong sections")
        require(type(tree["time"]) is float and math.isfinite(tree["time"]), "time")
        for section, store, dtype in (("params", self._params, np.float64), ("inputs", self._inputs, np.float64),
                                      ("modes", self._modes, np.int64)):
            values = tree[section]
            require(type(values) is dict and set(values) == set(store), f"{section}: wrong names")
            for name, value in values.items():
                require(type(value) is np.ndarray and value.dtype == dtype and value.shape == store[name].shape,
                        f"{section} {name}: wrong type or shape")
        require(all(int(m[0]) in InputMode._value2member_map_ for m in tree["modes"].values()), "modes: values")
        for section in ("derivatives", "last_inputs"):
            require(type(tree[section]) is dict and set(tree[section]) <= set(self._inputs), f"{section}: names")
        for name, value in tree["derivatives"].items():
            require(type(value) is np.ndarray and value.dtype == np.float64 and value.shape == self._inputs[name].shape,
                    f"derivatives {name}")
        for name, entry in tree["last_inputs"].items():
            require(type(entry) in (tuple, list) and len(entry) == 2 and type(entry[0]) is np.ndarray
                    and entry[0].dtype == np.float64 and entry[0].shape == self._inputs[name].shape
                    and type(entry[1]) is float and math.isfinite(entry[1]), f"last_inputs {name}")
        require(tree["block_error"] is None or type(tree["block_error"]) is str, "block_error")
        require(tree["block"] is None or type(tree["block"]) is dict, "block")
        require(type(tree["initialized"]) is bool, "initialized")
        require(not tree["initialized"] or (tree["block"] is not None and tree["block_error"] is None),
                "initialized without a block")
        loader = tree["loader"]
        require(loader is None or (type(loader) is dict and set(loader) == {"fmi", "state"}
                                   and type(loader["fmi"]) is int and type(loader["state"]) is str
                                   and len(loader["state"]) < 32), "loader")

    def serialize_fmu_state(self, state) -> bytes:
        """The bytes of ``state`` (:mod:`fmus.runtime.state_format`): the one serialized form of an FMU state."""
        state = self._own(state)
        try:
            return pack(state.identity, plain(state.tree))
        except StateFormatError as exc:           # beyond MAX_STATE_BYTES: not written, nothing changed
            raise Refused(str(exc)) from None

    def deserialize_fmu_state(self, data: bytes) -> FmuState:
        """An FMU state from bytes of :meth:`serialize_fmu_state`; anything else is refused
        (:class:`Refused`: format, version, identity, checksum, then every section checked)."""
        try:
            tree = unpack(data, self.identity)
            self._check_tree(tree)
        except (StateFormatError, StateError) as exc:
            raise Refused(str(exc)) from None
        return FmuState(self.identity, tree)

