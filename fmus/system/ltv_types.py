"""Component types ``ltv-plant`` and ``ltv-adaptive-observer`` of a system file (paper 001).

The plant class of paper 001, ``x' = A(t) x + k C^T(t) x + b u + sum_i m_i f_i(y, t)``, ``y = C^T(t) x``:
``A(t)``, ``L(t)`` and ``C(t)`` are expressions of ``t`` (``C`` numbers when it is constant), ``f`` one
expression of ``y`` and ``t`` or a list of ``p`` of them, with ``m`` then the ``n x p`` matrix
``[m_1, ..., m_p]``.  Every assumption that can be checked numerically is checked before anything is
built (:mod:`observers.ltv.assumptions`): the dimensions; ``(A0(t), C^T(t))`` observable and
``A0(t) = A(t) - L(t) C^T(t)`` stable at 200 points of ``[0, stop_time]`` -- exactly if ``A0`` and ``C``
are constant, else frozen-time tests, which are only a necessary condition; the unknowns among ``k``,
``b``, ``m`` and the known values of the others.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.ltv.assumptions import require_assumptions
from obsfmu.observers.ltv.estimators import DELTA_FLOOR, ESTIMATORS
from obsfmu.observers.ltv.model import gain_matrix
from obsfmu.observers.ltv.observer import PARTS

from ..caches import remembered
from ..runtime.callables import resolve
from ..runtime.functions import compiled, expression_function
from ..runtime.kinds.ltv import ltv_observer_definition, ltv_plant_definition
from .inmemory import CHECK_FIELD, block_of, check_key, component_block, drive, refuse_or_warn
from .schema import Context, Field, register

__all__ = ["GRID_POINTS"]

GRID_POINTS = 200          #: the points of [0, stop_time] at which A0(t) and (A0(t), C^T) are checked
_DEFAULT_HORIZON = 10.0    #: the grid's end when the experiment gives no stop time

_MODEL = (
    Field("A", "expression-matrix", "A(t): n x n expressions of the time t (or numbers)", unit="1/s",
          example='[["2 - sin(t)", 1], ["-8 + cos(t)", 0]]'),
    Field("C", "expression-vector", "output vector, y = C^T x: n numbers, or n expressions of t for a "
          "time-varying C(t)", example='[1, 0] or ["1", "0.5 sin(t)"]'),
    Field("f", "expression-or-vector", "the known nonlinearity f(y, t) of m f(y, t) (an expression of y and t), or a "
          "list of p of them: w = sum_i m_i f_i(y, t)", "0", example='"sin(y)" or ["sin(y)", "y^3"]'),
    Field("constants", "table", "named constants the expressions may use", None, example="{ w = 2.0 }"),
)
_STEPPING = (
    Field("max_substep", "number", "longest RK4 sub-step inside a communication step", 1e-3, "s", "5e-3"),
    Field("max_dy", "number", "largest change of y over one RK4 sub-step (resolves f(y))", 0.2, "(y)", "0.1"),
    Field("input_degree", "integer", "degree of the polynomial through the last communication points that "
          "interpolated inputs follow inside a step (1 to 5; with noisy samples 1 or 2)", 2, example="3"),
)


def _vector(values: dict, name: str, n: int, prefix: str, default=None, p: int = 1):
    """The field ``name``: a vector of ``n`` (``m``, ``m_hat0``: the ``n x p`` gains), or ``default`` if absent."""
    value = values[name]
    if value is None:
        return default
    if name.startswith("m") and (p > 1 or np.ndim(value) == 2):
        return gain_matrix(prefix + name, value, n, p).tolist()
    if np.ndim(value) != 1 or np.size(value) != n:
        raise ParameterError(f"{prefix}{name}: expected {n} entries (n = the entries of C), got shape {np.shape(value)}")
    return list(map(float, value))


def _output_vector(values: dict, prefix: str):
    """``C``: n numbers (constant), or the expression function ``C(t)`` if an entry is a text."""
    C = values["C"]
    if any(isinstance(entry, str) for entry in C):
        return expression_function(C, (("t", 0),), (len(C),), constants=values["constants"] or {}, field=prefix + "C")
    if not any(C):
        raise ParameterError(f"{prefix}C: the output vector is zero; y = C^T x would measure nothing")
    return [float(v) for v in C]


def _functions(values: dict, n: int, prefix: str, names=("A", "f")) -> dict:
    """The expression functions of ``names`` (A(t): n x n, L(t): n, f(y, t): one value or p), each checked as it
    compiles.

    ``f`` is a function of ``(t, y)`` only if a text reads ``t`` (else of ``y``: the kinds then call it
    ``f(y)``, and ``f_correction`` applies)."""
    constants = values["constants"] or {}
    f_shape = (len(values["f"]),) if isinstance(values["f"], list) else ()
    shapes = {"A": ((("t", 0),), (n, n)), "L": ((("t", 0),), (n,)), "f": ((("t", 0), ("y", 0)), f_shape)}
    found = {name: expression_function(values[name], shapes[name][0], shapes[name][1], constants=constants,
                                       field=prefix + name) for name in names}
    if "t" not in compiled(found["f"]).vector.uses:
        found["f"] = expression_function(values["f"], (("y", 0),), f_shape, constants=constants, field=prefix + "f")
    return found


def _count(values: dict) -> int:
    """``p``: the number of nonlinearities in ``f``."""
    return len(values["f"]) if isinstance(values["f"], list) else 1


def _define_plant(model_name: str, values: dict, context: Context) -> list:
    prefix = context.prefix
    C = _output_vector(values, prefix)
    n, p = len(values["C"]), _count(values)
    functions = _functions(values, n, prefix)
    zeros = {name: [0.0] * n if name != "m" or p == 1 else np.zeros((n, p)).tolist() for name in (*PARTS, "x0")}
    parts = {name: _vector(values, name, n, prefix, zeros[name], p) for name in (*PARTS, "x0")}
    return [ltv_plant_definition(model_name, functions["A"], C, functions["f"], **parts,
                                 noise_std=values["noise_std"], noise_dt=values["noise_dt"],
                                 noise_seed=values["noise_seed"], max_substep=values["max_substep"],
                                 max_dy=values["max_dy"], input_degree=values["input_degree"],
                                 description=values["description"])]


register("ltv-plant", "Plant of paper 001: `x' = A(t) x + k C^T(t) x + b u + sum_i m_i f_i(y, t)`, `y = C^T(t) x + v` "
         "(v: measurement noise, held over `noise_dt`). Input `u`; outputs `y`, the true state `x` and the true "
         "`theta = [-x(0); k; b; m_1; ...; m_p]` (to compare with an observer's `theta_hat` when all of k, b, m are "
         "unknown).", _MODEL + (
             Field("k", "vector", "the output injection k of k C^T x (absent: zero)", None, example="[-1, 3]"),
             Field("b", "vector", "the input vector b of b u (absent: zero)", None, example="[1, 2]"),
             Field("m", "vector-or-matrix", "the gain m of m f(y) (absent: zero); with p nonlinearities the n x p "
                   "matrix [m_1, ..., m_p] (row i: state i)", None, example="[-4, 4] or [[-4, 1], [4, 0]]"),
             Field("x0", "vector", "initial state x(0) (absent: zero)", None, example="[-3, -2]"),
             Field("noise_std", "number", "standard deviation of the Gaussian measurement noise v on y (0: none)",
                   0.0, "(y)", "0.01"),
             Field("noise_dt", "number", "hold interval of the measurement noise", 1e-3, "s", "1e-3"),
             Field("noise_seed", "integer", "seed of the measurement noise (>= 0)", 0, example="7"),
         ) + _STEPPING, _define_plant)


def _unknowns(values: dict, prefix: str) -> tuple[str, ...]:
    names = [name.strip() for name in values["unknowns"].split(",") if name.strip()]
    wrong = [name for name in names if name not in PARTS]
    if wrong or len(set(names)) != len(names):
        raise ParameterError(f"{prefix}unknowns: expected distinct names among k, b, m separated by commas (x(0) is "
                             f"always estimated; no other unknown fits paper 001's regression (7)), got "
                             f"{values['unknowns']!r}")
    return tuple(name for name in PARTS if name in names)


#: points (y, t) at which the terms of the unknowns are compared (seeded: the same verdict every build)
_SAMPLES = 64


def _require_separable(f, unknowns, p: int, prefix: str, stop_time: float) -> None:
    """The unknowns' terms of regression (7) are not linearly dependent as functions of ``(y, t)``: ``k`` enters
    through ``y``, ``m_i`` through ``f_i(y, t)``; if one is a combination of the others (``f = "y"`` with ``k`` and
    ``m`` unknown), their columns of the regressor coincide whatever the excitation, the estimates never move
    and nothing said why (issue 36).  Checked at seeded random points of ``y`` in [-3, 3] and ``t`` in
    [0, stop_time]; ``u`` (the term of ``b``) is the plant's input, independent of them."""
    if "m" not in unknowns:
        return
    rng = np.random.default_rng(36)
    ys, ts = rng.uniform(-3.0, 3.0, _SAMPLES), rng.uniform(0.0, stop_time, _SAMPLES)
    function, timed = resolve(f), "t" in compiled(f).vector.uses
    with np.errstate(all="ignore"):
        values = np.array([np.atleast_1d(function(t, y) if timed else function(y)) for y, t in zip(ys, ts)],
                          dtype=float).reshape(_SAMPLES, p)
    names = (["k (its term k y)"] if "k" in unknowns else []) + \
        [f"m (its term m f(y{', t' if timed else ''}))" if p == 1 else f"m_{i} (the column of f[{i}])"
         for i in range(1, p + 1)]
    columns = np.column_stack(([ys] if "k" in unknowns else []) + [values[:, i] for i in range(p)])
    usable = np.all(np.isfinite(columns), axis=1)
    columns = columns[usable]
    if len(columns) < columns.shape[1] + 2:
        return                                       # f is not finite where it was sampled: refused elsewhere
    scaled = columns / np.maximum(np.linalg.norm(columns, axis=0), 1e-300)
    for j in range(scaled.shape[1]):
        earlier = scaled[:, :j]
        if not np.linalg.norm(scaled[:, j]) > 1e-12:
            raise ParameterError(f"{prefix}unknowns: {names[j]} multiplies a term that is zero for every y; it "
                                 "cannot be identified (regression (7) needs independent columns)")
        if j and np.linalg.norm(scaled[:, j] - earlier @ np.linalg.lstsq(earlier, scaled[:, j], rcond=None)[0]) \
                < 1e-9:
            coefficients = np.linalg.lstsq(earlier, scaled[:, j], rcond=None)[0]
            partners = [names[i] for i in range(j) if abs(coefficients[i]) > 1e-9]
            raise ParameterError(
                f"{prefix}unknowns: {names[j]} cannot be separated from {' and '.join(partners)}: its term is a "
                f"linear combination of theirs for every y, so their columns of regression (7) coincide whatever "
                f"the excitation (the estimates would never move); drop one from unknowns or give it as known, or "
                f"change f")


def _known(values: dict, unknowns, n: int, prefix: str, p: int) -> dict:
    """The values of the known parts; a value for an unknown part, or a known part without one, refused."""
    known = {}
    for name in PARTS:
        given = values[name] is not None
        if name in unknowns and given:
            raise ParameterError(f"{prefix}{name}: {name} is in unknowns (estimated); give no value, or remove it from "
                                 "unknowns")
        if name not in unknowns:
            if not given:
                raise ParameterError(f"{prefix}{name}: {name} is known (not in unknowns); its value is required (zeros "
                                     "if the plant has none)")
            known[name] = _vector(values, name, n, prefix, p=p)
        if name not in unknowns and values[f"{name}_hat0"] is not None:
            raise ParameterError(f"{prefix}{name}_hat0: {name} is known (not in unknowns); it has no estimate")
    return known


def _grid(context: Context) -> np.ndarray:
    return np.linspace(0.0, context.stop_time or _DEFAULT_HORIZON, GRID_POINTS)


def _define_observer(model_name: str, values: dict, context: Context) -> list:
    prefix = context.prefix
    C = _output_vector(values, prefix)
    n, p = len(values["C"]), _count(values)
    functions = _functions(values, n, prefix, ("A", "L", "f"))
    unknowns = _unknowns(values, prefix)
    known = _known(values, unknowns, n, prefix, p)
    test = require_assumptions(resolve(functions["A"]), resolve(functions["L"]),
                               resolve(C) if isinstance(C, dict) else np.array(C), _grid(context))
    context.notes.append(f"{prefix.rstrip('.')}: A0(t) = A(t) - L(t) C^T "
                         + ("constant, uniformly stable" if test == "constant" else
                            f"stable at {GRID_POINTS} frozen times of [0, {_grid(context)[-1]:g}] (necessary only)"))
    if test == "constant":                    # the filters' rates: the converged flag's step range (load.py)
        A0 = resolve(functions["A"])(0.0) - np.outer(resolve(functions["L"])(0.0),
                                                      resolve(C)(0.0) if isinstance(C, dict) else np.array(C))
        context.rate(np.linalg.eigvals(A0), "eig(A0) = eig(A - L C^T)")
    _require_separable(functions["f"], unknowns, p, prefix, context.stop_time or 1.0)
    starts = {f"{name}_hat0": _vector(values, f"{name}_hat0", n, prefix, p=p) for name in ("x", *unknowns)}
    definition = ltv_observer_definition(
        model_name, functions["A"], C, functions["L"], functions["f"], gamma=values["gamma"], beta=values["beta"],
        f0=values["f0"], M=values["M"], **starts, max_substep=values["max_substep"], max_dy=values["max_dy"],
        input_degree=values["input_degree"], f_correction=float(values["f_correction"]),
        converged_tolerance=values["converged_tolerance"], theta_bound=values["theta_bound"],
        regression_error_bound=values["regression_error_bound"], unknowns=unknowns, known=known,
        estimator=values["estimator"], extension_rate=values["extension_rate"], delta_floor=values["delta_floor"],
        description=values["description"])
    _check_identified(definition, unknowns, n, p, values, context)
    return [definition]


# ------------------------------------------------------------------ the file's experiment, in memory
#: the code the verdict depends on (its sources are part of the cache key)
_CHECK_SOURCES = ("observers/ltv", "observers/estimation", "observers/integrators.py", "plants/ltv.py",
                  "plants/signals.py", "fmus/system/ltv_types.py", "fmus/system/inmemory.py")


def _check_identified(definition, unknowns, n: int, p: int, values: dict, context: Context) -> None:
    """With ``plant`` and ``input`` named, the observer is run on them in memory along the file's experiment;
    if its estimate of ``Theta`` is not within ``converged_tolerance`` of the plant's at the end, the file is
    refused naming the entries least identified (or, ``check = false``, built with the finding logged)."""
    where = context.prefix.rstrip(".")
    names = values["plant"], values["input"]
    if None in names or context.stop_time is None or context.step is None:
        context.notes.append(f"{where}: identification not checked (name the file's ltv-plant and the source driving "
                             "it in plant and input to check it before the build)")
        return
    for field, name in zip(("plant", "input"), names):
        if name not in context.others:
            raise ParameterError(f"{context.prefix}{field}: {name!r} is not a component defined before this one")
    if context.others[names[0]][0] != "ltv-plant":
        raise ParameterError(f"{context.prefix}plant: {names[0]!r} is a component of kind "
                             f"{context.others[names[0]][0]!r}; the check runs an ltv-plant")
    inputs = {"observer": definition.to_json(), "plant": context.others[names[0]], "input": context.others[names[1]],
              "stop_time": context.stop_time, "step": context.step}
    finding = remembered("checks", check_key(inputs, _CHECK_SOURCES), lambda: _identification_problem(
        definition, unknowns, n, p, values, context))
    refuse_or_warn(finding, values, context, definition)


def _identification_problem(definition, unknowns, n: int, p: int, values: dict, context: Context):
    """``(field, message)`` when the in-memory run ends with ``|Theta_hat - Theta|_2 > converged_tolerance``."""
    plant_name, source_name = values["plant"], values["input"]
    source = component_block(source_name, context)
    if source.input_sizes or source.output_sizes.get("y") != 1:
        raise ParameterError(f"{context.prefix}input: {source_name!r} is not a source with no input and one output y")
    plant = component_block(plant_name, context)
    truth, estimate, excitation = drive(source, plant, block_of(definition), context.stop_time, context.step)
    theta = truth["theta"]
    parts = {"x(0)": (-theta[:n], estimate["x0_hat"]), "k": (theta[n:2 * n], estimate["k_hat"]),
             "b": (theta[2 * n:3 * n], estimate["b_hat"]), "m": (theta[3 * n:], estimate["m_hat"])}
    labels, errors = [], []
    for part in ("x(0)", *unknowns):
        true, found = parts[part]
        labels += [f"{part}[{i + 1}]" for i in range(true.size)]
        errors += list(np.abs(found - true))
    errors = np.array(errors)
    total, tolerance = float(np.linalg.norm(errors)), values["converged_tolerance"]
    if total <= tolerance:
        return None
    worst = [f"{labels[j]} (off by {errors[j]:.2g})" for j in np.argsort(-errors) if errors[j] > 0.1 * errors.max()]
    return "input", (f"in the file's experiment ({source_name!r} driving {plant_name!r}, {context.stop_time:g} s at a "
                     f"step of {context.step:g} s) the observer does not identify Theta = [-x(0); {'; '.join(unknowns)}]: "
                     f"|Theta_hat - Theta|_2 = {total:.2g} > converged_tolerance = {tolerance:g} at the end, least "
                     f"identified {', '.join(worst[:6])}; the excitation reached {excitation:.1e} "
                     f"({values['estimator']}): regression (7) needs an input and nonlinearities that excite every "
                     "unknown (more frequencies, a longer run, a larger gamma)")


register("ltv-adaptive-observer", "Adaptive observer of paper 001 for a plant `x' = A(t) x + k C^T(t) x + b u + "
         "sum_i m_i f_i(y, t)`, `y = C^T(t) x`: filters (2)-(6) (one rho_i per f_i), regression (7) in `Theta = "
         "[-x(0); the unknowns]` (m: its columns m_1, ..., m_p), an estimator, the state (10). Needs `L(t)` with "
         "`A0(t) = A(t) - L(t) C^T(t)` uniformly stable (Assumptions 3-4) and `(A0, C^T)` observable. Inputs `u`, `y`; outputs `x_hat`, `theta_hat`, `k_hat`, `b_hat`, `m_hat`, `x0_hat`, "
         "`F_max` (least squares), `excitation`, `converged`.", _MODEL + (
             Field("L", "expression-vector", "L(t): n expressions of t making A0(t) = A(t) - L(t) C^T uniformly "
                   "stable", unit="1/s", example='["2 - sin(t)", "1 + cos(t)"]'),
             Field("unknowns", "string", "which of k, b, m are estimated (with x(0)), separated by commas; \"\": x(0) "
                   "only", "k, b, m", example='"k"'),
             Field("k", "vector", "the known k (exactly when k is not in unknowns)", None, example="[-1, 3]"),
             Field("b", "vector", "the known b (exactly when b is not in unknowns)", None, example="[0, 1]"),
             Field("m", "vector-or-matrix", "the known m (exactly when m is not in unknowns; n x p with p "
                   "nonlinearities)", None, example="[0, -0.5]"),
             Field("estimator", "choice", "the estimator of regression (7)", ESTIMATORS[0], choices=ESTIMATORS),
             Field("gamma", "number", "adaptation gain of the estimator (drem: the rate, 1/s, at which each "
                   "parameter error decays while |Delta| >> delta_floor)", 1000.0, "", "100"),
             Field("beta", "number", "least squares: forgetting factor", 1.0, "1/s", "0.5"),
             Field("f0", "number", "least squares: F(0) = I / f0", 0.1, "", "0.1"),
             Field("M", "number", "least squares: bound on the largest eigenvalue of F", 1e12, "", "1e12"),
             Field("extension_rate", "number", "DREM: rate a of the extension Phi_e' = -a Phi_e + Psi^T Psi", 1.0,
                   "1/s", "2"),
             Field("delta_floor", "number", "DREM: normalised gain gamma / (delta_floor^2 + Delta^2), so gamma is a "
                   "rate whatever the number of unknowns; 0: the raw gain gamma of the papers", DELTA_FLOOR, "",
                   "1e-6"),
             Field("x_hat0", "vector", "initial estimate of x(0) (absent: zero)", None, example="[0, 0]"),
             Field("k_hat0", "vector", "initial estimate of k (absent: zero)", None, example="[0, 0]"),
             Field("b_hat0", "vector", "initial estimate of b (absent: zero)", None, example="[0, 0]"),
             Field("m_hat0", "vector-or-matrix", "initial estimate of m (absent: zero; n x p with p nonlinearities)",
                   None, example="[0, 0]"),
             Field("f_correction", "boolean", "resolve inside a step the fast part of y that m f(y) drives (outputs "
                   "f(y) makes oscillate between samples; docs/paper001.md, section 2)", False, example="true"),
             Field("converged_tolerance", "number", "converged = 1 once the estimator's guaranteed bound on "
                   "|Theta_hat - Theta| is at most this", 1e-3, "", "1e-2"),
             Field("theta_bound", "number", "a-priori bound on every entry of Theta (the converged criterion's "
                   "assumption)", 100.0, "", "5"),
             Field("regression_error_bound", "number", "least squares: a-priori bound on |z - Psi Theta| (noise); 0: "
                   "exact", 0.0, "(y)", "0.01"),
             Field("plant", "component", "the ltv-plant it observes: with input, the observer is run on them in memory "
                   "along the file's experiment before the build, and the file refused if Theta is not identified to "
                   "converged_tolerance by the end", None, example='"plant"'),
             Field("input", "component", "the source driving that plant (no input, output y)", None,
                   example='"force"'),
             CHECK_FIELD,
         ) + _STEPPING, _define_observer)
