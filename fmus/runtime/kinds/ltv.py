"""Kinds for paper 001: the nonlinear LTV plant and its adaptive observer (LS, DREM or gradient).

The user's model functions ``A(t)``, ``L(t)``, ``f(y)`` (one value or ``p``), and ``C(t)`` when the output
vector varies, are ``"module:function"`` references or
expression functions (:mod:`fmus.runtime.functions`) in the definition's ``options`` (resolved here
with :func:`fmus.runtime.callables.resolve`, never evaluated); everything numeric is an FMU
parameter.  The estimator is the option ``estimator`` (default least squares, the paper's).  The
dimension ``n`` is fixed when the FMU is built; the paper's functions are in :mod:`plants.ltv`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import Names
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET
from obsfmu.observers.ltv import LTVAdaptiveObserver
from obsfmu.observers.ltv.estimators import DELTA_FLOOR, ESTIMATORS, require_exact
from obsfmu.observers.ltv.model import Nonlinearities, OutputVector
from obsfmu.observers.ltv.observer import PARTS
from obsfmu.plants.ltv import OutputNonlinearLTVPlant
from obsfmu.plants.signals import SampledNoise

from ..callables import reference, resolve
from ..definition import FmuDefinition, Parameter, Port
from ..functions import expression_parts, is_expression_function
from . import register
from .diagnostics import LS_CONTRACT, Contract, contract_parameters, contract_ports, contract_values

__all__ = ["ltv_plant_definition", "ltv_observer_definition", "kernel_expressions"]

PLANT_KIND = "ltv-output-nonlinear-plant"
OBSERVER_KIND = "ltv-adaptive-observer"

_BOUNDS = tuple(LS_CONTRACT.parameters[:2])      #: converged_tolerance and theta_bound, as least squares has them

#: the diagnostics contract of each estimator (observers/ltv/estimators.py)
CONTRACTS = {
    "least-squares": LS_CONTRACT,
    "drem": Contract(
        "|Delta| of the row-normalised Kreisselmeier-extended regressor at the last step (0 <= Delta <= 1)",
        "1 once max_i exp(-gamma int Delta^2) |Theta_tilde(0)| <= converged_tolerance (the DREM error identity, "
        "exact regression), else 0",
        _BOUNDS),
    "gradient": Contract(
        "1 - |T|_2, T the transition matrix of the gradient's error: the guaranteed fraction of the initial "
        "error removed so far (0 to 1)",
        "1 once |T|_2 |Theta_tilde(0)| <= converged_tolerance (exact regression), else 0",
        _BOUNDS),
}


def _function(options: dict, key: str) -> Callable:
    if key not in options:
        raise ParameterError(f"{key}: the definition's options lack the 'module:function' reference {key!r}")
    return resolve(options[key], key)


@register(PLANT_KIND)
def _plant(p, options):
    noise = SampledNoise(float(p["noise_std"]), float(p["noise_dt"]), float(p["noise_seed"]))   # checks all three
    return OutputNonlinearLTVPlant(_function(options, "A"), _output(p, options), _function(options, "f"), p["k"], p["b"],
                                   p["m"], p["x0"], noise, float(p["max_substep"]), float(p["max_dy"]),
                                   _degree(p), _budget(p), f_time=_timed(options, "f"))


@register(OBSERVER_KIND)
def _observer(p, options):
    unknowns = _unknowns(options)
    estimator = _estimator(options)
    known = {name: p.get(name) for name in PARTS if name not in unknowns}
    contract = dict(zip(("converged_tolerance", "theta_bound", "regression_error_bound"),
                        contract_values(p, CONTRACTS[estimator])))
    least_squares = {name: float(p[name]) for name in ("beta", "f0", "M") if name in p}
    return LTVAdaptiveObserver(_function(options, "A"), _output(p, options), _function(options, "L"),
                               _function(options, "f"),
                               float(p["gamma"]), x_hat0=p["x_hat0"], k_hat0=p.get("k_hat0"),
                               b_hat0=p.get("b_hat0"), m_hat0=p.get("m_hat0"), max_substep=float(p["max_substep"]),
                               max_dy=float(p["max_dy"]), input_degree=_degree(p), substep_budget=_budget(p),
                               f_correction=_flag(p, "f_correction"), unknowns=unknowns, estimator=estimator,
                               extension_rate=float(p.get("extension_rate", 1.0)), f_time=_timed(options, "f"),
                               delta_floor=float(p.get("delta_floor", DELTA_FLOOR)),
                               **least_squares, **contract, **known)


def kernel_expressions(definition: FmuDefinition):
    """The compiled kernel's functions of the adaptive observer or the plant (``f`` the nonlinearities, ``h``
    ``A(t)``, ``l`` the observer's ``L(t)``, ``c`` a ``C(t)``, ``v`` the plant's measurement noise) and the names of
    each; None when it steps in Python: a function given as a ``module:function`` reference, or an observer's
    estimator other than least squares (observers/ltv/kernel.py)."""
    options = definition.options
    keys = (("f", "f"), ("h", "A")) + ((("l", "L"),) if definition.kind == OBSERVER_KIND else ()) \
        + ((("c", "C"),) if "C" in options else ())
    if (definition.kind == OBSERVER_KIND and _estimator(options) != ESTIMATORS[0]) or \
            not all(is_expression_function(options.get(key)) for _, key in keys):
        return None
    parts = {symbol: expression_parts(options[key], key) for symbol, key in keys}
    if definition.kind == PLANT_KIND:                                        # v(t), the measurement noise
        parts["v"] = ([SampledNoise.expression(1)], Names(p=3))
    return {symbol: part[0] for symbol, part in parts.items()}, {symbol: part[1] for symbol, part in parts.items()}


def _output(p, options: dict):
    """``C``: the parameter, or the function ``C(t)`` of the option ``C`` (then there is no parameter)."""
    return _function(options, "C") if "C" in options else p["C"]


def _sizes(C, f_option) -> tuple[int, int]:
    """``(n, p)``: the state's size (from ``C`` or ``C(t)``) and the number of nonlinearities ``f`` returns."""
    if isinstance(C, (str, dict)):
        C = resolve(C, "C")
    return OutputVector(C).n, Nonlinearities(resolve(f_option, "f"), _timed({"f": f_option}, "f")).count


def _output_parameters(options: dict, C) -> list[Parameter]:
    """``C`` as a parameter, or (a function of time) as the option ``C``."""
    if callable(C) or isinstance(C, (str, dict)):
        options["C"] = _reference(C)
        return []
    return [Parameter.of("C", C, "output vector, y = C^T x")]


def _timed(options: dict, key: str) -> bool:
    """The function option ``key`` is an expression function of ``(t, y)``: called ``f(t, y)``."""
    option = options.get(key)
    return is_expression_function(option) and list(option["arguments"][0]) == ["t", 0]


def _estimator(options: dict) -> str:
    """The option ``estimator`` (default least squares); refused naming the choices."""
    name = options.get("estimator", ESTIMATORS[0])
    if name not in ESTIMATORS:
        raise ParameterError(f"estimator: expected one of {list(ESTIMATORS)}, got {name!r}")
    return name


def _unknowns(options: dict) -> tuple[str, ...]:
    """The option ``unknowns``: names among k, b, m separated by commas ("k,m"); default all three."""
    text = options.get("unknowns", ",".join(PARTS))
    if not isinstance(text, str):
        raise ParameterError(f"unknowns: expected names among {list(PARTS)} separated by commas, got {text!r}")
    return tuple(name.strip() for name in text.split(",") if name.strip())


def _flag(p, name: str) -> bool:
    value = float(p.get(name, 0.0))
    if value not in (0.0, 1.0):
        raise ParameterError(f"{name}: expected 0 or 1, got {value:g}")
    return bool(value)


def _budget(p):
    return p.get("substep_budget", DEFAULT_SUBSTEP_BUDGET)


def _reference(function: Callable | str | dict):
    """A ``"module:function"`` reference or an expression function's option (a dict) as it is; a function
    as its reference."""
    return function if isinstance(function, (str, dict)) else reference(function)


def _shown(option) -> str:
    """A function option in a description: the reference, or the expressions."""
    if isinstance(option, dict):
        texts = option.get("expressions", [])
        return "[" + ", ".join(texts) + "]" if len(texts) > 1 else "".join(texts)
    return str(option)


def _scalar(name, value, description, unit=None) -> Parameter:
    return Parameter.of(name, np.array(value, dtype=float), description, unit)


def _degree(p) -> int:
    degree = float(p["input_degree"])
    if not np.isfinite(degree) or degree != int(degree):
        raise ParameterError(f"input_degree: expected an integer from 1 to 5, got {degree:g}")
    return int(degree)


def _stepping(max_substep: float, max_dy: float, input_degree: int) -> list[Parameter]:
    return [_scalar("max_substep", max_substep, "longest RK4 sub-step inside a communication step", "s"),
            _scalar("max_dy", max_dy, "largest change of y over one RK4 sub-step (resolves f(y))"),
            _scalar("input_degree", input_degree, "degree of the polynomial through the last communication "
                    "points that interpolated inputs follow inside a step (2: parabola)"),
            Parameter.substep_budget()]


def ltv_plant_definition(model_name: str, A, C, f, k, b, m, x0, *, noise_std=0.0, noise_dt=1e-3,
                         noise_seed=0, max_substep=1e-3, max_dy=0.2, input_degree=2,
                         description: str = "") -> FmuDefinition:
    """Plant FMU ``x' = A(t) x + k C^T x + b u + sum_i m_i f_i(y)``, ``y = C^T x + v``.

    ``A``, ``f`` (and ``C`` if it is ``C(t)``) are module-level functions, ``"module:function"``
    references or expression functions; ``C``, ``k``, ``b``, ``x0`` are vectors of length n, ``m`` a
    vector (one nonlinearity) or the ``n x p`` matrix ``[m_1, ..., m_p]``.  Outputs ``y`` (with the
    noise ``v``), the true state ``x`` and the true ``theta = [-x(0); k; b; m_1; ...; m_p]``.  Checked by
    building the block once.
    """
    options = {"A": _reference(A), "f": _reference(f)}
    n, p = _sizes(C, options["f"])
    parameters = _output_parameters(options, C) + [
        Parameter.of("k", k, "unknown output injection k C^T x"),
        Parameter.of("b", b, "unknown input vector b u"),
        Parameter.of("m", m, "unknown gains of the nonlinearities, sum_i m_i f_i(y) (column i: m_i)"),
        Parameter.of("x0", x0, "unknown initial state x(0)"),
        _scalar("noise_std", noise_std, "standard deviation of the measurement noise on y (0: none)"),
        _scalar("noise_dt", noise_dt, "hold interval of the measurement noise", "s"),
        _scalar("noise_seed", noise_seed, "seed of the measurement noise (a non-negative integer)"),
    ] + _stepping(max_substep, max_dy, input_degree)
    definition = FmuDefinition(
        model_name=model_name, kind=PLANT_KIND, options=options,
        description=description or (f"paper 001 plant x' = A(t) x + k C^T x + b u + m f(y), y = C^T x + noise; "
                                    f"A = {_shown(options['A'])}, f = {_shown(options['f'])}"),
        parameters=parameters,
        inputs=[Port("u", 1, "plant input u", scalar=True)],
        outputs=[Port("y", 1, "measured output y = C^T x (+ noise)", scalar=True),
                 Port("x", n, "true state x"),
                 Port("theta", (3 + p) * n,
                      "true Theta = [-x(0); k; b; m] of regression (7), to compare with theta_hat"
                      + ("" if p == 1 else " (m: its columns m_1, ..., m_p one after another)"))],
    )
    _check(definition)
    return definition


def ltv_observer_definition(model_name: str, A, C, L, f, *, gamma=1000.0, beta=1.0, f0=0.1, M=1e12,
                            x_hat0=None, k_hat0=None, b_hat0=None, m_hat0=None, max_substep=1e-3,
                            max_dy=0.2, input_degree=2, f_correction=0, converged_tolerance=1e-3, theta_bound=100.0,
                            regression_error_bound=0.0, unknowns=PARTS, known: dict | None = None,
                            estimator: str = "least-squares", extension_rate=1.0, delta_floor=DELTA_FLOOR,
                            description: str = "") -> FmuDefinition:
    """Adaptive observer FMU of paper 001 (filters (2)-(6), regression (7), LS with forgetting, (10)).

    ``A``, ``L``, ``f`` are module-level functions or ``"module:function"`` references; ``C`` is
    the output vector (length n).  ``unknowns``: which of ``k``, ``b``, ``m`` are estimated (with
    ``x(0)``); the others are parameters with the values ``known[name]`` (vectors of n), and
    ``theta_hat`` holds ``[-x(0); unknowns]`` only.  ``estimator``: ``"least-squares"`` (parameters
    ``gamma``, ``beta``, ``f0``, ``M``; output ``F_max``), ``"drem"`` (``gamma``, ``extension_rate``,
    ``delta_floor``) or
    ``"gradient"`` (``gamma``).  Checked by building the block once.
    """
    unknowns = tuple(unknowns)
    known = dict(known or {})
    options = {"A": _reference(A), "L": _reference(L), "f": _reference(f)}
    n, p = _sizes(C, options["f"])
    sizes = {"x": n, "k": n, "b": n, "m": n * p}
    zeros = {"x": np.zeros(n), "k": np.zeros(n), "b": np.zeros(n), "m": np.zeros((n, p) if p > 1 else n)}
    if unknowns != PARTS:
        options["unknowns"] = ",".join(unknowns)
    if estimator != ESTIMATORS[0]:
        options["estimator"] = estimator
    contract = CONTRACTS[_estimator({"estimator": estimator})]
    require_exact(estimator, float(regression_error_bound))
    starts = {"k": k_hat0, "b": b_hat0, "m": m_hat0}
    estimates = [("x_hat0", x_hat0, "initial estimate of x(0) (= x_hat(0))")] \
        + [(f"{name}_hat0", starts[name], f"initial estimate of {name}") for name in PARTS if name in unknowns]
    for name in PARTS:
        if name in unknowns and name in known:
            raise ParameterError(f"{name}: {name} is in unknowns; it cannot also be known")
        if name not in unknowns and starts[name] is not None:
            raise ParameterError(f"{name}_hat0: {name} is known (not in unknowns); it has no estimate")
    values = [Parameter.of(name, known[name], f"known {name} (not estimated)") for name in PARTS
              if name not in unknowns and name in known]
    parameters = _output_parameters(options, C) + values + [
        _scalar("gamma", gamma, f"adaptation gain of the {estimator} estimator"),
    ] + _estimator_parameters(estimator, beta, f0, M, extension_rate, delta_floor) \
      + [Parameter.of(name, zeros[name[0]] if value is None else value, text)
         for name, value, text in estimates] \
      + _stepping(max_substep, max_dy, input_degree) \
      + [_scalar("f_correction", f_correction, "1: inside a step y follows the polynomial of y - C^T m_hat "
                 "int f(y) plus that fast part (for outputs f(y) makes oscillate between samples); "
                 "0: the polynomial of y")] \
      + contract_parameters(contract, converged_tolerance=converged_tolerance, theta_bound=theta_bound,
                            regression_error_bound=regression_error_bound)
    definition = FmuDefinition(
        model_name=model_name, kind=OBSERVER_KIND, options=options,
        description=description or (f"paper 001 adaptive observer: filters (2)-(6), regression (7), {estimator} "
                                    f"estimator, estimate (10); A = {_shown(options['A'])}, "
                                    f"L = {_shown(options['L'])}, f = {_shown(options['f'])}"),
        parameters=parameters,
        inputs=[Port("u", 1, "plant input u", scalar=True), Port("y", 1, "measured output y", scalar=True)],
        outputs=[Port("x_hat", n, "state estimate x_hat (10)"),
                 Port("theta_hat", n + sum(sizes[name] for name in unknowns),
                      f"estimate of Theta = [-x(0); {'; '.join(unknowns)}]" if unknowns else "estimate of Theta = -x(0)"),
                 Port("k_hat", n, "estimate of k"), Port("b_hat", n, "estimate of b"),
                 Port("m_hat", n * p, "estimate of m" if p == 1 else "estimate of m: its columns m_1, ..., m_p"),
                 Port("x0_hat", n, "estimate of x(0)")]
                + ([Port("F_max", 1, "largest eigenvalue of the estimator gain F (bounded by M)", scalar=True)]
                   if estimator == ESTIMATORS[0] else [])
                + contract_ports(contract),
    )
    _check(definition)
    return definition


def _estimator_parameters(estimator: str, beta, f0, M, extension_rate, delta_floor) -> list[Parameter]:
    if estimator == "least-squares":
        return [_scalar("beta", beta, "forgetting factor", "1/s"), _scalar("f0", f0, "F(0) = I / f0"),
                _scalar("M", M, "bound on the largest eigenvalue of F")]
    if estimator == "drem":
        return [_scalar("extension_rate", extension_rate, "rate a of the Kreisselmeier extension "
                        "Phi_e' = -a Phi_e + Psi^T Psi", "1/s"),
                _scalar("delta_floor", delta_floor, "normalised gain gamma / (delta_floor^2 + Delta^2) of the scalar "
                        "laws (0: the raw gain gamma)")]
    return []


def _check(definition: FmuDefinition) -> None:
    """Build the block once so that every mistake is reported before an FMU is built."""
    from . import create_block
    create_block(definition.kind, {p.name: p.array(p.value) for p in definition.parameters}, definition.options)
