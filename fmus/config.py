"""Observer FMUs for the user's own LTI plant, from a small TOML file.

Example (the ship of paper 002; the scenario ``ship`` itself is a system file,
``fmus/scenarios/ship/system.toml``; another design: ``examples/nomoto3.toml``)::

    name = "ship"                  # FMU names: ship_plant, ship_observer, ship_controller
    description = "..."            # optional

    [plant]                        # x' = A x + B u, y = C x + D u
    A = [[0, 1], [-2, 3]]
    B = [[0], [1]]
    C = [[1, 0]]
    x0 = [0.05, 0.2]               # optional, default 0
    state_units = ["rad", "rad/s"] # optional (also input_units, output_units)
    fmu = true                     # also build the plant FMU (default true)

    [observer]                     # exactly one of: poles, t_settle, shift, N
    t_settle = 0.15                # settling time of the estimation error, s
    form = "binomial"              # or "butterworth"
    x_hat0 = [0, 0]

    [controller]                   # optional: state feedback u = -K x_hat + r
    t_settle = 0.3                 # or poles = [...], shift = ... or K = [[...]]

Poles are numbers or ``[re, im]`` pairs (``poles = [[-2, 3], [-2, -3], -5]``);
``shift = s`` asks for the plant's own eigenvalues moved left by ``s`` -- the
well-conditioned choice for plants of high order (a 50-state flexible
structure: every mode damped, see ``docs/DEVELOPING.md``).

Designed gains are checked twice (:mod:`observers.modal`): the closed loop
must have the requested poles to 1 % (relative) as computed in double
precision -- the binomial form of order 20 (a 20-fold pole) fails, its
eigenvalues scatter by 36 % -- and must not amplify an initial error more
than 1e8 times before it decays (fast poles on a chain of integrators need
gains of 1e20).  Either failure is refused with the reason.

Every error names the field it comes from (``plant.A: expected a square
matrix ...``); dimensions, finiteness, observability/controllability and the
stability of the designed gains are all checked before anything is built.
Limits: at most ``MAX_DIMENSION`` (200) states, inputs and outputs each --
the FMUs have one variable per matrix entry (200 states: 40 000 for ``A``,
built in about 7 s and 340 MB); a bigger matrix is refused as soon as its
size is read, and a file over ``MAX_FILE_BYTES`` (4 MiB) before it is read.  Texts (``description``, units) hold no control characters
(they go into the modelDescription's XML).
"""

from __future__ import annotations

import os
import sys
import unicodedata
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from obsfmu.observers.checks import ParameterError, as_matrix, as_vector, require_hurwitz
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.modal import (MAX_TRANSIENT_GROWTH, desired_poles, shifted_poles, is_controllable, is_observable, observer_gain,
                             place, transient_growth)
from obsfmu.observers.standard_forms import FORMS

from .runtime.definition import FmuDefinition, experiment, valid_identifier
from .toml_numbers import huge_integer
from .runtime.kinds.linear import feedback_definition, observer_definition, plant_definition

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["LinearDesign", "load_config", "design_from_config", "design_gain", "require_bounded_transient",
           "MAX_DIMENSION"]

MAX_DIMENSION = 200  #: states, inputs and outputs of a design, each (its FMUs: a variable per matrix entry)
MAX_FILE_BYTES = 4 * 2**20  #: a design file (200 states at 17 digits: about 1 MB)

_SECTIONS = {
    "": {"name", "description", "plant", "observer", "controller"},
    "plant": {"A", "B", "C", "D", "x0", "state_units", "input_units", "output_units", "fmu"},
    "observer": {"poles", "t_settle", "shift", "form", "N", "x_hat0"},
    "controller": {"poles", "t_settle", "shift", "form", "K"},
}


@dataclass
class LinearDesign:
    """A checked plant model with its designed observer (and optional controller)."""

    name: str
    description: str
    model: StateSpace
    x0: np.ndarray
    units: dict
    N: np.ndarray
    observer_poles: np.ndarray
    x_hat0: np.ndarray
    K: np.ndarray | None
    controller_poles: np.ndarray | None
    build_plant: bool

    def experiment(self) -> dict[str, float]:
        """The design's own ``DefaultExperiment``: 10 time constants of its slowest designed pole (the errors
        decay by ``e^-10``), at a hundredth of the time constant of its fastest, each to one digit."""
        poles = np.concatenate([self.observer_poles, [] if self.controller_poles is None else self.controller_poles])
        slowest, fastest = np.abs(np.real(poles)).min(), np.abs(poles).max()
        return experiment(float(f"{10 / slowest:.1g}"), float(f"{0.01 / fastest:.1g}"))

    def definitions(self, default_experiment: dict[str, float] | None = None) -> list[FmuDefinition]:
        """FMU definitions: observer, then plant and controller when requested; ``default_experiment``: the
        FMUs' (None: none, a scenario built on the design fills in its own)."""
        text = self.description
        result = [observer_definition(f"{self.name}_observer", self.model, self.N, self.x_hat0,
                                      self.units, "", self.observer_poles)]
        if self.build_plant:
            result.append(plant_definition(f"{self.name}_plant", self.model, self.x0, self.units,
                                           f"{text} -- plant" if text else ""))
        if self.K is not None:
            result.append(feedback_definition(f"{self.name}_controller", self.K, self.units, ""))
        for definition in result:
            definition.default_experiment = default_experiment
        return result


def load_config(path: Path | str) -> dict:
    """Read a TOML design file; syntax errors name the file and line."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            size = os.fstat(handle.fileno()).st_size
            if size > MAX_FILE_BYTES:
                raise ParameterError(f"config {path}: {size / 2**20:.1f} MiB; a design file has at most "
                                     f"{MAX_FILE_BYTES // 2**20} MiB ({MAX_DIMENSION} states, inputs and outputs)")
            config = tomllib.load(handle)
    except FileNotFoundError:
        raise ParameterError(f"config: file {path} does not exist") from None
    except IsADirectoryError:
        raise ParameterError(f"config {path}: is a directory, expected a TOML file") from None
    except OSError as exc:
        raise ParameterError(f"config {path}: cannot be read ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError(f"config {path}: {exc}") from None
    except UnicodeDecodeError:
        raise ParameterError(f"config {path}: not a UTF-8 text file") from None
    if not config:
        raise ParameterError(f"config {path}: the file is empty; a design needs at least name, [plant] "
                             "and [observer]")
    huge = huge_integer(config)
    if huge:
        raise ParameterError(f"config {path}: {huge}")
    return config


def _check_keys(section: str, table) -> None:
    if not isinstance(table, dict):
        raise ParameterError(f"{section}: expected a table, got {table!r}")
    unknown = set(table) - _SECTIONS[section]
    if unknown:
        where = f"{section}." if section else ""
        raise ParameterError(f"{where}{sorted(unknown)[0]}: unknown field; expected one of "
                             f"{sorted(_SECTIONS[section])}")


#: fields that hold numbers (TOML booleans are refused there, although numpy would take them as 0/1)
_NUMERIC = {"plant": ("A", "B", "C", "D", "x0"), "observer": ("poles", "t_settle", "N", "x_hat0"),
            "controller": ("poles", "t_settle", "K")}


def _reject_booleans(field: str, value, index: tuple[int, ...] = ()) -> None:
    if isinstance(value, bool):
        where = f"entry {index} is" if index else "got"
        raise ParameterError(f"{field}: {where} {str(value).lower()}, expected a number (booleans are not numbers)")
    if isinstance(value, list):
        for i, item in enumerate(value):
            _reject_booleans(field, item, index + (i + 1,))


#: the axes of the plant's matrices, for the size limit
_AXES = {"A": ("states", "states"), "B": ("states", "inputs"), "C": ("outputs", "states"), "D": ("outputs", "inputs")}


def _require_small(plant: dict) -> None:
    """Refuse a plant matrix beyond ``MAX_DIMENSION`` rows or columns from its size alone (before any work)."""
    for key, axes in _AXES.items():
        rows = plant.get(key)
        if not isinstance(rows, list):
            continue
        columns = len(rows[0]) if rows and isinstance(rows[0], list) else 1
        for size, axis in zip((len(rows), columns), axes):
            if size > MAX_DIMENSION:
                raise ParameterError(f"plant.{key}: {size} {axis}; a design has at most {MAX_DIMENSION} states, "
                                     f"inputs and outputs each (its FMUs have one variable per matrix entry)")


def _require_text(field: str, value) -> str:
    """A string without control characters (it goes into the FMUs' XML and logs)."""
    if not isinstance(value, str):
        raise ParameterError(f"{field}: expected a string, got {value!r}")
    for position, character in enumerate(value):
        if unicodedata.category(character) == "Cc":
            raise ParameterError(f"{field}: control character {character!r} at position {position + 1}; "
                                 "texts are written into the FMUs' XML, write them on one line without "
                                 "control characters")
        if unicodedata.category(character) == "Cf":      # U+202E, zero-width: the text reads otherwise than it is
            raise ParameterError(f"{field}: invisible format character U+{ord(character):04X} at position "
                                 f"{position + 1} (a bidirectional override or zero-width character)")
    return value


def _units(plant: dict, model: StateSpace) -> dict:
    units = {}
    for key, size in (("state_units", model.n), ("input_units", model.m), ("output_units", model.p)):
        if key in plant:
            values = plant[key]
            if not (isinstance(values, list) and len(values) == size and all(isinstance(v, str) for v in values)):
                raise ParameterError(f"plant.{key}: expected {size} unit strings, got {values!r}")
            units[key] = [_require_text(f"plant.{key}[{i + 1}]", unit) for i, unit in enumerate(values)]
    return units


def _poles(name: str, values) -> np.ndarray:
    """Poles from TOML: numbers, or ``[re, im]`` pairs for complex ones (TOML has no complex numbers)."""
    if not isinstance(values, list) or not values:
        raise ParameterError(f"{name}: expected a list of poles (numbers, or [re, im] pairs), got {values!r}")
    poles = []
    for i, value in enumerate(values):
        pair = as_vector(f"{name}[{i + 1}]", value)
        if pair.size > 2:
            raise ParameterError(f"{name}[{i + 1}]: expected a number or an [re, im] pair, got {value!r}")
        poles.append(complex(pair[0], pair[1] if pair.size == 2 else 0.0))
    poles = np.array(poles)
    return poles.real if not np.any(poles.imag) else poles


def design_gain(section: str, table: dict, model: StateSpace, gain_name: str, shape, designer):
    """A gain given directly (checked: Hurwitz) or designed from poles / t_settle / shift.

    A designed gain is also checked for transient growth (:func:`observers.modal.transient_growth`).
    """
    chosen = [key for key in ("poles", "t_settle", "shift", gain_name) if key in table]
    if len(chosen) != 1:
        raise ParameterError(f"{section}: give exactly one of 'poles', 't_settle', 'shift' or '{gain_name}', "
                             f"got {chosen or 'none'}")
    form = table.get("form", "binomial")
    if form not in FORMS:
        raise ParameterError(f"{section}.form: unknown standard form {form!r}; choose one of {FORMS}")
    if gain_name in table:
        return as_matrix(f"{section}.{gain_name}", table[gain_name], shape=shape), None
    n = model.n
    try:
        if "shift" in table:
            poles = shifted_poles(model.A, table["shift"], f"{section}.shift")
        else:
            poles = desired_poles(n, poles=_poles(f"{section}.poles", table["poles"]) if "poles" in table else None,
                                  t_settle=table.get("t_settle"), form=form, name=f"{section}.poles")
        gain = designer(poles, f"{section}.poles")
    except ParameterError as exc:
        message = str(exc)
        raise ParameterError(message if message.startswith(section) else f"{section}.{message}") from None
    return gain, poles


def require_bounded_transient(name: str, closed_loop: np.ndarray) -> None:
    growth = transient_growth(closed_loop)
    if growth > MAX_TRANSIENT_GROWTH:
        raise ParameterError(
            f"{name}: the designed closed loop amplifies an initial error up to {growth:.2g} times before it "
            f"decays (max_t |exp(M t)|, accepted: {MAX_TRANSIENT_GROWTH:g}); its rounding errors grow as much, "
            "so the estimate would be meaningless; choose slower poles or poles closer to the plant's own "
            "('shift')")


def design_from_config(config: dict) -> LinearDesign:
    """Check a parsed config and design its gains; raises :class:`ParameterError` naming the field."""
    _check_keys("", config)
    if "name" not in config:
        raise ParameterError("name: missing; the FMUs are called NAME_observer, NAME_plant, NAME_controller")
    name = config["name"]
    if not isinstance(name, str) or not valid_identifier(name):
        raise ParameterError(f"name: expected an identifier (letters, digits, _), got {name!r}")
    for section in ("plant", "observer"):
        if section not in config:
            raise ParameterError(f"{section}: missing section [{section}]")
    plant, observer = config["plant"], config["observer"]
    _check_keys("plant", plant)
    _check_keys("observer", observer)
    for section, keys in _NUMERIC.items():
        table = config.get(section, {})
        for key in keys:
            if isinstance(table, dict) and key in table:
                _reject_booleans(f"{section}.{key}", table[key])
    for key in ("A", "C"):
        if key not in plant:
            raise ParameterError(f"plant.{key}: missing")
    _require_small(plant)
    model = StateSpace.checked(plant["A"], plant.get("B"), plant["C"], plant.get("D"), prefix="plant.")
    n = model.n
    if not is_observable(model.A, model.C):
        raise ParameterError("plant.C: the pair (plant.A, plant.C) is not observable; "
                             "no observer can reconstruct the state")
    N, observer_poles = design_gain("observer", observer, model, "N", (n, model.p),
                              lambda poles, name: observer_gain(model.A, model.C, poles, name))
    require_hurwitz("observer.N (A - N C)", model.A - N @ model.C)
    if observer_poles is not None:
        require_bounded_transient("observer.poles", model.A - N @ model.C)
    if observer_poles is None:
        observer_poles = np.linalg.eigvals(model.A - N @ model.C)

    K = controller_poles = None
    if "controller" in config:
        controller = config["controller"]
        _check_keys("controller", controller)
        if model.m == 0:
            raise ParameterError("controller: the plant has no input (plant.B missing)")
        if not is_controllable(model.A, model.B):
            raise ParameterError("plant.B: the pair (plant.A, plant.B) is not controllable; "
                                 "state feedback cannot place the poles")
        K, controller_poles = design_gain("controller", controller, model, "K", (model.m, n),
                                    lambda poles, name: place(model.A, model.B, poles, name))
        require_hurwitz("controller.K (A - B K)", model.A - model.B @ K)
        if controller_poles is not None:
            require_bounded_transient("controller.poles", model.A - model.B @ K)

    build_plant = plant.get("fmu", True)
    if not isinstance(build_plant, bool):
        raise ParameterError(f"plant.fmu: expected true or false, got {build_plant!r}")
    description = _require_text("description", config.get("description", ""))
    return LinearDesign(
        name=name,
        description=description,
        model=model,
        x0=as_vector("plant.x0", plant.get("x0", np.zeros(n)), n),
        units=_units(plant, model),
        N=N,
        observer_poles=np.asarray(observer_poles),
        x_hat0=as_vector("observer.x_hat0", observer.get("x_hat0", np.zeros(n)), n),
        K=K,
        controller_poles=controller_poles,
        build_plant=build_plant,
    )
