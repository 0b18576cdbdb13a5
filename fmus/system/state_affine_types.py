r"""Component types of paper 004: ``state-affine-observer`` for any plant of its class, ``pendulum``, ``chemostat``.

The observer (``docs/adaptive-state-affine.md``) takes the user's state-affine form of the plant as
expressions: (2) ``chi' = Lambda(y, u) chi + Psi(y, u) theta_p + w(y, u)``, the relation (3)
``phi_l^T theta_l + phi_chi^T chi = c(y, u)`` (``phi = col(phi_l, phi_chi)``) and the left inverse
``x = phi_L(chi, theta)``.  Every dimension follows from the shapes of the expressions (``q`` the rows
of ``Lambda``, ``p`` the columns of ``Psi``, ``l = len(phi) - q``, ``n = len(phi_L)``).

Checked before anything is built, each refusal naming the field and the assumption:

* shapes: ``Lambda`` square, ``Psi`` and ``w`` with ``q`` rows, ``phi`` at least ``q`` entries,
  ``C``, ``L``, ``poles``, ``rates``, ``chi_hat0``, ``theta_hat0`` of their sizes;
* every function evaluated at a sample point ``(y, u)``: finite there;
* Statement 2 (numbers in ``Lambda``, with ``C``): ``(Lambda, C)`` observable (Assumption 6),
  ``Lambda - L C`` with bounded solutions (no eigenvalue right of the axis, none repeated on it);
* identifiability: each ``theta_p[j]`` enters (2) (its column of ``Psi`` is not zero at every sample
  point), each ``theta_l[j]`` enters (3), ``phi_chi`` is not zero everywhere (Assumption 2);
* the rank of the extended regressor (6): the filters of Statements 1-2 are run in memory on a
  generic exciting ``(y, u)`` (sines around the sample point); a regressor singular at every time
  means that some unknown of ``col(theta_l, chi(t), chi(0), theta_p)`` cannot be identified from any
  data -- refused naming it.

The paper's example plants keep their own kinds (``pendulum``, ``chemostat`` of
:mod:`plants.state_affine`), so that the paper scenarios run bit for bit from their files; a plant
of your own is an ``expression`` component (``examples/state_affine_vanderpol.toml``).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.modal import is_observable, observer_gain
from obsfmu.observers.state_affine.model import require_bounded_filter

from ..runtime.functions import compiled, expression_function
from ..runtime.kinds import create_block
from ..runtime.kinds.state_affine import chemostat_definition, observer_definition, pendulum_definition
from .schema import Context, Field, register
from .values import MAX_DIMENSION

__all__ = ["sample_points", "regressor_rank"]

_RANK_TOLERANCE = 1e-9     #: smallest / largest singular value of the normalised regressor below this: singular


def sample_points(ny: int, nu: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``(y, u)`` at which the functions are checked: the observer's probe ``(0.5, 0.5)`` first."""
    others = [(y0 + 0.1 * np.arange(ny), u0 + 0.1 * np.arange(nu)) for y0, u0 in ((-0.7, 1.1), (1.3, -0.4))]
    return [(np.full(ny, 0.5), np.full(nu, 0.5))] + others


# ------------------------------------------------------------------ shapes and options
def _shape(value) -> tuple[int, ...]:
    return () if not isinstance(value, list) else (len(value),) if not isinstance(value[0], list) \
        else (len(value), len(value[0]))


def _require_shape(name: str, value, shape: tuple[int, ...], what: str) -> None:
    if _shape(value) != shape:
        got = " x ".join(map(str, _shape(value))) or "one entry"
        raise ParameterError(f"{name}: expected {' x '.join(map(str, shape)) or 'one entry'} ({what}), got {got}")


def _dimensions(values: dict) -> dict[str, int]:
    """``q, p, l, n, ny, nu`` from the shapes of the expressions, each checked."""
    for key in ("outputs", "inputs"):
        if values[key] < 1:
            raise ParameterError(f"{key}: expected a size >= 1, got {values[key]}")
    Lambda = values["Lambda"]
    q = len(Lambda)
    _require_shape("Lambda", Lambda, (q, q), "q x q: square, one row per entry of chi")
    p = 0
    if values["Psi"] is not None:
        p = len(values["Psi"][0])
        _require_shape("Psi", values["Psi"], (q, p), f"q x p: q = {q} rows, one per entry of chi")
    if values["w"] is not None:
        _require_shape("w", values["w"], (q,), f"q = {q} entries, one per entry of chi")
    l = len(values["phi"]) - q
    if l < 0:
        raise ParameterError(f"phi: expected l + q >= q = {q} entries (col(phi_l, phi_chi) of relation (3)), "
                             f"got {len(values['phi'])}")
    n = q if values["phi_L"] is None else len(values["phi_L"])
    return dict(q=q, p=p, l=l, n=n, ny=values["outputs"], nu=values["inputs"])


def _functions(values: dict, dims: dict, constant: bool) -> dict[str, dict]:
    """The expression functions of the file: ``(y, u)`` for (2), (3); ``(chi, theta)`` for ``phi_L``."""
    q, p, l = dims["q"], dims["p"], dims["l"]
    constants = values["constants"] or {}
    clash = sorted(set(constants) & {"t", "y", "u", "chi", "theta"})
    if clash:
        raise ParameterError(f"constants: {clash[0]!r} is the name of an argument of the functions (y, u; chi, theta)")
    signals = [("y", dims["ny"]), ("u", dims["nu"])]
    texts = {"Lambda": None if constant else values["Lambda"], "Psi": values["Psi"],
             "w": values["w"] if values["w"] is not None else [0.0] * q, "phi": values["phi"], "c": values["c"],
             "phi_L": values["phi_L"] if values["phi_L"] is not None else [f"chi[{i}]" for i in range(1, q + 1)]}
    shapes = {"Lambda": (q, q), "Psi": (q, p), "w": (q,), "phi": (l + q,), "c": (), "phi_L": (dims["n"],)}
    return {name: expression_function(text, [("chi", q), ("theta", l + p)] if name == "phi_L" else signals,
                                      shapes[name], constants=constants, field=name)
            for name, text in texts.items() if text is not None}


def _finite_at_sample(functions: dict, dims: dict) -> None:
    """Every function once at the first sample point (``phi_L`` at ``chi = 0``, ``theta = 0``): finite."""
    y, u = sample_points(dims["ny"], dims["nu"])[0]
    for name, option in functions.items():
        arguments = (np.zeros(dims["q"]), np.zeros(dims["l"] + dims["p"])) if name == "phi_L" else (y, u)
        where = "chi = 0, theta = 0" if name == "phi_L" else f"y = {y.tolist()}, u = {u.tolist()}"
        try:
            value = np.asarray(compiled(option, name)(*arguments), dtype=float)
        except (ArithmeticError, ValueError) as exc:
            raise ParameterError(f"{name}: cannot be evaluated at the sample point {where} ({exc})") from None
        if not np.all(np.isfinite(value)):
            raise ParameterError(f"{name}: not finite at the sample point {where}: {value.tolist()}; the functions "
                                 "must be defined there (the observer's probe point)")


# ------------------------------------------------------------------ Statement 2
def _constant_lambda(values: dict, dims: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(Lambda, C, L)`` of Statement 2 (numbers in Lambda, with C), checked; None for Statement 1."""
    q, ny = dims["q"], dims["ny"]
    given = [key for key in ("C", "L", "poles") if values[key] is not None]
    if values["C"] is None:
        if given:
            raise ParameterError(f"{given[0]}: only with C (Statement 2: a constant Lambda and y = C chi)")
        return None
    if any(isinstance(v, str) for row in values["Lambda"] for v in row):
        raise ParameterError("Lambda: with C (Statement 2) Lambda must be a constant matrix of numbers; "
                             "leave C out for a Lambda(y, u) of expressions (Statement 1)")
    Lambda = np.array(values["Lambda"], dtype=float)
    C = values["C"]
    if C.shape != (ny, q):
        raise ParameterError(f"C: expected {ny} x {q} (ny x q: y = C chi), got {C.shape[0]} x {C.shape[1]}")
    if not is_observable(Lambda, C):
        raise ParameterError("C: the pair (Lambda, C) is not observable; Statement 2 (Assumption 6) needs it")
    if (values["L"] is None) == (values["poles"] is None):
        raise ParameterError("L: give exactly one of L (q x ny) and poles (the eigenvalues of Lambda - L C) "
                             "for Statement 2")
    if values["poles"] is not None:
        poles = [complex(*p) if isinstance(p, list) else complex(p) for p in values["poles"]]
        if len(poles) != q:
            raise ParameterError(f"poles: expected q = {q} eigenvalues of Lambda - L C, got {len(poles)}")
        poles = np.array(poles)
        L = observer_gain(Lambda, C, poles.real if not np.any(poles.imag) else poles)
        field = "poles"
    else:
        L = values["L"]
        if L.shape != (q, ny):
            raise ParameterError(f"L: expected {q} x {ny} (q x ny), got {L.shape[0]} x {L.shape[1]}")
        field = "L"
    try:
        require_bounded_filter("Lambda - L C", Lambda - L @ C)
    except ParameterError as exc:
        raise ParameterError(f"{field}: {exc} (Statement 2 needs bounded filters, Assumption 4)") from None
    return Lambda, C, L


# ------------------------------------------------------------------ identifiability and rank
def _identifiable(block, dims: dict) -> None:
    """Each unknown enters the model at some sample point (Assumption 2 for phi_chi)."""
    model, p, l = block.model, dims["p"], dims["l"]
    terms = []
    for y, u in sample_points(dims["ny"], dims["nu"]):
        try:
            with np.errstate(all="ignore"):
                terms.append(model.evaluate(y, u))
        except (ArithmeticError, ValueError, SignalError):
            continue        # outside the functions' domain (the first point, the probe, is inside)
    for j in range(p):
        if all(not np.any(t.Psi[:, j]) for t in terms):
            raise ParameterError(f"Psi: column {j + 1} is zero at every sample point: theta_p[{j + 1}] never enters "
                                 "(2) and cannot be estimated")
    for j in range(l):
        if all(t.phi[j] == 0 for t in terms):
            raise ParameterError(f"phi: entry {j + 1} (phi_l[{j + 1}]) is zero at every sample point: "
                                 f"theta_l[{j + 1}] never enters relation (3) and cannot be estimated")
    if all(not np.any(t.phi[l:]) for t in terms):
        raise ParameterError("phi: phi_chi (its last q entries) is zero at every sample point: relation (3) says "
                             "nothing about chi (Assumption 2)")


def _generic_signals(dims: dict, scale: float):
    """An exciting ``(y(t), u(t))``: two sines per entry around the first sample point."""
    y0, u0 = sample_points(dims["ny"], dims["nu"])[0]
    iy, iu = np.arange(dims["ny"]), np.arange(dims["nu"])

    def signals(t: float) -> tuple[np.ndarray, np.ndarray]:
        s = scale * t
        return (y0 + 0.2 * np.sin(1.3 * s + iy) + 0.1 * np.sin(3.1 * s + 2 * iy),
                u0 + 0.2 * np.sin(0.7 * s + 1 + iu) + 0.1 * np.sin(2.3 * s + iu))
    return signals


def regressor_rank(block, dims: dict, enough: float = np.inf) -> tuple[int, float, np.ndarray]:
    """Rank of the row-normalised extended regressor (6) along a generic exciting ``(y, u)``.

    The filters of :class:`~observers.state_affine.parametrization.Parametrization` are advanced by
    RK4 with step ``1 / max(rates)`` over ``5 / min(rates)`` (at most 500 steps); at every step the
    singular values of the regressor with its rows divided by their norms are taken.  The run stops
    as soon as ``s_min / s_max`` reaches ``enough`` (a regular model: after a few steps).

    Returns
    -------
    (rank, ratio, null) : the rank at the best time, the largest ``s_min / s_max`` over the run, the
    right singular vector of ``s_min`` there (the unidentifiable direction when the ratio is tiny);
    ratio -1 when no time gave a regressor without a zero row (the run left the functions' domain
    or its filters grew beyond floats at once): inconclusive.
    """
    parametrization, model = block.parametrization, block.model
    rates = parametrization.rates
    dt, steps = 1.0 / rates.max(), min(500, int(np.ceil(5.0 * rates.max() / rates.min())))
    signals = _generic_signals(dims, float(np.sqrt(rates.min() * rates.max())))

    def derivative(t, state):
        y, u = signals(t)
        return parametrization.derivative(state, model.evaluate(y, u), y)

    state, best = parametrization.initial_state(), (0, -1.0, np.zeros(parametrization.N))
    for i in range(steps):
        t = i * dt
        try:
            with np.errstate(all="ignore"):
                k1 = derivative(t, state)
                k2 = derivative(t + dt / 2, state + dt / 2 * k1)
                k3 = derivative(t + dt / 2, state + dt / 2 * k2)
                k4 = derivative(t + dt, state + dt * k3)
                state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        except (ArithmeticError, ValueError, SignalError):
            break           # outside the functions' domain: the check stops with what it has seen
        if not np.all(np.isfinite(state)):
            break
        Psi_e = parametrization.regression(state)[1]
        norms = np.linalg.norm(Psi_e, axis=1)
        if np.all(norms > 0):
            _, s, vt = np.linalg.svd(Psi_e / norms[:, None])
            ratio = s[-1] / s[0]
            if ratio > best[1]:
                best = (int(np.sum(s > _RANK_TOLERANCE * s[0])), float(ratio), vt[-1])
            if ratio >= enough:
                break
    return best


def _unknown_labels(dims: dict) -> list[tuple[str, str]]:
    """``(label, field to blame)`` of each unknown of ``col(theta_l, chi(t), chi(0), theta_p)``."""
    q, p, l = dims["q"], dims["p"], dims["l"]
    return ([(f"theta_l[{j}]", "phi") for j in range(1, l + 1)] + [(f"chi[{j}](t)", "Lambda") for j in range(1, q + 1)]
            + [(f"chi[{j}](0)", "Lambda") for j in range(1, q + 1)] + [(f"theta_p[{j}]", "Psi") for j in range(1, p + 1)])


def _require_exciting(block, dims: dict) -> None:
    rank, ratio, null = regressor_rank(block, dims, enough=_RANK_TOLERANCE)
    if ratio >= _RANK_TOLERANCE or ratio < 0:       # exciting, or inconclusive: accepted
        return
    labels = _unknown_labels(dims)
    weights = np.abs(null)
    involved = [labels[j][0] for j in np.argsort(-weights) if weights[j] > 0.1 * weights.max()]
    field = labels[int(np.argmax(weights))][1]
    hint = {"Psi": "their columns of Psi(y, u) are not independent along the data",
            "phi": "their entries of phi_l(y, u) are not independent along the data",
            "Lambda": "relation (3) (phi_chi) seen through Lambda does not observe them"}[field]
    raise ParameterError(f"{field}: the extended regressor (6) is singular along a generic exciting (y, u) (rank "
                         f"{rank} < N = {len(labels)}, s_min/s_max = {ratio:.1e}): {', '.join(involved)} cannot be "
                         f"identified from any data -- {hint} (Statements 1-2)")


# ------------------------------------------------------------------ the observer
def _vector(values: dict, key: str, size: int, what: str):
    vector = values[key]
    if vector is not None and np.size(vector) != size:
        raise ParameterError(f"{key}: expected {size} entries ({what}), got {np.size(vector)}")
    return vector


def _units(values: dict, time_unit: str) -> dict:
    return {"y": values["output_unit"], "u": values["input_unit"], "x": values["state_units"],
            "theta": values["parameter_units"], "time": time_unit}


def _define_observer(model_name: str, values: dict, context: Context) -> list:
    dims = _dimensions(values)
    statement2 = _constant_lambda(values, dims)
    functions = _functions(values, dims, constant=statement2 is not None)
    _finite_at_sample(functions, dims)
    _vector(values, "rates", dims["l"] + dims["q"] + dims["p"], "k = l + q + p filter rates, one per filtered copy "
            "of (4)/(5)")
    context.rate(values["rates"], "rates (filter rates a_i)")      # the converged flag's step range (load.py)
    _vector(values, "chi_hat0", dims["q"], "q: the observer's initial chi_hat")
    _vector(values, "theta_hat0", dims["l"] + dims["p"], "l + p: col(theta_l, theta_p)")
    Lambda, C, L = statement2 if statement2 is not None else (None, None, None)
    definition = observer_definition(
        model_name, dims=dims, functions=functions, rates=values["rates"], gamma=values["gamma"],
        gamma_x=values["gamma_x"], mu=values["mu"], max_substep=values["max_substep"], chi_hat0=values["chi_hat0"],
        theta_hat0=values["theta_hat0"], Lambda=Lambda, C=C, L=L, units=_units(values, context.time_unit),
        converged_tolerance=values["converged_tolerance"], theta_bound=values["theta_bound"],
        description=values["description"])
    block = create_block(definition.kind, {p.name: p.array(p.value) for p in definition.parameters},
                         definition.options)
    _identifiable(block, dims)
    _require_exciting(block, dims)
    return [definition]


_SIGNALS_DOC = "of y, u (y[1], u[2]; a one-entry y or u also bare)"
_OBSERVER_FIELDS = (
    Field("outputs", "integer", "ny: the size of the measured output y", 1, example="1", maximum=MAX_DIMENSION),
    Field("inputs", "integer", "nu: the size of the plant input u", 1, example="1", maximum=MAX_DIMENSION),
    Field("constants", "table", "named constants the expressions may use", None, example="{ mu_max = 0.5, k = 2 }"),
    Field("Lambda", "expression-matrix", f"Lambda of (2), q x q: expressions {_SIGNALS_DOC} (Statement 1), or "
          "numbers with C (Statement 2)", example='[["mu_max*y/(K_S + y) - u", 0], [0, "-u"]]'),
    Field("Psi", "expression-matrix", f"Psi of (2), q x p, {_SIGNALS_DOC} (absent: p = 0)", None,
          example='[["-y", 0], [0, "-sin(y)"]]'),
    Field("w", "expression-vector", f"w of (2), q entries, {_SIGNALS_DOC} (absent: zero)", None,
          example='[0, "u"]'),
    Field("phi", "expression-vector", f"col(phi_l, phi_chi) of relation (3), l + q entries, {_SIGNALS_DOC}",
          example="[1, 0]"),
    Field("c", "expression", f"right-hand side c of relation (3), {_SIGNALS_DOC}", example='"y"'),
    Field("phi_L", "expression-vector", "left inverse x = phi_L(chi, theta), n entries, of chi[i] and "
          "theta[j] = col(theta_l, theta_p) (absent: x = chi)", None, example='["chi[1]", "chi[2] - theta[1]*chi[1]"]'),
    Field("C", "matrix", "Statement 2: y = C chi (ny x q)", None, example="[[1, 0]]"),
    Field("L", "matrix", "Statement 2: the filters' injection gain (q x ny), or give poles", None,
          example="[[0], [4]]"),
    Field("poles", "poles", "Statement 2: the eigenvalues of Lambda - L C (q of them), instead of L; on the "
          "imaginary axis keeps Delta exciting", None, "1/(time unit)", "[[0, 2], [0, -2]]"),
    Field("rates", "vector", "filter rates a_i of a_i/(p + a_i), l + q + p distinct, > 0", unit="1/(time unit)",
          example="[0.5, 2, 8, 32]"),
    Field("gamma", "number", "gain of the finite-time gradient estimator (rate gamma Delta^2)", unit="1/(time unit)",
          example="1e10"),
    Field("gamma_x", "number", "gain of the correction of Statement 3 (rate gamma_x Delta^2)", unit="1/(time unit)",
          example="1e10"),
    Field("mu", "number", "switching level of the finite-time estimate, in (0, 1)", 0.98, example="0.98"),
    Field("max_substep", "number", "longest internal integration step", 1e-3, "(time unit)", "1e-3"),
    Field("chi_hat0", "vector", "initial chi_hat (q; absent: zero)", None, example="[0, 0]"),
    Field("theta_hat0", "vector", "initial estimate of col(theta_l, theta_p) (absent: zero)", None,
          example="[0, 0]"),
    Field("converged_tolerance", "number", "converged = 1 once the guaranteed parameter error bound is at most this",
          1e-3, "(parameter)", "1e-4"),
    Field("theta_bound", "number", "a-priori bound on every unknown, |theta_i| <= theta_bound (for converged)",
          100.0, "(parameter)", "20"),
    Field("output_unit", "units", "unit of y", None, example='"rad"'),
    Field("input_unit", "units", "unit of u", None, example='"rad/s2"'),
    Field("state_units", "units", "units of x_hat (n)", None, example='["rad", "rad/s"]'),
    Field("parameter_units", "units", "units of theta_hat (l + p)", None, example='["1/s", "1/s2"]'),
)

register("state-affine-observer",
         "DREM adaptive observer of paper 004 for a plant the user maps to the state-affine form (2) "
         "`chi' = Lambda chi + Psi theta_p + w` with the relation (3) `phi_l^T theta_l + phi_chi^T chi = c` and the "
         "left inverse `x = phi_L(chi, theta)` (docs/adaptive-state-affine.md). Inputs `y`, `u`; outputs `x_hat`, "
         "`theta_hat` (if l + p > 0), `chi_hat`, `Delta`, `nu`, `excitation`, `converged`.",
         _OBSERVER_FIELDS, _define_observer)


# ------------------------------------------------------------------ the paper's example plants
def _define_pendulum(model_name: str, values: dict, context: Context) -> list:
    return [pendulum_definition(model_name, values["a"], values["b"], _vector(values, "x0", 2, "angle, velocity"))]


def _define_chemostat(model_name: str, values: dict, context: Context) -> list:
    if values["S_in"] <= 0:
        raise ParameterError(f"S_in: must be > 0, got {values['S_in']:g}")
    return [chemostat_definition(model_name, values["S_in"], _vector(values, "x0", 2, "X, S"))]


register("pendulum", "Paper 004's pendulum `phi'' = -a sin(phi) - b phi' + u`, `y = phi` (plants.state_affine; "
         "RK4, sub-steps of 1e-3 s). Input `u`; outputs `y`, `x` = (phi, phi'), `theta` = (b, a) (the truth).", (
             Field("a", "number", "gravity coefficient g/l", unit="1/s2", example="9.81"),
             Field("b", "number", "viscous friction coefficient, >= 0", unit="1/s", example="0.5"),
             Field("x0", "vector", "initial angle and angular velocity", unit="rad, rad/s", example="[0.5, 0]"),
         ), _define_pendulum)
register("chemostat", "Paper 004's chemostat `X' = mu(S) X - D X`, `S' = -k mu(S) X + D (S_in - S)`, Monod "
         "`mu(S) = 0.5 S / (1 + S)` 1/h, `k = 2`, `y = S`, `u = D`; time in hours (plants.state_affine; RK4, "
         "sub-steps of 0.01 h). Input `u`; outputs `y`, `x` = (X, S), `theta` = S_in (the truth).", (
             Field("S_in", "number", "feed substrate concentration, > 0", unit="g/L", example="10"),
             Field("x0", "vector", "initial biomass X and substrate S", unit="g/L", example="[2, 3]"),
         ), _define_chemostat)
