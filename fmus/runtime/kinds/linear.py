"""Kinds for linear models (paper 002): LTI plant, Luenberger observer, state feedback.

Each kind has a factory (FMU parameters -> block) and a definition function
(design-time data -> :class:`~fmus.runtime.definition.FmuDefinition`).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.feedback import IntegralStateFeedback, StateFeedback, integral_augmented
from obsfmu.observers.lti_model import StateSpace
from obsfmu.observers.luenberger import LuenbergerObserver
from obsfmu.observers.modal import (MAX_TRANSIENT_GROWTH, desired_poles, observer_gain, place, shifted_poles,
                                   transient_growth)
from obsfmu.observers.riccati import checked_weight, dkalman_newton, kalman_newton, lqr_newton
from obsfmu.observers.standard_forms import butterworth_settling
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


#: the design parameters an observer or state-feedback FMU may carry instead of its gain (computed at initialisation)
DESIGNS = ("t_settle", "poles", "shift")


def _designed_gain(p, options) -> np.ndarray:
    """N with eig(A - N C) at the poles of the FMU's design parameter (paper 002, pole placement by duality), or
    the steady-state Kalman gain of its ``Q`` and ``R`` (continuous, or the sampled predictor's)."""
    A, C = np.atleast_2d(p["A"]), np.atleast_2d(p["C"])
    if options["design"] == "kalman":
        Q, R = _weights(p, len(A), len(C), "covariance")
        newton = dkalman_newton if "sample_time" in p else kalman_newton
        return newton(A, C, Q, R, np.asarray(options["initial_gain"]))
    N = _placed(A, p, options, lambda poles, name: observer_gain(A, C, poles, name),
                lambda N: A - N @ C, "A - N C")
    return N


def _designed_feedback(A, B, p, options) -> np.ndarray:
    """K with eig(A - B K) at the poles of the FMU's design parameter, or the LQR gain of its ``Q`` and ``R``
    (``A``, ``B`` of the plant, or of the plant augmented with the integrators of its output error)."""
    if options["design"] == "lqr":
        Q, R = _weights(p, len(A), B.shape[1], "weight")
        return lqr_newton(A, B, Q, R, np.asarray(options["initial_gain"]))
    return _placed(A, p, options, lambda poles, name: place(A, B, poles, name), lambda K: A - B @ K, "A - B K")


def _weights(p, n: int, m: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    """The FMU's ``Q`` (n x n) and ``R`` (m x m), checked symmetric and positive (semi)definite."""
    state = "state weight" if what == "weight" else what
    return (checked_weight("Q", np.reshape(p["Q"], (n, n)), n, definite=False, what=state),
            checked_weight("R", np.reshape(p["R"], (m, m)), m, definite=True,
                           what="input weight" if what == "weight" else what))


def _placed(A, p, options, designer, closed_loop, loop_text: str) -> np.ndarray:
    """The gain ``designer(poles, name)`` for the poles of the FMU's design parameter (``t_settle`` with the
    build's ``form``, real ``poles``, or ``shift``), as the system file designs it; a choice that cannot be
    placed (not observable/controllable) or leaves an unbounded transient raises, naming the parameter."""
    design = options["design"]
    if design == "shift":
        poles = shifted_poles(A, float(p["shift"]), "shift")
    elif design == "t_settle":
        poles = desired_poles(len(A), t_settle=float(p["t_settle"]), form=options["form"], name="t_settle",
                              normalised=options.get("settling"))
    else:
        poles = desired_poles(len(A), poles=np.ravel(p["poles"]), name="poles")
    gain = designer(poles, design)
    growth = transient_growth(closed_loop(gain))
    if growth > MAX_TRANSIENT_GROWTH:
        raise ParameterError(f"{design}: eig({loop_text}) = {np.round(poles, 6).tolist()} amplifies an initial error "
                             f"up to {growth:.2g} times before it decays (accepted: {MAX_TRANSIENT_GROWTH:g}); "
                             "choose slower poles or poles closer to the plant's own")
    return gain


def _model_matrices(p) -> tuple[np.ndarray, np.ndarray]:
    A = np.atleast_2d(np.asarray(p["A"], dtype=float))
    return A, np.asarray(p["B"], dtype=float).reshape(len(A), -1)


@register("state-feedback")
def _state_feedback(p, options):
    if "K" in p:
        return StateFeedback(p["K"])
    return StateFeedback(_designed_feedback(*_model_matrices(p), p, options))


@register("integral-state-feedback")
def _integral_state_feedback(p, options):
    if "K" in p:
        return IntegralStateFeedback(p["K"], p["K_i"])
    A, B = _model_matrices(p)
    K = _designed_feedback(*integral_augmented(A, B, p["C"]), p, options)
    return IntegralStateFeedback(K[:, :len(A)], K[:, len(A):])


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


#: designs whose parameters are the Riccati equation's weights Q and R (the build's gain starts Newton's iteration)
RICCATI = ("kalman", "lqr")


def _design_parameters(design, gain: Parameter, whose: str, designed: str = "") -> list[Parameter]:
    """The ``gain`` itself, or the design the FMU computes it (or ``designed``) from at initialisation: ``(name,
    value, form)`` of poles (``whose``: "the observer's" or "the closed loop's" poles), or ``(name, (Q, R), G0)``
    of a Riccati design."""
    if design is None:
        return [gain]
    name, value, form = design
    computed = f"{designed or gain.name} is designed from {'them' if name in ('poles', *RICCATI) else 'it'} at " \
               "initialisation"
    if name == "kalman":
        return [Parameter.of("Q", value[0], f"process noise covariance (entering every state); {computed}"),
                Parameter.of("R", value[1], f"measurement noise covariance; {computed}")]
    if name == "lqr":
        return [Parameter.of("Q", value[0], f"LQR state weight; {computed}"),
                Parameter.of("R", value[1], f"LQR input weight; {computed}")]
    if name == "t_settle":
        return [Parameter.scalar(name, value, f"settling time of {whose} poles ({form} standard form); {computed}",
                                 "s")]
    if name == "shift":
        return [Parameter.scalar(name, value, f"the plant's eigenvalues moved left by shift are {whose} poles; "
                                 f"{computed}", "1/s")]
    return [Parameter.of(name, value, f"{whose} poles (real); {computed}", "1/s")]


def _design_options(design, order: int) -> dict:
    """What the FMU's design needs besides its parameters: the Riccati iteration's start (the build's gain), the
    standard form of ``t_settle`` and the Butterworth form's settling time at radius 1 for the loop's ``order``
    (scipy computes it; an FMU has none)."""
    if design is None:
        return {}
    if design[0] in RICCATI:
        return {"design": design[0], "initial_gain": np.asarray(design[2], dtype=float).tolist()}
    options = {"design": design[0], "form": design[2]}
    if design[0] == "t_settle" and design[2] == "butterworth":
        options["settling"] = butterworth_settling(order)
    return options


def observer_definition(model_name: str, model: StateSpace, N, x_hat0, units: dict,
                        description: str, poles, design=None, offsets=None) -> FmuDefinition:
    """Luenberger observer FMU: parameters A, B, C, D, N (or the ``design`` it is computed from at
    initialisation: ``(name, value, form)``, name one of :data:`DESIGNS`, or ``("kalman", (Q, R), N0)``), x_hat0;
    inputs u, y; outputs x_hat, y_hat.
    ``offsets``: ``(c, e)`` of a model linearised at an operating point (:mod:`observers.luenberger`)."""
    u, y = _signal_ports(model, units)
    poles_text = ", ".join(f"{complex(p):.6g}".strip("()").replace("+0j", "") for p in poles)
    return FmuDefinition(
        model_name=model_name,
        kind="luenberger-observer",
        feedthrough=bool(np.any(model.D)),
        options=_design_options(design, model.n),
        description=description or ("discrete Luenberger observer x_hat[k+1] = A x_hat + B u + N (y - C x_hat - D u)"
                                    if model.discrete else "Luenberger observer x_hat' = A x_hat + B u + N (y - C x_hat "
                                    "- D u)") + f", eig(A - N C) = [{poles_text}]",
        parameters=_model_parameters(model) + [
            *_design_parameters(design, Parameter.of("N", N, "observer gain (eig(A - N C) Hurwitz)",
                                                     drop_axes=(1,)), "the observer's"),
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


def _design_model(model: StateSpace | None, design, with_C: bool = False) -> list[Parameter]:
    """The plant's A, B (and C) a state-feedback FMU designs its gain from at initialisation (none without a
    ``design``)."""
    return [] if design is None else _model_parameters(model)[:3 if with_C else 2]


def feedback_definition(model_name: str, K, units: dict, description: str, design=None,
                        model: StateSpace | None = None) -> FmuDefinition:
    """State-feedback FMU ``u = -K x_hat + r``: parameter K, or (with a ``design`` ``(name, value, form)``) the
    plant ``model``'s A, B and the design it computes K from at initialisation."""
    K = np.asarray(K, dtype=float)
    m, n = K.shape
    u_unit = _vector_unit(units, "input_units")
    return FmuDefinition(
        model_name=model_name,
        kind="state-feedback",
        feedthrough=True,
        options=_design_options(design, n),
        description=description or "modal state feedback u = -K x_hat + r",
        parameters=_design_model(model, design) + _design_parameters(
            design, Parameter.of("K", K, "state-feedback gain (eig(A - B K) Hurwitz)", drop_axes=(0,)),
            "the closed loop's"),
        inputs=[
            Port("x_hat", n, "state estimate", _vector_unit(units, "state_units"), labels=units.get("state_names")),
            Port("r", m, "reference input added to -K x_hat", u_unit, scalar=m == 1, labels=units.get("input_names")),
        ],
        outputs=[Port("u", m, "control u = -K x_hat + r", u_unit, scalar=m == 1, labels=units.get("input_names"))],
    )


def integral_feedback_definition(model_name: str, K, K_i, units: dict, description: str, design=None,
                                 model: StateSpace | None = None) -> FmuDefinition:
    """State feedback with integral action FMU: ``u = -K x_hat - K_i z``, ``z' = y - r`` (observers.feedback):
    parameters K and K_i, or (with a ``design``) the plant ``model``'s A, B, C and the design of the augmented
    loop ``[K, K_i]`` is computed from at initialisation."""
    K, K_i = np.asarray(K, dtype=float), np.asarray(K_i, dtype=float)
    (m, n), p = K.shape, K_i.shape[1]
    u_unit, y_unit = _vector_unit(units, "input_units"), _vector_unit(units, "output_units")
    gains = [Parameter.of("K", K, "state-feedback gain", drop_axes=(0,)),
             Parameter.of("K_i", K_i, "integral gain on z = int (y - r) dt", drop_axes=(0, 1))]
    if design is not None:
        gains = _design_parameters(design, gains[0], "the augmented closed loop's", "[K, K_i]")
    return FmuDefinition(
        model_name=model_name,
        kind="integral-state-feedback",
        feedthrough=True,
        options=_design_options(design, n + p),
        description=description or "state feedback with integral action u = -K x_hat - K_i z, z' = y - r",
        parameters=_design_model(model, design, with_C=True) + gains,
        inputs=[
            Port("x_hat", n, "state estimate", _vector_unit(units, "state_units"), labels=units.get("state_names")),
            Port("y", p, "measured output y", y_unit, scalar=p == 1, labels=units.get("output_names")),
            Port("r", p, "reference of y (tracked without steady-state error)", y_unit, scalar=p == 1,
                 labels=units.get("output_names")),
        ],
        outputs=[Port("u", m, "control u = -K x_hat - K_i z", u_unit, scalar=m == 1, labels=units.get("input_names"))],
    )
