"""Component types ``generator-plant`` and ``gpebo-observer`` of a system file (paper 000).

The plant class (1)-(2): ``x(k+1) = A x(k) + e_n beta(k) u(k) + theta(k) o f(y(k)) + delta(k)``,
``y = x_1``, ``A`` the shift matrix, ``beta = h_beta xi_beta``, ``theta = H_theta xi_theta``,
``delta = H_delta xi_delta``, ``xi(k+1) = Gamma xi(k)``, ``Gamma = Gamma0 + gamma e_1^T``; the observer
estimates per generator ``g`` of ``gamma = [0, ..., 0, g]`` (``gamma_*_unknown = "last"``, the default) or
the whole ``gamma`` (``"all"``, :mod:`observers.gpebo.companion`).  ``f`` is
a vector of expressions of ``y``; the rest are matrices.  Both components are discrete: the file's
``step`` must be their ``Ts``.

Checked before anything is built (one line naming the field, exit 2):

* dimensions: ``f`` and ``x0`` / ``x_hat0`` have ``n`` entries (the rows of ``H_theta``), the generator
  vectors and initial states the sizes of ``h_beta`` and the columns of ``H_theta``, ``H_delta``;
* the observer's structure: every generator reaches the output, the rows of the regression (16) have
  full rank on generic data (:func:`structural_rank`), the regression's shift ``D`` keeps the
  sign of every ``g`` (:class:`~observers.gpebo.regression.ShiftRegression`), the generators are of the
  form ``gamma = [0, ..., 0, g]`` (unless declared ``"all"``) with nonzero entries where the regression
  divides by them (the paper's ``gamma_beta != 0``; ``gamma_d`` of a whole gamma), the initial guesses
  nonzero there; a whole gamma within the regression's limits (rows, unknowns) and of an existing generator;
* the plant named by ``plant``: same ``Ts``, same structure, its generators of that form;
* excitation of the chosen input: with ``plant`` and ``input`` given, the observer itself (the code
  the FMU runs) is run in memory on the plant driven by the input for ``excitation_samples`` samples;
  if it is not ``excited`` at the end (Statement 2's ``nu_gamma``, ``nu_eta`` not below
  ``excitation_tol``) the file is refused with the measured values, naming the input.  This is sound
  for the file's own plant and input only: a plant from elsewhere (an imported FMU) or an input that
  is not a source component cannot be simulated before the run, and then nothing is claimed (the
  build's notes say so).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError, SignalError
from obsfmu.observers.gpebo import GpeboObserver, generator_matrix
from obsfmu.observers.gpebo.companion import UNKNOWN_FORMS
from obsfmu.observers.gpebo.terms import GENERATORS

from ..runtime.definition import FmuDefinition
from ..runtime.functions import expression_function
from ..runtime.kinds.gpebo import generator_plant_definition, gpebo_observer_definition
from .inmemory import CHECK_FIELD, block_of, component_block, refuse_or_warn
from .schema import Context, Field, register

__all__ = ["excitation_run", "structural_rank"]

_STRUCTURE = ("f", "h_beta", "H_theta", "H_delta")
_TS = Field("Ts", "number", "sample period: the file's step must equal it", 1.0, "(time unit)", "1.0")
_CONSTANTS = Field("constants", "table", "named constants of the expressions f", None, example="{ a = 0.5 }")


def _structure_fields(required: bool, source: str) -> tuple[Field, ...]:
    need = {} if required else {"default": None}
    return (
        Field("f", "expression-vector", f"f_i(y), one per state (n entries), expressions of y{source}",
              example='["sin(y)", "0"]', **need),
        Field("h_beta", "vector", f"beta = h_beta xi_beta (l entries: the beta generator's size){source}",
              example="[1, 0]", **need),
        Field("H_theta", "matrix", f"theta = H_theta xi_theta (n x m){source}", example="[[1, 0], [0, 0]]", **need),
        Field("H_delta", "matrix", f"delta = H_delta xi_delta (n x r; absent: no delta){source}", None,
              example="[[0], [1]]"),
    )


def _f_option(values: dict, n: int, prefix: str) -> dict:
    """``f(y)`` as an expression function of the scalar ``y`` with ``n`` entries (eq. (7))."""
    texts = values["f"]
    if len(texts) != n:
        raise ParameterError(f"{prefix}f: expected {n} expressions (one per state, the rows of H_theta), "
                             f"got {len(texts)}")
    return expression_function(texts, [("y", 0)], (n,), constants=values["constants"] or {}, field=prefix + "f")


# ------------------------------------------------------------------ generator-plant
def _define_plant(model_name: str, values: dict, context: Context) -> list:
    delta = [key for key in ("gamma_delta", "xi_delta0", "H_delta") if values[key] is not None]
    if delta and len(delta) != 3:
        missing = sorted({"gamma_delta", "xi_delta0", "H_delta"} - set(delta))
        raise ParameterError(f"{context.prefix}{missing[0]}: the delta generator needs gamma_delta, xi_delta0 and "
                             "H_delta together (or none of them)")
    n = np.size(values["x0"])
    definition = generator_plant_definition(
        model_name, gamma_beta=values["gamma_beta"],
        gamma_theta=values["gamma_theta"], xi_beta0=values["xi_beta0"], xi_theta0=values["xi_theta0"],
        x0=values["x0"], h_beta=values["h_beta"], H_theta=values["H_theta"], gamma_delta=values["gamma_delta"],
        xi_delta0=values["xi_delta0"], H_delta=values["H_delta"], Ts=_positive(values, "Ts", context.prefix),
        f=_f_option(values, n, context.prefix), description=values["description"])
    block_of(definition)      # the plant built once: shapes, f
    for name in ("gamma_beta", "gamma_theta", "gamma_delta"):
        if values[name] is not None:
            _require_bounded(context.prefix + name, values[name])
    return [definition]


def _require_bounded(field: str, gamma) -> None:
    """A generator ``Gamma = Gamma0 + gamma e_1^T`` whose state stays bounded: every eigenvalue on or inside the
    unit circle, those on it simple (the paper's generators are bounded; an unbounded one was refused only by
    the excitation check, whose message pointed at k_gamma)."""
    eigenvalues = np.linalg.eigvals(generator_matrix(np.asarray(gamma, dtype=float)))
    moduli = np.abs(eigenvalues)
    largest = float(moduli.max()) if moduli.size else 0.0
    on_circle = eigenvalues[np.abs(moduli - 1.0) <= 1e-9]
    repeated = any(np.sum(np.abs(on_circle - value) <= 1e-6) > 1 for value in on_circle)
    if largest > 1.0 + 1e-9 or repeated:
        why = (f"an eigenvalue of magnitude {largest:.4g} > 1" if largest > 1.0 + 1e-9
               else "a repeated eigenvalue on the unit circle")
        raise ParameterError(f"{field}: {np.asarray(gamma).tolist()} gives the generator Gamma = Gamma0 + gamma e_1^T "
                             f"{why} (eigenvalues {_listed(eigenvalues)}): the coefficient it generates, and the "
                             f"plant with it, grow without bound; the paper's generators are bounded (every "
                             f"eigenvalue on or inside the unit circle, those on it simple)")


def _listed(values) -> str:
    return ", ".join(f"{v.real:.4g}" if abs(v.imag) < 1e-12 else f"{v.real:.4g}{v.imag:+.4g}i" for v in values)


def _positive(values: dict, key: str, prefix: str) -> float:
    if not values[key] > 0:
        raise ParameterError(f"{prefix}{key}: must be > 0, got {values[key]:g}")
    return float(values[key])


register("generator-plant", "Discrete plant of paper 000: `x(k+1) = A x(k) + e_n beta(k) u(k) + theta(k) o f(y(k)) "
         "+ delta(k)`, `y = x_1`, `A` the shift matrix; `beta = h_beta xi_beta`, `theta = H_theta xi_theta`, "
         "`delta = H_delta xi_delta`, each generator `xi(k+1) = (Gamma0 + gamma e_1^T) xi(k)`. Sampled at "
         "`t = k Ts` whatever the communication step (a step that divides `Ts` samples exactly). Input `u`; outputs `y`, `x`, `beta`, `theta` (and `delta`).",
         (_TS,) + _structure_fields(True, "") + (
             _CONSTANTS,
             Field("gamma_beta", "vector", "coefficients of Gamma_beta = Gamma0 + gamma_beta e_1^T (l entries)",
                   example="[0, -1]"),
             Field("gamma_theta", "vector", "coefficients of Gamma_theta (m entries)", example="[0, 1]"),
             Field("gamma_delta", "vector", "coefficients of Gamma_delta (r entries; with H_delta)", None,
                   example="[0, 1]"),
             Field("xi_beta0", "vector", "initial state of the beta generator", example="[1, 0.5]"),
             Field("xi_theta0", "vector", "initial state of the theta generator", example="[0.5, -0.4]"),
             Field("xi_delta0", "vector", "initial state of the delta generator (with H_delta)", None,
                   example="[0.1]"),
             Field("x0", "vector", "initial state x(0) (n entries)", example="[0.3, -0.2]"),
         ), _define_plant)


# ------------------------------------------------------------------ gpebo-observer
def _other(values: dict, key: str, context: Context):
    """``(kind, values)`` of the component the field ``key`` names (None if absent)."""
    name = values[key]
    if name is not None and name not in context.others:
        raise ParameterError(f"{context.prefix}{key}: {name!r} is not a component defined before this one")
    return None if name is None else context.others[name]


def _plant_values(values: dict, context: Context) -> dict | None:
    other = _other(values, "plant", context)
    if other is None:
        return None
    (kind, plant), name = other, values["plant"]
    if kind != "generator-plant":
        raise ParameterError(f"{context.prefix}plant: {name!r} is a component of kind {kind!r}; the observer "
                             "takes its structure from a generator-plant")
    return plant


def _structure(values: dict, plant: dict | None, context: Context) -> dict:
    """``f``, ``h_beta``, ``H_theta``, ``H_delta``, ``constants``: the observer's own, else the plant's."""
    structure = {}
    for key in _STRUCTURE + ("constants",):
        own, theirs = values[key], None if plant is None else plant[key]
        if own is None and theirs is None and key in ("f", "h_beta", "H_theta"):
            raise ParameterError(f"{context.prefix}{key}: required (or name a generator-plant in plant to take "
                                 "the structure from)")
        if own is not None and theirs is not None and not _same(own, theirs):
            raise ParameterError(f"{context.prefix}{key}: {_text(own)} differs from the {key} of the plant "
                                 f"{values['plant']!r} ({_text(theirs)}); the observer needs the plant's structure")
        structure[key] = own if own is not None else theirs
    return structure


def _text(value) -> str:
    return str(value.tolist()) if isinstance(value, np.ndarray) else repr(value)


def _same(a, b) -> bool:
    try:
        return bool(np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float)))
    except (TypeError, ValueError):
        return a == b


def _require_plant_form(observer: GpeboObserver, plant: dict, values: dict, context: Context) -> None:
    """The plant's generators have the declared form (``[0, ..., 0, g]`` unless ``gamma_*_unknown = "all"``),
    nonzero where the regression divides, same ``Ts``."""
    if plant["Ts"] != values["Ts"]:
        raise ParameterError(f"{context.prefix}Ts: {values['Ts']:g} differs from the plant's Ts = {plant['Ts']:g}")
    regression, vectors = observer.regression, []
    for name, form in zip(GENERATORS, _unknown_forms(values)):
        gamma = np.asarray(plant[name] if plant[name] is not None else [], dtype=float)
        if form == "last" and np.any(gamma[:-1]):
            raise ParameterError(f"{context.prefix}plant: {name} of {values['plant']!r} is {gamma.tolist()}, not "
                                 "[0, ..., 0, g]: the observer's regression assumes one unknown coefficient per "
                                 f"generator (set {name}_unknown = \"all\" to estimate the whole vector)")
        vectors.append(gamma)
    truth = regression.unknowns(*vectors)
    for v in regression.divisors:
        if truth[v] == 0:
            name = regression.names[v]
            where = "ends in 0" if name in GENERATORS else f"has {name} = 0"
            raise ParameterError(f"{context.prefix}plant: {name.split('[')[0]} of {values['plant']!r} {where}; the "
                                 f"regression is divided by it (the paper assumes {name} != 0)")


def _unknown_forms(values: dict) -> tuple[str, ...]:
    """``gamma_beta_unknown``, ``gamma_theta_unknown``, ``gamma_delta_unknown``: "last" or "all"."""
    return tuple(values[f"{name}_unknown"] for name in GENERATORS)


def structural_rank(observer: GpeboObserver, seed: int = 0) -> tuple[int, int]:
    """``(rank, p)`` of the gamma regression's rows on generic data (random ``u``, ``y`` in [0.2, 1.2]).

    The rows are polynomials of the data, so a rank below ``p`` here is a rank below ``p`` for every
    input: the regression is not identifiable whatever the excitation (e.g. two terms with the same
    generator and the same constant ``f``).
    """
    regression, rng = observer.regression, np.random.default_rng(seed)
    w, samples = regression.window, regression.window + 3 * regression.p
    u, y = rng.standard_normal(samples), rng.uniform(0.2, 1.2, samples)
    rows = np.array([regression.row(u[k - w + 1:k + 1], y[k - w + 1:k + 1])[1] for k in range(w - 1, samples)])
    norms = np.linalg.norm(rows, axis=1)
    if not np.any(norms > 0):
        return 0, regression.p
    singular = np.linalg.svd(rows[norms > 0] / norms[norms > 0, None], compute_uv=False)
    return int(np.sum(singular > 1e-9 * singular[0])), regression.p


def _require_identifiable(observer: GpeboObserver, context: Context) -> None:
    try:
        rank, p = structural_rank(observer)
    except SignalError as exc:     # f undefined somewhere in [0.2, 1.2]: the run-time check still applies
        context.notes.append(f"{context.prefix.rstrip('.')}: structural rank not checked ({exc})")
        return
    if rank < p:
        raise ParameterError(f"{context.prefix}f: with this f and H_theta the regression (16) has {p} unknowns but "
                             f"rank {rank} on generic data: the generator coefficients are not identifiable "
                             "whatever the input (terms of one generator with proportional signals)")


def excitation_run(observer: GpeboObserver, plant, source, samples: int, Ts: float) -> GpeboObserver:
    """``observer`` after ``samples`` samples of ``plant`` driven by ``source`` (``u(k) = source(k Ts)``)."""
    for k in range(samples):
        t = k * Ts
        u = source.outputs(t, {})["y"]
        y = plant.outputs(t, {"u": u})["y"]
        observer.advance(t, Ts, {"u": Segment.hold(u), "y": Segment.hold(y)})
        plant.advance(t, Ts, {"u": Segment.hold(u)})
    return observer


def _require_exciting(observer_definition: FmuDefinition, values: dict, context: Context) -> None:
    """The observer's own criterion over the planned run: excited (nu_gamma, nu_eta < excitation_tol) at the end."""
    names = (values["plant"], values["input"])
    source = _other(values, "input", context)
    if None in names:
        context.notes.append(f"{context.prefix.rstrip('.')}: excitation not checked (name the file's plant and "
                             "input source in plant and input to check it before the run)")
        return
    source_kind = source[0]
    blocks = [component_block(name, context) for name in names]
    if blocks[1].input_sizes or blocks[1].output_sizes.get("y") != 1:
        raise ParameterError(f"{context.prefix}input: {names[1]!r} is a {source_kind}, not a source with no input "
                             "and one output y")
    samples = values["excitation_samples"]
    try:
        observer = excitation_run(block_of(observer_definition), *blocks, samples, float(values["Ts"]))
    except (SignalError, ParameterError, FloatingPointError) as exc:
        raise ParameterError(f"{context.prefix}input: the excitation check of {names[1]!r} driving {names[0]!r} "
                             f"failed: {exc}") from None
    if not observer.excited:
        refuse_or_warn(("input", f"{names[1]!r} does not excite the regressions over {samples} samples of {names[0]!r}: "
                        f"nu_gamma = {observer.nu_gamma:.1e}, nu_eta = {observer.nu_eta:.1e} (excited needs both < "
                        f"excitation_tol = {values['excitation_tol']:g}; Statement 2); gamma and the state are not "
                        f"identified{_gain_hint(observer, values)}"), values, context, observer_definition)
        return
    context.notes.append(f"{context.prefix.rstrip('.')}: input {names[1]!r} excites {names[0]!r} over {samples} "
                         f"samples: nu_gamma = {observer.nu_gamma:.1e}, nu_eta = {observer.nu_eta:.1e}")


def _gain_hint(observer: GpeboObserver, values: dict) -> str:
    """With a whole gamma unknown, |Delta| of the many rows is tiny: k_gamma must be below Delta^2."""
    if all(form == "last" for form in _unknown_forms(values)):
        return ""
    return (f"; with a whole gamma unknown the regression has p = {observer.regression.p} unknowns and |Delta| of "
            f"p rows is small: k_gamma = {values['k_gamma']:g} must be below Delta^2 (docs/adaptive-gpebo.md, "
            "\"Full gamma\")")


def _define_observer(model_name: str, values: dict, context: Context) -> list:
    plant = _plant_values(values, context)
    structure = _structure(values, plant, context)
    n = np.shape(structure["H_theta"])[0] if np.ndim(structure["H_theta"]) == 2 else 0
    x_hat0 = np.zeros(n) if values["x_hat0"] is None else values["x_hat0"]
    if np.size(x_hat0) != n:
        raise ParameterError(f"{context.prefix}x_hat0: expected {n} entries (the rows of H_theta), got "
                             f"{np.size(x_hat0)}")
    sizes = [np.size(structure["h_beta"]), np.shape(structure["H_theta"])[-1]]
    if structure["H_delta"] is not None:
        sizes.append(np.shape(structure["H_delta"])[-1])
    forms = _unknown_forms(values)
    if structure["H_delta"] is None and forms[2] == "all":
        raise ParameterError(f"{context.prefix}gamma_delta_unknown: \"all\" but there is no delta generator "
                             "(H_delta absent)")
    unknowns = sum(size if form == "all" else 1 for size, form in zip(sizes, forms))
    gamma_hat0 = np.full(unknowns, 0.5) if values["gamma_hat0"] is None else values["gamma_hat0"]
    keywords = {key: values[key] for key in ("k_gamma", "k_eta", "eta_hat0", "restart_tol", "excitation_tol",
                                              "converged_tolerance", "theta_bound", "consistency_tol")}
    definition = gpebo_observer_definition(
        model_name, Ts=_positive(values, "Ts", context.prefix),
        gamma_hat0=gamma_hat0, x_hat0=x_hat0, f=_f_option(structure, np.size(x_hat0), context.prefix),
        h_beta=structure["h_beta"], H_theta=structure["H_theta"], H_delta=structure["H_delta"],
        gamma_unknown=forms, description=values["description"], **keywords)
    observer = block_of(definition)
    _require_identifiable(observer, context)
    if plant is not None:
        _require_plant_form(observer, plant, values, context)
    _require_exciting(definition, values, context)
    return [definition]


register("gpebo-observer", "Adaptive observer of paper 000 (GPEBO + DREM) for a generator-plant structure: "
         "estimates the generator coefficients `g` (each generator `gamma = [0, ..., 0, g]`, or its whole `gamma` "
         "with `gamma_*_unknown = \"all\"`), the generator "
         "states and `x`. The structure is its own fields or, when absent, the `plant`'s. One step = one sample. "
         "Inputs `u`, `y`; outputs `x_hat`, `gamma_hat`, `eta_hat`, `beta_hat`, `theta_hat`, `excited`, "
         "`nu_gamma`, `nu_eta`, `restart_time`, `excitation`, `converged`.", (
             Field("plant", "component", "a generator-plant: its structure (f, h_beta, H_theta, H_delta) is taken "
                   "when the observer's is absent, and checked against it", None, example='"plant"'),
             Field("input", "component", "the source driving the plant: with plant, the observer is run on them in "
                   "memory and the file refused if it is not excited", None, example='"source"'),
             Field("excitation_samples", "integer", "samples of that check (the planned run)", 40, example="40",
                   maximum=10 ** 5),
             CHECK_FIELD,
             _TS) + _structure_fields(False, " (absent: the plant's)") + (
             Field("constants", "table", "named constants of the expressions f (absent: the plant's)", None,
                   example="{ a = 0.5 }"),
             Field("gamma_hat0", "vector", "initial g of each generator (beta, theta, delta), nonzero where the "
                   "regression divides (absent: 0.5 each); with gamma_*_unknown = \"all\" one entry per unknown, "
                   "in the order beta's, theta's, delta's", None, example="[-0.5, 0.5]"),
         ) + tuple(
             Field(f"{name}_unknown", "choice", f"which entries of {name} the observer estimates: \"last\" "
                   f"({name} = [0, ..., 0, g], g unknown) or \"all\" (the whole vector: the regression of "
                   "docs/adaptive-gpebo.md, \"Full gamma\")", "last", choices=UNKNOWN_FORMS, example='"all"')
             for name in GENERATORS) + (
             Field("eta_hat0", "vector", "initial [xi_beta; xi_theta; xi_delta](0) (absent: zero)", None,
                   example="[0, 0, 0, 0]"),
             Field("x_hat0", "vector", "initial estimate x_hat(0) (absent: zero)", None, example="[0, 0]"),
             Field("k_gamma", "number", "gain k of Statement 2 for sigma (small: fast; rows normalised; with a whole "
                   "gamma unknown it must be below Delta^2 of p rows, e.g. 1e-30 for p = 29)", 1e-8,
                   example="1e-8"),
             Field("k_eta", "number", "gain k of Statement 2 for eta", 1e-8, example="1e-8"),
             Field("restart_tol", "number", "relative change of gamma_hat that restarts the GPEBO filters", 1e-11,
                   example="1e-11"),
             Field("excitation_tol", "number", "excited = 1 once nu_gamma and nu_eta are below this", 1e-9,
                   example="1e-9"),
             Field("converged_tolerance", "number", "converged = 1 once the guaranteed errors of gamma and eta "
                   "are at most this", 1e-6, example="1e-6"),
             Field("theta_bound", "number", "a-priori bound on |sigma_i| and |eta_i| (the criterion's "
                   "assumption)", 100.0, example="100"),
             Field("consistency_tol", "number", "converged also needs the a-priori relative residuals of the "
                   "last p gamma rows at most this: the bounds hold for exact data only (noise keeps it 0)", 1e-10,
                   example="1e-10"),
         ), _define_observer)

