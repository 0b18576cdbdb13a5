"""Kinds for paper 004: the DREM observer for state-affine forms and its two example plants.

* ``state-affine-observer`` -- :class:`~observers.state_affine.StateAffineObserver`; the user's
  functions are ``"module:function"`` references or expression functions (:mod:`fmus.runtime.functions`,
  the system file's ``state-affine-observer``) in the definition's options (resolved with
  :func:`fmus.runtime.callables.resolve`, never evaluated); a constant ``Lambda`` (Statement 2) and its
  ``C``, ``L`` are parameters, checked when the FMU is instantiated (observability of
  ``(Lambda, C)``, bounded filters).
* ``state-affine-pendulum``, ``state-affine-chemostat`` -- the example plants of
  :mod:`plants.state_affine`.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET
from obsfmu.observers.state_affine import StateAffineModel, StateAffineObserver
from obsfmu.observers.state_affine.observer import SUBSTEP_BUDGET
from obsfmu.plants.state_affine import Chemostat, Pendulum

from ..callables import resolve
from ..definition import FmuDefinition, Parameter, Port
from . import register
from .diagnostics import FT_DREM_CONTRACT, contract_parameters, contract_ports, contract_values

__all__ = ["FUNCTIONS", "observer_definition", "pendulum_definition", "chemostat_definition"]

#: the user's functions of a model, in the order of the paper: (2), (3), left inverse
FUNCTIONS = ("Lambda", "Psi", "w", "phi", "c", "phi_L")
DIMENSIONS = ("q", "p", "l", "n", "ny", "nu")


@register("state-affine-observer")
def _observer(p, options):
    functions = {name: resolve(options[name], name) for name in FUNCTIONS if options.get(name)}
    constant = "Lambda" not in functions
    model = StateAffineModel(
        **{name: int(options[name]) for name in DIMENSIONS},
        Lambda=p["Lambda"] if constant else functions["Lambda"],
        Psi=functions.get("Psi"), w=functions.get("w"), phi=functions.get("phi"), c=functions.get("c"),
        phi_L=functions.get("phi_L"), C=p["C"] if constant else None, L=p["L"] if constant else None)
    return StateAffineObserver(model, p["rates"], float(p["gamma"]), float(p["gamma_x"]), float(p["mu"]),
                               p["chi_hat0"], p.get("theta_hat0"), float(p["max_substep"]),
                               p.get("substep_budget", SUBSTEP_BUDGET), *contract_values(p, FT_DREM_CONTRACT))


def _budget(p):
    return p.get("substep_budget", DEFAULT_SUBSTEP_BUDGET)


def observer_definition(model_name: str, *, dims: dict[str, int], functions: dict[str, str | dict], rates,
                        gamma: float, gamma_x: float, mu: float = 0.98, max_substep: float, chi_hat0=None,
                        theta_hat0=None, Lambda=None, C=None, L=None, units: dict | None = None,
                        converged_tolerance: float = 1e-3, theta_bound: float = 100.0,
                        description: str = "") -> FmuDefinition:
    """Observer FMU of paper 004.

    Parameters
    ----------
    dims : dict
        ``q, p, l, n, ny, nu`` (see :class:`~observers.state_affine.StateAffineModel`).
    functions : dict
        ``"module:function"`` references or expression functions
        (:func:`fmus.runtime.functions.expression_function`) for ``Psi`` (if ``p > 0``), ``w``,
        ``phi``, ``c``, ``phi_L`` and, for Statement 1, ``Lambda``.
    Lambda, C, L : array_like, optional
        Statement 2: the constant ``Lambda`` (q x q), ``y = C chi`` and the gain ``L``; they
        become parameters ``Lambda[i,j]``, ``C[..]``, ``L[..]``.
    units : dict, optional
        ``y``, ``u`` (one unit or a list), ``x`` (list of n), ``theta`` (list of l + p),
        ``time`` (the unit of time, default ``"s"``, used for rates and gains).
    """
    units = units or {}
    q, p, l, n, ny, nu = (int(dims[name]) for name in DIMENSIONS)
    missing = [name for name in ("w", "phi", "c", "phi_L") + (("Psi",) if p else ()) if name not in functions]
    if missing:
        raise ValueError(f"functions: missing {', '.join(missing)}")
    unknown = sorted(set(functions) - set(FUNCTIONS))
    if unknown:
        raise ValueError(f"functions: unknown {', '.join(unknown)}; expected some of {', '.join(FUNCTIONS)}")
    if ("Lambda" in functions) == (Lambda is not None):
        raise ValueError("Lambda: give either a function reference (Statement 1) or a constant matrix (Statement 2)")
    time_unit = units.get("time", "s")
    rate = f"1/{time_unit}"
    parameters = [
        Parameter.of("rates", rates, "filter rates a_i of a_i/(p + a_i), one per filtered copy of (4)/(5)", rate),
        Parameter.of("gamma", gamma, "gain of the finite-time gradient estimator (rate gamma Delta^2)", rate),
        Parameter.of("gamma_x", gamma_x, "gain of the correction term of Statement 3 (rate gamma_x Delta^2)", rate),
        Parameter.of("mu", mu, "switching level of the finite-time estimate, in (0, 1)"),
        Parameter.of("max_substep", max_substep, "longest internal integration step", time_unit),
        Parameter.substep_budget(SUBSTEP_BUDGET),
        Parameter.of("chi_hat0", np.zeros(q) if chi_hat0 is None else chi_hat0,
                     "initial estimate chi_hat(0) of the image chi = phi(x) (the observer's state)"),
    ] + contract_parameters(FT_DREM_CONTRACT, converged_tolerance=converged_tolerance, theta_bound=theta_bound)
    if l + p:
        parameters.append(Parameter.of("theta_hat0", np.zeros(l + p) if theta_hat0 is None else theta_hat0,
                                       "initial estimate of col(theta_l, theta_p)", units.get("theta")))
    if Lambda is not None:
        parameters += [
            Parameter.of("Lambda", Lambda, "constant Lambda of chi' = Lambda chi + Psi theta_p + w (Statement 2)"),
            Parameter.of("C", C, "output matrix of y = C chi (Statement 2)", drop_axes=(0,)),
            Parameter.of("L", L, "injection gain: filters use Lambda - L C (Statement 2)", drop_axes=(1,)),
        ]
    outputs = [Port("x_hat", n, "state estimate x_hat = phi_L(chi_hat, theta_hat)", units.get("x"))]
    if l + p:
        outputs.append(Port("theta_hat", l + p, "finite-time estimate of col(theta_l, theta_p)", units.get("theta")))
    outputs += [Port("chi_hat", q, "estimate of chi = phi(x)"),
                Port("Delta", 1, "Delta = det of the row-normalised extended regressor", scalar=True),
                Port("nu", 1, "nu of the finite-time estimator (theta_hat exact once nu < mu)", scalar=True)] \
        + contract_ports(FT_DREM_CONTRACT)
    return FmuDefinition(
        model_name=model_name,
        kind="state-affine-observer",
        description=description or "DREM adaptive observer for a state-affine form (paper 004, Statements 1-3)",
        parameters=parameters,
        inputs=[Port("y", ny, "measured output y", units.get("y"), scalar=ny == 1),
                Port("u", nu, "plant input u", units.get("u"), scalar=nu == 1)],
        outputs=outputs,
        options={**{name: int(dims[name]) for name in DIMENSIONS}, **dict(functions)},
    )


@register("state-affine-pendulum")
def _pendulum(p, options):
    return Pendulum(p["a"], p["b"], p["x0"], substep_budget=_budget(p))


def pendulum_definition(model_name: str, a: float, b: float, x0) -> FmuDefinition:
    """Pendulum plant FMU (:class:`plants.state_affine.Pendulum`)."""
    return FmuDefinition(
        model_name=model_name,
        kind="state-affine-pendulum",
        description="pendulum phi'' = -a sin(phi) - b phi' + u measured in angle (paper 004 example)",
        parameters=[Parameter.of("a", a, "gravity coefficient g/l (unknown to the observer)", "1/s2"),
                    Parameter.of("b", b, "viscous friction coefficient (unknown to the observer)", "1/s"),
                    Parameter.of("x0", x0, "initial state (angle, angular velocity)", ["rad", "rad/s"]),
                    Parameter.substep_budget()],
        inputs=[Port("u", 1, "torque / (m l^2)", "rad/s2", scalar=True)],
        outputs=[Port("y", 1, "measured angle", "rad", scalar=True),
                 Port("x", 2, "true state (angle, angular velocity)", ["rad", "rad/s"]),
                 Port("theta", 2, "true unknown parameters (b, a), for comparison", ["1/s", "1/s2"])],
    )


@register("state-affine-chemostat")
def _chemostat(p, options):
    return Chemostat(p["S_in"], p["x0"], substep_budget=_budget(p))


def chemostat_definition(model_name: str, S_in: float, x0) -> FmuDefinition:
    """Chemostat plant FMU (:class:`plants.state_affine.Chemostat`); time in hours."""
    return FmuDefinition(
        model_name=model_name,
        kind="state-affine-chemostat",
        description="chemostat X' = mu(S) X - D X, S' = -k mu(S) X + D (S_in - S), y = S; time in hours "
                    "(paper 004 example)",
        parameters=[Parameter.of("S_in", S_in, "feed substrate concentration (unknown to the observer)", "g/L"),
                    Parameter.of("x0", x0, "initial state (biomass X, substrate S)", "g/L"),
                    Parameter.substep_budget()],
        inputs=[Port("u", 1, "dilution rate D", "1/h", scalar=True)],
        outputs=[Port("y", 1, "measured substrate concentration S", "g/L", scalar=True),
                 Port("x", 2, "true state (biomass X, substrate S)", "g/L"),
                 Port("theta", 1, "true unknown parameter S_in, for comparison", "g/L")],
    )
