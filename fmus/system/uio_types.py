"""Component types of paper 003: ``ltv-disturbed-plant`` and ``uio-ftdrem-observer``.

The plant (1) ``x' = A x + B [theta^T x + f]``, ``y = C x``, ``theta = H xi``, ``xi' = Gamma xi``,
``f = sum_k a_k sin(omega_k t + phi_k)``; the observer is designed here from the plant's matrices
(:mod:`observers.uio.design`): the relative degree ``r`` (computed, or given and checked), ``G``
and ``M`` of (3)-(4), ``L`` placing the chosen ``eig(F)``, ``F = M - L C``.  Refused before
anything is built, naming the field and the assumption: the relative-degree conditions
(``C A^k B = 0`` for ``k < r - 1``, ``rank C A^(r-1) B = rank B``: (3) solvable), unstable zeros
or poles (``F`` Hurwitz), ``B_bar B = 1``, the number of harmonics (known, >= 1, distinct positive
frequencies) and an unbounded generator of ``theta`` (``e^{Gamma t}`` must be bounded: every eigenvalue
with ``Re <= 0``, those on the imaginary axis semisimple; :mod:`observers.uio.generator`).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.uio import (UIOFiniteTimeObserver, UIOSettings, check_generator, check_relative_degree,
                           relative_degree, uio_gain, uio_matrices)
from obsfmu.observers.uio.identifiability import (ENOUGH_EXCITATION, EXACT_LEVEL, RANK_TOLERANCE,
                                                  stage_two_excitation, stage_two_labels, stage_two_truth)
from obsfmu.plants.uio import DisturbedLTVPlant

from ..caches import remembered
from ..config import require_bounded_transient
from ..runtime.kinds.uio import ltv_plant_definition, uio_observer_definition
from .inmemory import CHECK_FIELD, check_key, refuse_or_warn
from .linear_types import matrix_text, poles_text
from .schema import Context, Field, register

__all__ = ["plant_arrays"]

PLANT_KIND = "ltv-disturbed-plant"
_DEFAULTS = UIOSettings()


def plant_arrays(values: dict) -> dict:
    """The plant's matrices and vectors with the defaults filled in (``H = I``, ``Gamma = 0``, ...)."""
    A = np.atleast_2d(values["A"])
    n = A.shape[0]
    H = np.eye(n) if values["H"] is None else values["H"]
    m = np.shape(H)[1]
    amplitude = values["amplitude"]
    return {"A": A, "B": values["B"], "C": values["C"], "H": H,
            "Gamma": np.zeros((m, m)) if values["Gamma"] is None else values["Gamma"],
            "xi0": values["xi0"], "x0": np.zeros(n) if values["x0"] is None else values["x0"],
            "amplitude": amplitude, "omega": values["omega"],
            "phase": np.zeros(np.size(amplitude)) if values["phase"] is None else values["phase"]}


def _define_plant(model_name: str, values: dict, context: Context) -> list:
    p = plant_arrays(values)
    if np.size(p["amplitude"]) < 1:
        raise ParameterError("amplitude: no sinusoid; f is a sum of N >= 1 sinusoids (Assumption 1)")
    if np.any(np.asarray(p["omega"]) <= 0):
        raise ParameterError(f"omega: frequencies must be > 0 (f is a sum of sinusoids, Assumption 1), "
                             f"got {np.asarray(p['omega']).tolist()}")
    DisturbedLTVPlant(**p)      # checks every shape, naming the field
    return [ltv_plant_definition(model_name, **p, description=values["description"])]


register(PLANT_KIND, "Plant of paper 003, eq. (1): `x' = A x + B [theta^T x + f(t)]`, `y = C x`, single input "
         "and output; state feedback with parameters `theta = H xi`, `xi' = Gamma xi`; disturbance "
         "`f = sum_k amplitude_k sin(omega_k t + phase_k)`. No inputs; outputs `y`, the true `x`, `theta`, `xi`, `f` "
         "and `f_omega` (the frequencies).", (
             Field("A", "matrix", "state matrix (n x n)", unit="1/s", example="[[0, 1], [-2, 0]]"),
             Field("B", "vector", "input vector (n entries): theta^T x + f enters through it", example="[0, 1]"),
             Field("C", "vector", "output row (n entries), y = C x", example="[2, 0]"),
             Field("H", "matrix", "theta = H xi (n x m; absent: the identity)", None, example="[[1, 0], [0, 1]]"),
             Field("Gamma", "matrix", "generator of the parameters, xi' = Gamma xi (m x m; absent: zero)", None,
                   "1/s", "[[0, 0], [0, 0]]"),
             Field("xi0", "vector", "initial generator state xi(0) (m entries; unknown to the observer)",
                   example="[0, -1]"),
             Field("x0", "vector", "initial state x(0) (absent: zero)", None, example="[-1, 1]"),
             Field("amplitude", "vector", "amplitudes a_k of the N sinusoids of f", example="[5]"),
             Field("omega", "vector", "their angular frequencies (> 0)", unit="rad/s", example="[1]"),
             Field("phase", "vector", "their phases (absent: zero)", None, "rad", "[0]"),
         ), _define_plant)


# ---------------------------------------------------------------------------------------------- observer
def _plant_of(values: dict, context: Context) -> dict:
    """The arrays of the ``ltv-disturbed-plant`` component the observer names, its assumptions checked."""
    name = values["plant"]
    kind, plant_values = context.others[name]
    if kind != PLANT_KIND:
        raise ParameterError(f"plant: {name!r} is a component of kind {kind!r}; the observer needs an "
                             f"{PLANT_KIND} component defined before it")
    p = plant_arrays(plant_values)
    check_generator(p["Gamma"], np.shape(p["H"])[1], f"components.{name}.Gamma")      # theta = H e^{Gamma t} xi(0)
    return p


def _harmonics(values: dict, plant: dict, name: str) -> int:
    """The known number N of sinusoids (Assumption 1): the plant's, with distinct frequencies."""
    omega = np.asarray(plant["omega"], dtype=float)
    N = omega.size if values["harmonics"] is None else values["harmonics"]
    if N < 1:
        raise ParameterError(f"harmonics: expected N >= 1 sinusoids, got {N}")
    if N != omega.size:
        raise ParameterError(f"harmonics: {N}, but the disturbance of {name!r} has {omega.size} sinusoids; the "
                             "observer needs the true number of harmonics (Assumption 1)")
    if np.unique(omega).size != omega.size:
        raise ParameterError(f"harmonics: the frequencies of {name!r} {omega.tolist()} are not distinct; N "
                             "sinusoids must have N distinct frequencies (otherwise give fewer)")
    return int(N)


def _order(values: dict, plant: dict, name: str) -> int:
    """``r``: the plant's relative degree, or the one given, checked (``C A^k B = 0`` for ``k < r - 1``,
    ``rank C A^(r-1) B = rank B``: (3) has a solution)."""
    try:
        r = relative_degree(plant["A"], plant["B"], plant["C"])
    except ParameterError as exc:
        raise ParameterError(f"plant: {name!r}: {exc}") from None
    if "r" not in values["given"]:
        return r
    return check_relative_degree(plant["A"], plant["B"], plant["C"], values["r"])


def _complex_poles(poles) -> np.ndarray:
    """Poles of the ``poles`` field type: numbers, or ``[re, im]`` pairs."""
    array = np.array([complex(*p) if isinstance(p, list) else complex(p) for p in poles])
    return array.real if not np.any(array.imag) else array


def _gain(values: dict, plant: dict, r: int) -> tuple[np.ndarray, bool]:
    """``L``: placing ``poles`` = eig(F) (Hurwitz, bounded transient), or given; and whether designed."""
    chosen = [key for key in ("poles", "L") if key in values["given"]]
    if len(chosen) != 1:
        raise ParameterError(f"poles: give exactly one of 'poles' (eig(F), F = M - L C) or 'L', got "
                             f"{chosen or 'none'}")
    if chosen == ["L"]:
        _, M = uio_matrices(plant["A"], plant["B"], plant["C"], r)
        eigenvalues = np.linalg.eigvals(M - np.outer(values["L"], plant["C"])) if np.size(values["L"]) == \
            np.size(plant["C"]) else np.zeros(0)
        if np.any(eigenvalues.real >= 0):
            raise ParameterError(f"L: eig(M - L C) = [{poles_text(eigenvalues)}] not all in the open left "
                                 "half-plane; F = M - L C must be Hurwitz (x_tilde' = F x_tilde, (6))")
        return values["L"], False
    poles = _complex_poles(values["poles"])
    unstable = poles[poles.real >= 0]
    if unstable.size:
        raise ParameterError(f"poles: {poles_text(unstable)} not in the open left half-plane; F = M - L C must "
                             "be Hurwitz (x_tilde' = F x_tilde, (6))")
    return uio_gain(plant["A"], plant["B"], plant["C"], r, poles), True


def _rates(values: dict, probe: UIOFiniteTimeObserver):
    """The extension rates of the four stages: given ones, the defaults for the others (None: all default)."""
    given = [f"rates{k}" in values["given"] for k in range(1, 5)]
    if not any(given):
        return None
    return [values[f"rates{k}"] if given[k - 1] else probe.rates[k - 1] for k in range(1, 5)]


def _settings(values: dict, rates=None) -> UIOSettings:
    return UIOSettings(
        lambdas=(values["lambda1"], values["lambda2"], values["lambda3"]), gamma=tuple(values["gamma"]),
        mu=values["mu"], rates=rates, settle_tol=values["settle_tol"], settle_window=values["settle_window"],
        t_identify=values["t_identify"], normalize=values["normalize"], filter_order=values["filter_order"],
        converged_tolerance=values["converged_tolerance"], decay_rate=values["decay_rate"])


def _define_observer(model_name: str, values: dict, context: Context) -> list:
    name = values["plant"]
    gamma = np.asarray(values["gamma"], dtype=float)
    if np.any(gamma <= 0):
        stage = int(np.argmax(gamma <= 0)) + 1
        raise ParameterError(f"gamma: entry {stage} (stage {stage}) is {gamma[stage - 1]:g}; every FT-DREM gain "
                             "must be > 0")
    plant = _plant_of(values, context)
    N = _harmonics(values, plant, name)
    r = _order(values, plant, name)
    L, designed = _gain(values, plant, r)
    n = plant["A"].shape[0]
    m = np.shape(plant["H"])[1]
    B_bar = plant["B"] / float(plant["B"] @ plant["B"]) if values["B_bar"] is None else values["B_bar"]
    xi0_free = np.ones(m) if values["xi0_free"] is None else values["xi0_free"]
    xi0_known = np.zeros(m) if values["xi0_known"] is None else values["xi0_known"]
    z0 = np.zeros(n) if values["z0"] is None else values["z0"]
    arguments = (plant["A"], plant["B"], plant["C"], r, L, plant["H"], B_bar, z0, xi0_free, xi0_known)
    probe = UIOFiniteTimeObserver(*arguments, N, _settings(values), plant["Gamma"])   # checks every value
    if designed:
        require_bounded_transient("poles", probe.design.F)
    context.rate(np.linalg.eigvals(probe.design.F), "eig(F)")
    context.rate(probe.lambdas, "lambdas (filter rates)")
    definition = uio_observer_definition(model_name, *arguments, harmonics=N,
                                         settings=_settings(values, _rates(values, probe)), Gamma=plant["Gamma"],
                                         description=values["description"])
    d = probe.design
    context.notes.append(f"{context.prefix.rstrip('.')}: r = {r}, G = {matrix_text(d.G)}, L = {matrix_text(L)}; "
                         f"eig(F) = [{poles_text(np.linalg.eigvals(d.F))}]")
    _check_identifiable(probe, plant, values, context, definition)
    return [definition]


# ------------------------------------------------------------------ identifiability in the file's experiment
def _check_identifiable(probe: UIOFiniteTimeObserver, plant: dict, values: dict, context: Context,
                        definition) -> None:
    """Stage 2 along the file's own experiment (:mod:`observers.uio.identifiability`): refused, or with
    ``check = false`` built with the finding in the FMU's log."""
    where = context.prefix.rstrip(".")
    if context.stop_time is None:
        context.notes.append(f"{where}: identifiability not checked (no experiment stop_time)")
        return
    inputs = {"plant": plant, "observer": {k: v for k, v in values.items() if k not in ("description", "check")},
              "stop_time": context.stop_time}
    problem = remembered("checks", check_key(inputs, _CHECK_SOURCES),          # a list in JSON
                         lambda: _stage_two_problem(probe, plant, values, context.stop_time))
    refuse_or_warn(problem, values, context, definition)


#: the code the verdict of the check depends on (its sources are part of the cache key)
_CHECK_SOURCES = ("observers/uio", "observers/estimation", "plants/uio.py", "fmus/system/uio_types.py")


def _stage_two_problem(probe, plant: dict, values: dict, stop_time: float) -> tuple[str, str] | None:
    """``(field, message)`` of what keeps stage 2 from identifying its unknowns in the experiment, or None."""
    arrays = {key: plant[key] for key in ("A", "B", "C", "H", "Gamma", "xi0", "x0", "amplitude", "omega", "phase")}
    rate = max(np.max(np.abs(np.linalg.eigvals(plant["A"] + np.outer(plant["B"], plant["H"] @ plant["xi0"])))),
               float(np.max(plant["omega"])))
    found = stage_two_excitation(probe, DisturbedLTVPlant(**arrays), stage_two_truth(plant["xi0"], plant["omega"],
                                 probe.free), stop_time, rate, np.pi / 4 / float(np.max(plant["omega"])))
    labels = stage_two_labels(probe.free, probe.harmonics)
    unknowns = f"stage 2's {len(labels)} unknowns [{', '.join(labels)}]"
    zeros = (f" and the part of x_tilde(0) along the plant's invariant zeros [{poles_text(found.zeros)}], which stage 1 "
             "cannot see" if found.zeros.size else "")
    exact = (f"regression (17) is exact (to {EXACT_LEVEL:g}) from t = {found.window[0]:.3g} s on (its error decays "
             f"with the filters lambda2, lambda3{zeros})")
    if not found.exact_part:
        return "plant", (f"the file's experiment cannot identify {unknowns}: regression (17) is not exact before its "
                         f"stop_time = {stop_time:g} s (its error, which decays with the filters lambda2, lambda3{zeros}, "
                         f"is still {found.residual:.1e} of the signals at the end); give a longer experiment")
    if 0 <= found.ratio < RANK_TOLERANCE:
        weights = np.abs(found.null)
        involved = [labels[j] for j in np.argsort(-weights) if weights[j] > 0.1 * weights.max()]
        known = [name for name in involved if name.startswith("xi0[")]
        return "xi0_free", (f"in the file's experiment {unknowns} cannot all be identified: {exact}, and there its "
                            f"rows have rank < {len(labels)} (s_min / s_max = {found.ratio:.1e}): "
                            f"{', '.join(sorted(involved, key=labels.index))} cannot be separated (in steady state y "
                            f"is a sum of {probe.harmonics} sinusoid(s), {2 * probe.harmonics} dimensions: the unknowns "
                            "rest on the plant's own transient)"
                            + (f"; make {' or '.join(known)} known (xi0_free, xi0_known)" if known else ""))
    if found.exponent < ENOUGH_EXCITATION:
        needed = ENOUGH_EXCITATION / found.integral if found.integral > 0 else np.inf
        return "gamma", (f"in the file's experiment stage 2 is barely excited where it counts: {exact}, and over "
                         f"[{found.window[0]:.3g}, {stop_time:g}] s gamma[2] int Delta^2 = {found.exponent:.2g} < "
                         f"{ENOUGH_EXCITATION:g}, so {unknowns} keep the error of the transient (a wrong value that "
                         f"looks identified); it would take gamma[2] >= {needed:.1e}, or a plant transient that "
                         f"outlasts {found.window[0]:.3g} s")
    return None


register("uio-ftdrem-observer", "Observer of paper 003 (unknown-input observer + finite-time DREM) for an "
         f"`{PLANT_KIND}` component whose generator `Gamma` is bounded (zero: constant theta; e.g. a rotation "
         "[[0, w], [-w, 0]]): from `y` alone, `x_tilde(0)` (stage 1), the free entries of "
         "`xi(0)` and the frequencies (stage 2), the amplitudes of `f` (stage 3), the state (stage 4). Designed from "
         "the plant's A, B, C, H, Gamma: give `poles` (eig(F)) or `L`. Input `y`; outputs `x_hat`, `x_tilde0_hat`, "
         "`xi0_hat`, `theta_hat`, `omega_hat`, `f_hat`, `identified`, `t_identified`, `excitation`, `converged`.", (
             Field("plant", "component", f"the {PLANT_KIND} component it observes (its A, B, C, H, Gamma are known)",
                   example='"plant"'),
             Field("r", "integer", "relative degree (absent: the plant's; given: checked, C A^k B = 0 for "
                   "k < r - 1 and rank C A^(r-1) B = rank B)", None, example="2"),
             Field("poles", "poles", "eig(F), F = M - L C (n of them; n - #zeros when r < n: the plant's zeros "
                   "stay eigenvalues of F)", None, "1/s", "[-0.5, -0.3]"),
             Field("L", "vector", "the gain of (2) itself (n entries), instead of poles", None,
                   example="[0.4, 0.075]"),
             Field("B_bar", "vector", "row with B_bar B = 1, picks the row of (16) (absent: B / |B|^2)", None,
                   example="[1, 1]"),
             Field("z0", "vector", "initial state z_r(0) of the chain (7) (absent: zero)", None, example="[-3, 3]"),
             Field("harmonics", "integer", "number N of sinusoids of f (absent: the plant's; Assumption 1)", None,
                   example="1"),
             Field("xi0_free", "vector", "per entry of xi(0): 1 estimate it, 0 known (absent: all estimated)", None,
                   example="[0, 1]"),
             Field("xi0_known", "vector", "values of the known entries of xi(0) (absent: zero)", None,
                   example="[0, 0]"),
             Field("lambda1", "number", "rate of the filter of (10)", _DEFAULTS.lambdas[0], "1/s", "10"),
             Field("lambda2", "number", "rate of the filters of (14)", _DEFAULTS.lambdas[1], "1/s", "10"),
             Field("lambda3", "number", "rate of the filters of (17)", _DEFAULTS.lambdas[2], "1/s", "10"),
             Field("filter_order", "integer", "order of the filter of (14), >= r (absent: r + 1)", None,
                   example="3"),
             Field("gamma", "vector", "FT-DREM gains of stages 1-4 (4 entries)", list(_DEFAULTS.gamma), "",
                   "[1e6, 1e8, 1e6, 1e6]"),
             Field("mu", "number", "FT-DREM switching level in (0, 1)", _DEFAULTS.mu, "", "0.98"),
             *(Field(f"rates{k}", "vector", f"extension filter rates a_i of the stage-{k} DREM (one fewer than its "
                     "unknowns; absent: lambda1 / (1, 2, ...))", None, "1/s", "[10, 5]") for k in range(1, 5)),
             Field("normalize", "boolean", "row-normalise the DREM mixing (false: the paper's raw det)",
                   _DEFAULTS.normalize, example="false"),
             Field("settle_tol", "number", "relative tolerance of the identification test of stages 2-4",
                   _DEFAULTS.settle_tol, "", "1e-6"),
             Field("settle_window", "number", "quiet window of the identification test", _DEFAULTS.settle_window,
                   "s", "0.5"),
             Field("t_identify", "number", "a stage still running this long after its start is stopped",
                   _DEFAULTS.t_identify, "s", "10"),
             Field("converged_tolerance", "number", "converged = 1 once the bound on the error of every stage is "
                   "at most this", _DEFAULTS.converged_tolerance, "", "1e-3"),
             Field("decay_rate", "number", "sigma, a lower bound on the decay rate of the errors of stages 2-4 "
                   "(absent: the slowest filter pole)", None, "1/s", "0.3"),
             CHECK_FIELD,
         ), _define_observer, depends=("plant",))
