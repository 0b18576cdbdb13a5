"""Kinds for linear models (paper 002): LTI plant, Luenberger observer, state feedback.

Each kind has a factory (FMU parameters -> block) and a definition function
(design-time data -> :class:`~fmus.runtime.definition.FmuDefinition`).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.feedback import IntegralStateFeedback, StateFeedback
from obsfmu.observers.luenberger import LuenbergerObserver
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.modal import MAX_TRANSIENT_GROWTH, desired_poles, observer_gain, shifted_poles, transient_growth
from obsfmu.plants.lti import LTIPlant

from ..definition import FmuDefinition, Parameter, Port
from . import register

__all__ = ["plant_definition", "observer_definition", "feedback_definition", "integral_feedback_definition",
           "vector_unit"]


@register("lti-plant")
def _lti_plant(p, options):
    if "sample_time" in p:              # discrete: x[k+1] = A x[k] + B u[k]
        model = StateSpace.checked(p["A"], p["B"], p["C"], p["D"], dt=float(p["sample_time"]))
        return LTIPlant(model, x0=p["x0"], substep_budget=float(p["substep_budget"]))
    return LTIPlant(p["A"], p["B"], p["C"], p["D"], p["x0"])


@register("luenberger-observer")
def _luenberger(p, options):
    N = p["N"] if "N" in p else _designed_gain(p, options)
    offsets = {key: p[key] for key in ("offset", "output_offset") if key in p}     # a linearised model's
    if "sample_time" in p:              # discrete: the predictor x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u)
        model = StateSpace.checked(p["A"], p["B"], p["C"], p["D"], dt=float(p["sample_time"]))
        return LuenbergerObserver(model, N=N, x_hat0=p["x_hat0"], substep_budget=float(p["substep_budget"]),
                                  **offsets)
    return LuenbergerObserver(p["A"], p["B"], p["C"], N, p["x_hat0"], p["D"], **offsets)


#: the design parameters an observer FMU may carry instead of its gain N (computed at initialisation)
DESIGNS = ("t_settle", "poles", "shift")


def _designed_gain(p, options) -> np.ndarray:
    """N with eig(A - N C) at the poles of the FMU's design parameter (``t_settle`` with the build's ``form``,
    real ``poles``, or ``shift``), as the system file designs it (paper 002, pole placement by duality); a
    choice that is not observable or leaves an unbounded transient raises, naming the parameter."""
    A, C, design = np.atleast_2d(p["A"]), np.atleast_2d(p["C"]), options["design"]
    if design == "shift":
        poles = shifted_poles(A, float(p["shift"]), "shift")
    elif design == "t_settle":
        poles = desired_poles(len(A), t_settle=float(p["t_settle"]), form=options["form"], name="t_settle")
    else:
        poles = desired_poles(len(A), poles=np.ravel(p["poles"]), name="poles")
    N = observer_gain(A, C, poles, design)
    growth = transient_growth(A - N @ C)
    if growth > MAX_TRANSIENT_GROWTH:
        raise ParameterError(f"{design}: eig(A - N C) = {np.round(poles, 6).tolist()} amplifies an initial error "
                             f"up to {growth:.2g} times before it decays (accepted: {MAX_TRANSIENT_GROWTH:g}); "
                             "choose slower poles or poles closer to the plant's own")
    return N


@register("state-feedback")
def _state_feedback(p, options):
    return StateFeedback(p["K"])


@register("integral-state-feedback")
def _integral_state_feedback(p, options):
    return IntegralStateFeedback(p["K"], p["K_i"])


def vector_unit(values):
    """Units of a vector: one string when all entries share it, else the list (or None)."""
    if isinstance(values, str) or not values:
        return values or None
    values = list(values)
    return values[0] if len(set(values)) == 1 else values


def _vector_unit(units: dict, key: str):
    return vector_unit(units.get(key))


def _model_parameters(model: StateSpace) -> list[Parameter]:
    return [
        Parameter.of("A", model.A, "state matrix of x' = A x + B u"),
        Parameter.of("B", model.B, "input matrix of x' = A x + B u", drop_axes=(1,)),
        Parameter.of("C", model.C, "output matrix of y = C x + D u", drop_axes=(0,)),
        Parameter.of("D", model.D, "feedthrough matrix of y = C x + D u", drop_axes=(0, 1)),
    ]


def _signal_ports(model: StateSpace, units: dict) -> tuple[Port, Port]:
    u = Port("u", model.m, "plant input u", _vector_unit(units, "input_units"), scalar=model.m == 1,
             labels=units.get("input_names"))
    y = Port("y", model.p, "measured output y = C x + D u", _vector_unit(units, "output_units"),
             scalar=model.p == 1, labels=units.get("output_names"))
    return u, y


def _timing(model: StateSpace, substep_budget=None) -> list[Parameter]:
    """A discrete model's ``sample_time`` and ``substep_budget`` parameters (none for a continuous one)."""
    if not model.discrete:
        return []
    return [Parameter.scalar("sample_time", model.dt, "sample time T of x[k+1] = A x[k] + B u[k]", "s"),
            Parameter.substep_budget(substep_budget)]


def plant_definition(model_name: str, model: StateSpace, x0, units: dict, description: str,
                     substep_budget=None) -> FmuDefinition:
    """LTI plant FMU: parameters A, B, C, D, x0; input u; outputs y and the true state x.

    A discrete ``model`` (``model.dt > 0``) adds the parameters ``sample_time`` (= ``model.dt``) and
    ``substep_budget``: a step covers whole samples (any other is refused, fmi2Discard), ``u[k]`` the
    input at ``t_k``.  A continuous model's FMU has neither (and is what it always was).
    """
    u, y = _signal_ports(model, units)
    timing = _timing(model, substep_budget)
    law = "x[k+1] = A x[k] + B u[k], y = C x + D u (a step covers whole samples)" if model.discrete else \
        "x' = A x + B u, y = C x + D u (exact step for linear inputs)"
    return FmuDefinition(
        model_name=model_name,
        kind="lti-plant",
        feedthrough=bool(np.any(model.D)),
        description=description or f"LTI plant {law}",
        parameters=_model_parameters(model) + [
            Parameter.of("x0", x0, "initial state x(0)", _vector_unit(units, "state_units")),
        ] + timing,
        inputs=[u],
        outputs=[y, Port("x", model.n, "true state x", _vector_unit(units, "state_units"),
                         labels=units.get("state_names"))],
    )


def _design_parameter(design, N) -> Parameter:
    """The gain ``N`` itself, or the design ``(name, value, form)`` the FMU computes ``N`` from at initialisation."""
    if design is None:
        return Parameter.of("N", N, "observer gain (eig(A - N C) Hurwitz)", drop_axes=(1,))
    name, value, form = design
    if name == "t_settle":
        return Parameter.scalar(name, value, f"settling time of the observer's poles ({form} standard form); "
                                "N is designed from it at initialisation", "s")
    if name == "shift":
        return Parameter.scalar(name, value, "the plant's eigenvalues moved left by shift are the observer's "
                                "poles; N is designed from it at initialisation", "1/s")
    return Parameter.of(name, value, "the observer's poles (real); N is designed from them at initialisation", "1/s")


def observer_definition(model_name: str, model: StateSpace, N, x_hat0, units: dict,
                        description: str, poles, design=None, offsets=None) -> FmuDefinition:
    """Luenberger observer FMU: parameters A, B, C, D, N (or the ``design`` it is computed from at
    initialisation: ``(name, value, form)``, name one of :data:`DESIGNS`), x_hat0; inputs u, y; outputs x_hat, y_hat.
    ``offsets``: ``(c, e)`` of a model linearised at an operating point (:mod:`observers.luenberger`)."""
    u, y = _signal_ports(model, units)
    poles_text = ", ".join(f"{complex(p):.6g}".strip("()").replace("+0j", "") for p in poles)
    return FmuDefinition(
        model_name=model_name,
        kind="luenberger-observer",
        feedthrough=bool(np.any(model.D)),
        options={} if design is None else {"design": design[0], "form": design[2]},
        description=description or ("discrete Luenberger observer x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u)"
                                    if model.discrete else "Luenberger observer x_hat' = A x_hat + B u + N (y - C x_hat "
                                    "- D u)") + f", eig(A - N C) = [{poles_text}]",
        parameters=_model_parameters(model) + [
            _design_parameter(design, N),
            Parameter.of("x_hat0", x_hat0, "initial estimate x_hat(0)", _vector_unit(units, "state_units")),
        ] + _timing(model) + ([] if offsets is None else [
            Parameter.of("offset", offsets[0], "c = f(x_0, u_0) - A x_0 - B u_0 of the model linearised at the "
                         "operating point (x_hat' = A x_hat + B u + N (y - y_hat) + c)"),
            Parameter.of("output_offset", offsets[1], "e = h(x_0, u_0) - C x_0 - D u_0 (y_hat = C x_hat + D u + e)",
                         drop_axes=(0,) if model.p == 1 else ()),
        ]),
        inputs=[u, y],
        outputs=[
            Port("x_hat", model.n, "state estimate x_hat", _vector_unit(units, "state_units"),
                 labels=units.get("state_names")),
            Port("y_hat", model.p, "output estimate C x_hat + D u", _vector_unit(units, "output_units"),
                 scalar=model.p == 1, labels=units.get("output_names")),
        ],
    )


def feedback_definition(model_name: str, K, units: dict, description: str) -> FmuDefinition:
    """State-feedback FMU ``u = -K x_hat + r``."""
    K = np.asarray(K, dtype=float)
    m, n = K.shape
    u_unit = _vector_unit(units, "input_units")
    return FmuDefinition(
        model_name=model_name,
        kind="state-feedback",
        feedthrough=True,
        description=description or "modal state feedback u = -K x_hat + r",
        parameters=[Parameter.of("K", K, "state-feedback gain (eig(A - B K) Hurwitz)", drop_axes=(0,))],
        inputs=[
            Port("x_hat", n, "state estimate", _vector_unit(units, "state_units"), labels=units.get("state_names")),
            Port("r", m, "reference input added to -K x_hat", u_unit, scalar=m == 1, labels=units.get("input_names")),
        ],
        outputs=[Port("u", m, "control u = -K x_hat + r", u_unit, scalar=m == 1, labels=units.get("input_names"))],
    )


def integral_feedback_definition(model_name: str, K, K_i, units: dict, description: str) -> FmuDefinition:
    """State feedback with integral action FMU: ``u = -K x_hat - K_i z``, ``z' = y - r`` (observers.feedback)."""
    K, K_i = np.asarray(K, dtype=float), np.asarray(K_i, dtype=float)
    (m, n), p = K.shape, K_i.shape[1]
    u_unit, y_unit = _vector_unit(units, "input_units"), _vector_unit(units, "output_units")
    return FmuDefinition(
        model_name=model_name,
        kind="integral-state-feedback",
        feedthrough=True,
        description=description or "state feedback with integral action u = -K x_hat - K_i z, z' = y - r",
        parameters=[Parameter.of("K", K, "state-feedback gain", drop_axes=(0,)),
                    Parameter.of("K_i", K_i, "integral gain on z = int (y - r) dt", drop_axes=(0, 1))],
        inputs=[
            Port("x_hat", n, "state estimate", _vector_unit(units, "state_units"), labels=units.get("state_names")),
            Port("y", p, "measured output y", y_unit, scalar=p == 1, labels=units.get("output_names")),
            Port("r", p, "reference of y (tracked without steady-state error)", y_unit, scalar=p == 1,
                 labels=units.get("output_names")),
        ],
        outputs=[Port("u", m, "control u = -K x_hat - K_i z", u_unit, scalar=m == 1, labels=units.get("input_names"))],
    )

