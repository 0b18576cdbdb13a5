"""Component types ``lti``, ``expression``, ``luenberger`` and ``state-feedback`` of a system file.

The observer and controller are designed here as in the single-plant design file (:mod:`fmus.config`):
exactly one of ``poles``, ``t_settle`` (with ``form``), ``shift`` or the gain itself; a designed gain
must place the poles and keep the transient bounded.  Each designed gain is added to the build's notes.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError, require_hurwitz
from obsfmu.observers.feedback import integral_augmented
from obsfmu.observers.linearise import linearise
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.modal import is_controllable, is_observable, observer_gain, place
from obsfmu.observers.riccati import checked_weight
from obsfmu.observers.standard_forms import FORMS

from ..config import design_gain, require_bounded_transient
from ..runtime.kinds.expression import expression_plant_definition
from ..runtime.kinds.linear import (feedback_definition, integral_feedback_definition, observer_definition,
                                   plant_definition)
from .inmemory import component_block
from .schema import Context, Field, register
from .values import MAX_DIMENSION

__all__ = ["model_of", "matrix_text", "poles_text", "lqr_gain"]

_UNITS = (
    Field("state_units", "units", "unit of the state (one, or one per state)", None, example='["A", "rad/s", "rad"]'),
    Field("input_units", "units", "unit of the input u", None, example='"V"'),
    Field("output_units", "units", "unit of the output y", None, example='"rad"'),
    Field("state_names", "names", "a name per state (in FMU descriptions, summaries, figures, show); the CSV "
          "columns keep plant.x[i]", None, example='["current", "speed", "angle"]'),
    Field("input_names", "names", "a name per input", None, example='["voltage"]'),
    Field("output_names", "names", "a name per output", None, example='["angle"]'),
)
_SAMPLE_TIME = Field("sample_time", "number", "sample time T: the plant is discrete, x[k+1] = ... (absent: "
                     "continuous)", None, "s", "0.01")


def _expanded_units(values: dict, model: StateSpace) -> dict:
    """Units (``state_units`` ...) one per entry, and the entries' names (``state_names`` ...) where given."""
    units = {}
    for kind, size in (("state", model.n), ("input", model.m), ("output", model.p)):
        unit, names = values.get(f"{kind}_units"), values.get(f"{kind}_names")
        if unit is not None:
            if isinstance(unit, str):
                unit = [unit] * size
            elif len(unit) != size:
                raise ParameterError(f"{kind}_units: expected {size} units (one per entry), got {len(unit)}")
            units[f"{kind}_units"] = list(unit)
        if names is not None:
            if len(names) != size:
                raise ParameterError(f"{kind}_names: expected {size} names (one per {kind}), got {len(names)}")
            units[f"{kind}_names"] = list(names)
    return units


def model_of(values: dict, prefix: str) -> StateSpace:
    """The checked state-space model of an ``lti`` component."""
    dt = values["sample_time"]
    if dt is not None and dt <= 0:
        raise ParameterError(f"{prefix}sample_time: must be > 0 (absent: a continuous plant), got {dt:g}")
    return StateSpace.checked(values["A"], values["B"], values["C"], values["D"], prefix=prefix,
                              dt=0.0 if dt is None else dt)


def _define_lti(model_name: str, values: dict, context: Context) -> list:
    model = model_of(values, context.prefix)
    n = model.n
    x0 = np.zeros(n) if values["x0"] is None else values["x0"]
    if np.size(x0) != n:
        raise ParameterError(f"{context.prefix}x0: expected {n} entries (one per state), got {np.size(x0)}")
    try:
        units = _expanded_units(values, model)
    except ParameterError as exc:
        raise ParameterError(f"{context.prefix}{exc}") from None
    if not model.discrete:
        context.rate(np.linalg.eigvals(model.A), "A: eig(A)")
    return [plant_definition(model_name, model, x0, units, values["description"])]


register("lti", "Linear plant `x' = A x + B u`, `y = C x + D u` (with `sample_time`: `x[k+1] = A x[k] + B u[k]`). "
         "Ports: input `u` (size of B's columns), outputs `y` and the true state `x`.", (
             Field("A", "matrix", "state matrix (n x n)", unit="1/s", example="[[0, 1], [-2, -3]]"),
             Field("B", "matrix", "input matrix (n x m); absent: no input", None, example="[[0], [1]]"),
             Field("C", "matrix", "output matrix (p x n); absent: the identity", None, example="[[1, 0]]"),
             Field("D", "matrix", "feedthrough matrix (p x m); absent: zero", None, example="[[0]]"),
             Field("x0", "vector", "initial state (absent: zero)", None, example="[0.1, 0]"),
             _SAMPLE_TIME) + _UNITS, _define_lti)


def _plant(values: dict, context: Context, kind: str, discrete: bool = False) -> tuple[StateSpace, dict]:
    """The lti component ``values["plant"]`` names: its model and units (``discrete``: a sampled one accepted)."""
    name = values["plant"]
    other = context.others.get(name)
    if other is None or other[0] != "lti":
        what = "no component" if other is None else f"a component of kind {other[0]!r}"
        raise ParameterError(f"{context.prefix}plant: {name!r} is {what}; the {kind} needs an lti component "
                             "defined before it")
    model = model_of(other[1], f"components.{name}.")
    if model.discrete and not discrete:
        raise ParameterError(f"{context.prefix}plant: {name!r} is discrete (sample_time); the {kind} is designed "
                             "for a continuous lti plant")
    return model, _expanded_units(other[1], model)


def _design_fields(gain: str, shape: str, doc: str) -> tuple[Field, ...]:
    return (
        Field("plant", "component", "the lti component it is designed for", example='"plant"'),
        Field("poles", "poles", f"{doc} poles (n of them)", None, "1/s", "[[-2, 3], [-2, -3], -5]"),
        Field("t_settle", "number", "settling time: poles of a standard form", None, "s", "0.2"),
        Field("form", "choice", "standard form of the t_settle poles", "binomial", choices=FORMS),
        Field("shift", "number", "the plant's eigenvalues moved left by shift", None, "1/s", "5"),
        Field(gain, "matrix", f"the gain itself ({shape}), instead of a design", None, example="[[1.5, 0.3]]"),
    )


def _table(values: dict, keys) -> dict:
    """The design request as :func:`fmus.config.design_gain` reads it (only the fields the file gave)."""
    return {key: values[key] for key in keys if key in values["given"]}


def poles_text(poles) -> str:
    return ", ".join(f"{complex(p):.6g}".strip("()").replace("+0j", "").replace("-0j", "") for p in poles)


def matrix_text(matrix) -> str:
    """A matrix on one line, rows separated by ``;``: ``[1.5, 0.3; -2, 4]``."""
    rows = np.atleast_2d(np.real_if_close(np.asarray(matrix)))
    return "[" + "; ".join(", ".join(f"{v:.6g}" for v in row) for row in rows) + "]"


def _checked_gain(context: Context, table: dict, model, gain: str, shape, designer, closed_loop, loop_text: str):
    """The gain of ``table`` (designed or given) with the poles of its closed loop: Hurwitz always, and a
    bounded transient for designed poles (:func:`fmus.config.require_bounded_transient`).  The gain and
    poles go into the build's notes, the poles' largest magnitude into the rates the step is checked against."""
    section = context.prefix.rstrip(".")
    G, poles = design_gain(section, table, model, gain, shape, designer)
    loop = closed_loop(G)
    require_hurwitz(f"{section}.{gain} ({loop_text})", loop)
    if poles is not None:
        require_bounded_transient(f"{section}.poles", loop)
    poles = np.linalg.eigvals(loop) if poles is None else poles
    context.notes.append(f"{section}: {gain} = {matrix_text(G)}; eig({loop_text}) = [{poles_text(poles)}]")
    context.rate(poles, f"eig({loop_text})")
    return G, poles


def _linearised(values: dict, context: Context):
    """An ``expression`` plant's model linearised at ``x_op``, ``u_op`` (checked, :mod:`observers.linearise`), its
    units and names, and the observer's offsets ``(c, e)``."""
    name, prefix = values["plant"], context.prefix
    plant = component_block(name, context)
    if plant.sample_time is not None:
        raise ParameterError(f"{prefix}plant: {name!r} is a sampled expression plant; a luenberger observer is "
                             "designed from a continuous one's linearisation")
    n, m = plant.f.size, plant.input_sizes.get("u", 0)
    if values["x_op"] is None:
        raise ParameterError(f"{prefix}x_op: {name!r} is an expression plant; give the operating point x_op ({n} "
                             "entries; and u_op) at which its linearisation designs the observer")
    x_op = np.asarray(values["x_op"], dtype=float)
    u_op = np.zeros(m) if values["u_op"] is None else np.asarray(values["u_op"], dtype=float)
    for key, vector, size in (("x_op", x_op, n), ("u_op", u_op, m)):
        if vector.size != size:
            raise ParameterError(f"{prefix}{key}: expected {size} entries, got {vector.size}")
    lin = linearise(plant.f, plant.h, x_op, u_op, plant.p, where=f"{prefix}x_op")
    model = StateSpace.checked(lin.A, lin.B if m else None, lin.C, lin.D if m else None, prefix=prefix)
    offsets = (lin.f0 - lin.A @ x_op - lin.B @ u_op, lin.y0 - lin.C @ x_op - lin.D @ u_op)
    context.notes.append(f"{prefix.rstrip('.')}: {name!r} linearised at x = {matrix_text(x_op)}, u = "
                         f"{matrix_text(u_op)}: A = {matrix_text(lin.A)}, C = {matrix_text(lin.C)}"
                         + ("" if not np.any(lin.f0) else f"; f there = {matrix_text(lin.f0)} (not an equilibrium)"))
    units = {key: list(value) if isinstance(value, list) else [value] * size
             for key, size in (("state_units", n), ("input_units", m), ("output_units", model.p))
             if (value := context.others[name][1].get(key)) is not None}
    return model, units, offsets


def _define_observer(model_name: str, values: dict, context: Context) -> list:
    offsets = None
    if context.others.get(values["plant"], ("",))[0] == "expression":
        model, units, offsets = _linearised(values, context)
    else:
        model, units = _plant(values, context, "luenberger observer", discrete=True)
    if not is_observable(model.A, model.C):
        raise ParameterError(f"{context.prefix}plant: the pair (A, C) of {values['plant']!r} is not observable"
                             f"{' at the operating point' if offsets else ''}; no observer can reconstruct the state")
    if model.discrete:
        table = _table(values, ("poles", "t_settle", "shift", "form", "N"))
        return [_discrete_observer(model_name, values, context, model, units, table)]
    return [_continuous_observer(model_name, values, context, model, units, offsets)]


def _continuous_observer(model_name: str, values: dict, context: Context, model, units: dict, offsets=None):
    """The observer of a continuous model (an lti plant's, or a linearisation's with its ``offsets``)."""
    table = _table(values, ("poles", "t_settle", "shift", "form", "N"))
    if values["Q"] is not None or values["R"] is not None:
        N, poles, table = _kalman(values, context, model, table), None, {}
    else:
        N, poles = _checked_gain(context, table, model, "N", (model.n, model.p),
                                 lambda p, name: observer_gain(model.A, model.C, p, name),
                                 lambda N: model.A - N @ model.C, "A - N C")
    x_hat0 = np.zeros(model.n) if values["x_hat0"] is None else values["x_hat0"]
    if np.size(x_hat0) != model.n:
        raise ParameterError(f"{context.prefix}x_hat0: expected {model.n} entries, got {np.size(x_hat0)}")
    poles = np.linalg.eigvals(model.A - N @ model.C) if poles is None else poles
    design = _carried_design(values, table, context, "N", model.p, "output", model.A) if offsets is None else None
    if values["Q"] is not None and offsets is None:
        design = _riccati_design(values, "kalman", N)
    return observer_definition(model_name, model, N, x_hat0, units, values["description"], poles, design, offsets)


def lqr_gain(where: str, A, B, Q, R) -> np.ndarray:
    """The LQR gain ``K = R^-1 B' P``, ``P`` the stabilising solution of ``A' P + P A - P B R^-1 B' P + Q = 0``
    (minimises ``int x' Q x + u' R u`` under ``u = -K x``).  The steady-state Kalman gain is its dual:
    ``N = lqr_gain(A', C', Q, R)'``."""
    from scipy.linalg import solve_continuous_are
    try:
        P = solve_continuous_are(A, B, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ParameterError(f"{where}: the Riccati equation has no stabilising solution ({exc})") from None
    return np.linalg.solve(R, B.T @ P)


def _riccati_request(values: dict, prefix: str, table: dict, gain: str) -> None:
    if values["Q"] is None or values["R"] is None or table.keys() - {"form"}:
        raise ParameterError(f"{prefix}Q, R: a{' Kalman' if gain == 'N' else 'n LQR'} design needs both Q and R and "
                             f"none of poles, t_settle, shift, {gain}")


def _kalman(values: dict, context: Context, model, table: dict) -> np.ndarray:
    """The steady-state Kalman gain (LQE) N = P C' R^-1, P the stabilising solution of the continuous Riccati
    equation A P + P A' - P C' R^-1 C P + Q = 0 (process noise entering every state: G = I)."""
    prefix = context.prefix
    _riccati_request(values, prefix, table, "N")
    Q = checked_weight(f"{prefix}Q", values["Q"], model.n, definite=False)
    R = checked_weight(f"{prefix}R", values["R"], model.p, definite=True)
    N = lqr_gain(f"{prefix}Q, R", model.A.T, model.C.T, Q, R).T
    require_hurwitz(f"{prefix}Q, R (A - N C of the Kalman gain)", model.A - N @ model.C)
    context.notes.append(f"{prefix.rstrip('.')}: Kalman N = {matrix_text(N)}; eig(A - N C) = "
                         f"[{poles_text(np.linalg.eigvals(model.A - N @ model.C))}]")
    context.rate(np.linalg.eigvals(model.A - N @ model.C), "eig(A - N C)")
    return N


def _lqr(values: dict, context: Context, model, table: dict) -> np.ndarray:
    """The LQR gain K = R^-1 B' P of the state weight Q and the input weight R."""
    prefix = context.prefix
    _riccati_request(values, prefix, table, "K")
    Q = checked_weight(f"{prefix}Q", values["Q"], model.n, definite=False, what="state weight")
    R = checked_weight(f"{prefix}R", values["R"], model.m, definite=True, what="input weight")
    K = lqr_gain(f"{prefix}Q, R", model.A, model.B, Q, R)
    loop = model.A - model.B @ K
    require_hurwitz(f"{prefix}Q, R (A - B K of the LQR gain)", loop)
    context.notes.append(f"{prefix.rstrip('.')}: LQR K = {matrix_text(K)}; eig(A - B K) = "
                         f"[{poles_text(np.linalg.eigvals(loop))}]")
    context.rate(np.linalg.eigvals(loop), "eig(A - B K)")
    return K


def _discrete_observer(model_name: str, values: dict, context: Context, model, units: dict, table: dict):
    """The predictor x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u) of a sampled plant: N given, or the
    steady-state discrete Kalman gain of Q and R (the continuous designs poles, t_settle, shift do not apply)."""
    prefix = context.prefix
    if table.keys() & {"poles", "t_settle", "shift"}:
        raise ParameterError(f"{prefix}poles: {values['plant']!r} is discrete (sample_time); give N (A - N C "
                             "Schur-stable) or Q and R (the discrete Kalman gain), not poles, t_settle or shift")
    if values["Q"] is not None or values["R"] is not None:
        N = _discrete_kalman(values, context, model, table)
    elif "N" in table:
        N = table["N"]
    else:
        raise ParameterError(f"{prefix}N: {values['plant']!r} is discrete (sample_time); give N or Q and R")
    x_hat0 = np.zeros(model.n) if values["x_hat0"] is None else values["x_hat0"]
    if np.size(x_hat0) != model.n:
        raise ParameterError(f"{prefix}x_hat0: expected {model.n} entries, got {np.size(x_hat0)}")
    try:
        N = np.asarray(N, dtype=float).reshape(model.n, model.p)
    except ValueError:
        raise ParameterError(f"{prefix}N: expected {model.n} x {model.p} (n x p), got shape {np.shape(N)}") from None
    poles = np.linalg.eigvals(model.A - N @ model.C)
    if not np.max(np.abs(poles)) < 1.0:
        raise ParameterError(f"{prefix}N: eig(A - N C) = [{poles_text(poles)}] not all inside the unit circle; a "
                             "discrete observer's error e[k+1] = (A - N C) e[k] must decay")
    context.notes.append(f"{prefix.rstrip('.')}: N = {matrix_text(N)}; eig(A - N C) = [{poles_text(poles)}] "
                         "(discrete: |.| < 1)")
    design = _riccati_design(values, "kalman", N) if values["Q"] is not None else None
    return observer_definition(model_name, model, N, x_hat0, units, values["description"], poles, design)


def _discrete_kalman(values: dict, context: Context, model, table: dict) -> np.ndarray:
    """The steady-state Kalman gain of the predictor, N = A P C' (C P C' + R)^-1, P the stabilising solution of
    the discrete Riccati equation P = A P A' - A P C' (C P C' + R)^-1 C P A' + Q (process noise on every state)."""
    from scipy.linalg import solve_discrete_are
    prefix = context.prefix
    _riccati_request(values, prefix, table, "N")
    Q = checked_weight(f"{prefix}Q", values["Q"], model.n, definite=False)
    R = checked_weight(f"{prefix}R", values["R"], model.p, definite=True)
    try:
        P = solve_discrete_are(model.A.T, model.C.T, Q, R)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ParameterError(f"{prefix}Q, R: the discrete Riccati equation has no stabilising solution ({exc})") \
            from None
    return model.A @ P @ model.C.T @ np.linalg.inv(model.C @ P @ model.C.T + R)


def _carried_design(values: dict, table: dict, context: Context, gain: str, channels: int, channel: str,
                    A: np.ndarray):
    """The design the FMU carries as its parameter (``tunable``), or None: the gain itself is.  Complex poles with
    several outputs (inputs) need scipy's place_poles (a shift of a plant with complex eigenvalues, the
    Butterworth form); an FMU carries numpy only, so their gain stays the parameter (said in the build's notes)."""
    design = _design(table) if values["tunable"] else None
    if design is None:
        return None
    complex_poles = design[0] == "shift" and np.any(np.linalg.eigvals(A).imag != 0) or \
        design[0] == "t_settle" and design[2] == "butterworth" and len(A) > 1
    if channels > 1 and complex_poles:
        context.notes.append(f"{context.prefix.rstrip('.')}: {gain} is the FMU's parameter (complex poles with "
                             f"several {channel}s need scipy, which an FMU does not carry: tunable designs with "
                             f"several {channel}s are real poles, binomial t_settle, or a shift of real eigenvalues)")
        return None
    return design


def _riccati_design(values: dict, name: str, gain):
    """``(name, (Q, R), gain)``: the FMU carries the weights (checked by the build) and designs its gain from them
    at initialisation by Newton's method from the build's ``gain`` (:mod:`observers.riccati`); None when not
    ``tunable``."""
    if not values["tunable"]:
        return None
    return name, (np.asarray(values["Q"], dtype=float), np.asarray(values["R"], dtype=float)), gain


def _tunable(gain: str, channel: str) -> Field:
    return Field("tunable", "boolean", f"the design (`t_settle`, `shift`, real `poles`, or `Q` and `R`) is the FMU's "
                 f"parameter and {gain} is designed from it at initialisation (`--set`, `--vary`, importers change "
                 f"it); false, or complex poles (the butterworth form, a shift of complex eigenvalues) with several "
                 f"{channel}s: {gain} itself is the parameter", True, example="false")


def _design(table: dict):
    """The design the FMU carries as a parameter and designs its gain from at initialisation (``--set``,
    ``--vary`` and importers can change it), or None: the gain itself (given, or complex poles)."""
    form = table.get("form", "binomial")
    if "t_settle" in table:
        return "t_settle", table["t_settle"], form
    if "shift" in table:
        return "shift", table["shift"], form
    if "poles" in table and all(np.isreal(complex(p) if np.ndim(p) == 0 else complex(*p)) for p in table["poles"]):
        return "poles", [float(np.real(p if np.ndim(p) == 0 else p[0])) for p in table["poles"]], form
    return None


register("luenberger", "Luenberger observer of an lti component: `x_hat' = A x_hat + B u + N (y - C x_hat - D u)`. "
         "Give exactly one of `poles`, `t_settle` (with `form`), `shift`, `N`, or the noise covariances `Q` and `R` "
         "(the steady-state Kalman gain). For a sampled plant (`sample_time`) the predictor `x_hat[k+1] = A x_hat + "
         "B u + N (y - C x_hat - D u)` at `t = k T`, with `N` or `Q` and `R` (discrete Kalman). Inputs `u`, `y`; "
         "outputs `x_hat`, `y_hat`.", _design_fields("N", "n x p", "observer") + (
             Field("x_hat0", "vector", "initial estimate (absent: zero)", None, example="[0, 0]"),
             Field("Q", "matrix", "process noise covariance (n x n, entering every state): with R, the "
                   "steady-state Kalman gain (LQE) instead of poles", None, example="[[0, 0], [0, 1]]"),
             Field("R", "matrix", "measurement noise covariance (p x p, positive definite)", None, example="[[1e-4]]"),
             Field("x_op", "vector", "for an expression plant: the state of the operating point whose linearisation "
                   "(numerical Jacobians, checked) the observer is designed from", None, example="[0, 0]"),
             Field("u_op", "vector", "for an expression plant: the input there (absent: zero)", None,
                   example="[0]"),
             _tunable("N", "output"),),
         _define_observer, depends=("plant",))


def _define_feedback(model_name: str, values: dict, context: Context) -> list:
    model, units = _plant(values, context, "state feedback")
    if model.m == 0:
        raise ParameterError(f"{context.prefix}plant: {values['plant']!r} has no input (B absent)")
    if not is_controllable(model.A, model.B):
        raise ParameterError(f"{context.prefix}plant: the pair (A, B) of {values['plant']!r} is not controllable; "
                             "state feedback cannot place the poles")
    table = _table(values, ("poles", "t_settle", "shift", "form", "K"))
    design = _augmented(model, values, context) if values["integral"] else model
    if values["Q"] is not None or values["R"] is not None:
        K = _lqr(values, context, design, table)
    else:
        K, _ = _checked_gain(context, table, design, "K", (design.m, design.n),
                             lambda p, name: place(design.A, design.B, p, name),
                             lambda K: design.A - design.B @ K, "A - B K" if design is model else "A_a - B_a K")
    carried = _carried_design(values, table, context, "K", model.m, "input", design.A)
    if values["Q"] is not None:
        carried = _riccati_design(values, "lqr", K)
    if not values["integral"]:
        return [feedback_definition(model_name, K, units, values["description"], carried, model)]
    K = np.asarray(K, dtype=float).reshape(design.m, design.n)
    return [integral_feedback_definition(model_name, K[:, :model.n], K[:, model.n:], units, values["description"],
                                         carried, model)]


def _augmented(model, values: dict, context: Context) -> StateSpace:
    """The plant with the integrators of its output error, ``[x; z]' = [[A, 0], [C, 0]] [x; z] + [[B], [0]] u``:
    its gain ``[K, K_i]`` (``n + p`` poles, or Q of that size) gives integral action."""
    p = model.p
    A, B = integral_augmented(model.A, model.B, model.C)
    if np.any(model.D):
        raise ParameterError(f"{context.prefix}integral: {values['plant']!r} has a feedthrough D; integral action is "
                             "designed here for y = C x")
    if not is_controllable(A, B):
        raise ParameterError(f"{context.prefix}integral: the plant with the integrators of y - r is not controllable "
                             f"(more outputs ({p}) than inputs ({model.m}), or a zero of the plant at s = 0): no "
                             "integral action can hold y at r")
    return StateSpace.checked(A, B, np.hstack([model.C, np.zeros((p, p))]), prefix=context.prefix)


register("state-feedback", "State feedback `u = -K x_hat + r` for an lti component. Give exactly one of `poles`, "
         "`t_settle` (with `form`), `shift`, `K`, or the LQR weights `Q` and `R`. Inputs `x_hat`, `r`; output `u`. "
         "With `integral = true`: `u = -K x_hat - K_i z`, `z' = y - r` (inputs `x_hat`, `y`, `r`; `K` of the plant "
         "augmented with the integrators, n + p).",
         _design_fields("K", "m x n", "closed-loop") + (
             Field("Q", "matrix", "LQR state weight (n x n, symmetric positive semidefinite): with R, the gain K = "
                   "R^-1 B' P minimising int x' Q x + u' R u, instead of poles", None, example="[[10, 0], [0, 1]]"),
             Field("R", "matrix", "LQR input weight (m x m, symmetric positive definite)", None, example="[[0.1]]"),
             Field("integral", "boolean", "integral action: u = -K x_hat - K_i z, z' = y - r (inputs x_hat, y, r; "
                   "r is then the reference of y, tracked without steady-state error); the design (n + p poles, or "
                   "Q of n + p) is that of the plant augmented with the integrators", False, example="true"),
             _tunable("K", "input"),
         ), _define_feedback, depends=("plant",))


def _define_expression(model_name: str, values: dict, context: Context) -> list:
    n = len(values["f"])
    if values["states"] is not None and values["states"] != n:
        raise ParameterError(f"{context.prefix}f: {n} expressions, but states = {values['states']}")
    x0 = np.zeros(n) if values["x0"] is None else values["x0"]
    return [expression_plant_definition(
        model_name, values["f"], values["h"], x0, inputs=values["inputs"], parameters=values["parameters"],
        parameter_units=values["parameter_units"], sample_time=values["sample_time"],
        max_substep=values["max_substep"], rtol=values["rtol"], atol=values["atol"], state_units=values["state_units"], output_units=values["output_units"],
        input_units=values["input_units"], field_prefix=context.prefix, description=values["description"])]


register("expression", "Plant of expressions: `dx/dt = f(t, x, u, p)`, `y = h(t, x, u, p)` (with `sample_time`: "
         "`x[k+1] = f`). `x`, `u`, `p` are indexed from 1; named parameters are FMU parameters too. Ports: input `u` "
         "(if inputs > 0), outputs `y` and `x`. What the integrator guarantees: a continuous plant advances by RK4 "
         "sub-steps of at most `max_substep`, each accepted only when its local error estimate (the embedded "
         "third-order solution of the same stages) is within `atol + rtol |x|` in every state, else taken again "
         "shorter; a communication step that needs more than `substep_budget` sub-steps is refused (fmi2Discard, "
         "naming it). A stiff plant is therefore integrated to `atol` (`f = -2700 x[1]`: 1.5e-15 at 0.05 s, exact "
         "2e-59; plain RK4 at 1e-3 gave 1.6e-3) or refused, never silently wrong. The bound is per sub-step: an "
         "unstable or chaotic plant's global error still grows with time.", (
             Field("states", "integer", "number of states (absent: the number of f's expressions)", None,
                   example="2", maximum=MAX_DIMENSION),
             Field("inputs", "integer", "size of the input u", 0, example="1", maximum=MAX_DIMENSION),
             Field("parameters", "table", "named parameters of the expressions (FMU parameters)", None,
                   example="{ g = 9.81, l = 0.5 }"),
             Field("parameter_units", "unit-table", "their units", None, example='{ g = "m/s2" }'),
             Field("f", "expressions", "right-hand side, one expression per state", example='["x[2]", "-x[1]"]'),
             Field("h", "expressions", "output, one expression per output", example='["x[1]"]'),
             Field("x0", "vector", "initial state (absent: zero)", None, example="[0.5, 0]"),
             _SAMPLE_TIME,
             Field("max_substep", "number", "longest RK4 sub-step of a continuous plant", 1e-3, "s", "1e-4"),
             Field("rtol", "number", "relative error tolerance of each RK4 sub-step (a longer one is taken again "
                   "shorter)", 1e-8, "", "1e-6"),
             Field("atol", "number", "absolute error tolerance of each RK4 sub-step, in the states' units", 1e-12,
                   "", "1e-9"),
         ) + _UNITS, _define_expression)
