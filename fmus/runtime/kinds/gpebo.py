"""Kinds for paper 000: the generator-driven discrete plant and the GPEBO + DREM observer.

Both are *discrete* blocks updated at the instants ``t_k = k Ts`` (the parameter ``Ts``), whatever the
communication step (:class:`observers.sampling.SampledBlock`): several samples in a long step, none in
a short one, the state held in between; each input is taken at ``t_k``, ``u(k) = u(t_k)`` -- its value
at the step start when ``t_k`` is a communication point (their DefaultExperiment steps one ``Ts``).  Under
``hold`` (0) the value set before ``doStep`` is used, so the producer must not have stepped yet (Jacobi
order, or Gauss-Seidel with the producer after this FMU).
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.gpebo import GeneratorModel, GpeboObserver
from obsfmu.plants.gpebo import EXAMPLE, GeneratorPlant

from ..callables import resolve
from ..definition import FmuDefinition, Parameter, Port
from . import register
from .diagnostics import GPEBO_CONTRACT, contract_parameters, contract_ports, contract_values

__all__ = ["generator_plant_definition", "gpebo_observer_definition"]

_SAMPLING = ("sampled at t = k Ts whatever the communication step (state held between samples); "
             "inputs are taken at the instants, u(k) = u(k Ts)")


@register("generator-plant")
def _generator_plant(p, options):
    return GeneratorPlant(_model(p, options, p["x0"].size), p["gamma_beta"], p["gamma_theta"], p["xi_beta0"], p["xi_theta0"], p["x0"],
                          float(p["Ts"]), p.get("gamma_delta", ()), p.get("xi_delta0", ()))


def _model(p, options, n: int) -> GeneratorModel:
    """The known structure (1)-(2) from the parameters ``h_beta``, ``H_theta``, ``H_delta`` and the option ``f``."""
    return GeneratorModel.checked(n, p["h_beta"], p["H_theta"], p.get("H_delta"), resolve(options["f"], "f"))


@register("gpebo-observer")
def _gpebo_observer(p, options):
    return GpeboObserver(_model(p, options, p["x_hat0"].size), float(p["Ts"]), float(p["k_gamma"]),
                         float(p["k_eta"]), p["gamma_hat0"], p["eta_hat0"], p["x_hat0"],
                         float(p["restart_tol"]), float(p["excitation_tol"]), *contract_values(p, GPEBO_CONTRACT),
                         consistency_tol=float(p["consistency_tol"]), gamma_unknown=options.get("gamma_unknown"))


def _scalar(name, value, description, unit=None) -> Parameter:
    return Parameter.of(name, np.array(value, dtype=float), description, unit)


def _structure(h_beta, H_theta, H_delta) -> list[Parameter]:
    """The known output maps of the generators: ``beta = h_beta xi_beta``, ``theta = H_theta xi_theta``, ..."""
    parameters = [
        Parameter.of("h_beta", h_beta, "output row of the beta generator, beta = h_beta xi_beta"),
        Parameter.of("H_theta", H_theta, "output matrix of the theta generator, theta = H_theta xi_theta"),
    ]
    if H_delta is not None:
        parameters.append(Parameter.of("H_delta", H_delta,
                                       "output matrix of the delta generator, delta = H_delta xi_delta"))
    return parameters


def generator_plant_definition(model_name: str, *, gamma_beta=EXAMPLE["gamma_beta"],
                               gamma_theta=EXAMPLE["gamma_theta"], xi_beta0=EXAMPLE["xi_beta0"],
                               xi_theta0=EXAMPLE["xi_theta0"], x0=EXAMPLE["x0"], h_beta=EXAMPLE["h_beta"],
                               H_theta=EXAMPLE["H_theta"], gamma_delta=None, xi_delta0=None, H_delta=None,
                               Ts: float = 1.0, f: str = "plants.gpebo:sine",
                               description: str = "") -> FmuDefinition:
    """Plant (1)-(2) of paper 000 for any ``n`` (``len(x0)``) and generator sizes; defaults: the example.

    ``gamma_delta``, ``xi_delta0``, ``H_delta`` (all or none) add the disturbance generator.
    """
    x0 = np.asarray(x0, dtype=float)
    n = x0.size
    parameters = [
        _scalar("Ts", Ts, "sample period: the block samples at t = k Ts", "s"),
        Parameter.of("gamma_beta", gamma_beta, "coefficients of Gamma_beta = Gamma0 + gamma_beta e1^T"),
        Parameter.of("gamma_theta", gamma_theta, "coefficients of Gamma_theta = Gamma0 + gamma_theta e1^T"),
        Parameter.of("xi_beta0", xi_beta0, "initial state of the beta generator"),
        Parameter.of("xi_theta0", xi_theta0, "initial state of the theta generator"),
    ] + _structure(h_beta, H_theta, H_delta)
    outputs = [Port("y", 1, "measured output y = x1", scalar=True), Port("x", n, "true state x"),
               Port("beta", 1, "input gain beta(k) = h_beta xi_beta(k)", scalar=True),
               Port("theta", n, "coefficients theta(k) = H_theta xi_theta(k) of f(y)")]
    if gamma_delta is not None:
        parameters += [
            Parameter.of("gamma_delta", gamma_delta, "coefficients of Gamma_delta = Gamma0 + gamma_delta e1^T"),
            Parameter.of("xi_delta0", xi_delta0, "initial state of the delta generator"),
        ]
        outputs.append(Port("delta", n, "disturbance delta(k) = H_delta xi_delta(k)"))
    parameters.append(Parameter.of("x0", x0, "initial state x(0)"))
    return FmuDefinition(
        model_name=model_name,
        kind="generator-plant",
        description=description or (f"paper 000 discrete plant x(k+1) = A x(k) + e_n beta(k) u(k) + theta(k) "
                                     f"f(y(k)) + delta(k), y = x1, generators xi(k+1) = Gamma xi(k); {_SAMPLING}"),
        parameters=parameters,
        inputs=[Port("u", 1, "plant input u(k), taken at the step start", scalar=True)],
        outputs=outputs,
        options={"f": f},
    )


def _observer_options(f, gamma_unknown) -> dict:
    """``f``, and ``gamma_unknown`` only where a whole ``gamma`` is unknown (today's FMUs unchanged)."""
    if gamma_unknown is None or all(form == "last" for form in gamma_unknown):
        return {"f": f}
    return {"f": f, "gamma_unknown": list(gamma_unknown)}


def gpebo_observer_definition(model_name: str, *, Ts: float = 1.0, k_gamma: float = 1e-8, k_eta: float = 1e-8,
                              gamma_hat0=(-0.5, 0.5), eta_hat0=None, x_hat0=None, restart_tol: float = 1e-11,
                              excitation_tol: float = 1e-9, converged_tolerance: float = 1e-6,
                              theta_bound: float = 100.0, consistency_tol: float = 1e-10, f="plants.gpebo:sine", h_beta=EXAMPLE["h_beta"],
                              H_theta=EXAMPLE["H_theta"], H_delta=None, gamma_unknown=None,
                              description: str = "") -> FmuDefinition:
    """GPEBO + DREM observer of paper 000 for the structure ``h_beta``, ``H_theta``, ``H_delta``, ``f``.

    ``n`` is the number of rows of ``H_theta``, the generator sizes are ``len(h_beta)`` and the columns
    of ``H_theta``, ``H_delta``; every generator is ``gamma = [0, ..., 0, g]`` with ``g`` unknown
    (``gamma_hat0``: one initial ``g`` per generator), unless ``gamma_unknown`` ("last" | "all" per
    generator, an option of the FMU) makes a whole ``gamma`` unknown (``gamma_hat0``: one entry per
    unknown).  Defaults: the paper's example.  The observer is
    built once here, so a structure its regression cannot take is refused before the FMU exists.
    """
    H_theta = np.asarray(H_theta, dtype=float)
    n = H_theta.shape[0] if H_theta.ndim == 2 else 0
    x_hat0 = np.zeros(n) if x_hat0 is None else np.asarray(x_hat0, dtype=float)
    model = GeneratorModel.checked(x_hat0.size, h_beta, H_theta, H_delta, resolve(f, "f"))
    eta_hat0 = np.zeros(model.N) if eta_hat0 is None else eta_hat0
    names = GpeboObserver(model, Ts, k_gamma, k_eta, gamma_hat0, eta_hat0, x_hat0, restart_tol, excitation_tol,
                          converged_tolerance, theta_bound, consistency_tol, gamma_unknown).regression.names
    coefficients = ", ".join(names)
    return FmuDefinition(
        model_name=model_name,
        kind="gpebo-observer",
        description=description or ("paper 000 adaptive observer: gamma by DREM on the input-output regression, "
                                    f"eta = xi(t0) by GPEBO filters + DREM, x_hat = phi_x eta_hat; {_SAMPLING}; "
                                    "outputs are one-sample predictions from y(0..k-1)"),
        parameters=[
            _scalar("Ts", Ts, "sample period: the block samples at t = k Ts", "s"),
            _scalar("k_gamma", k_gamma, "gain k_i of Statement 2 for sigma (rows normalised, Delta^2 <= 1)"),
            _scalar("k_eta", k_eta, "gain k_i of Statement 2 for eta"),
            Parameter.of("gamma_hat0", gamma_hat0, f"initial [{coefficients}] (nonzero)"),
            Parameter.of("eta_hat0", eta_hat0, "initial [xi_beta; xi_theta](0) estimate"
                         if H_delta is None else "initial [xi_beta; xi_theta; xi_delta](0) estimate"),
            Parameter.of("x_hat0", x_hat0, "initial estimate x_hat(0)"),
            _scalar("restart_tol", restart_tol, "relative change of gamma_hat that restarts the GPEBO filters"),
            _scalar("excitation_tol", excitation_tol, "excited = 1 once nu_gamma and nu_eta are below this"),
        ] + contract_parameters(GPEBO_CONTRACT, converged_tolerance=converged_tolerance, theta_bound=theta_bound)
        + [_scalar("consistency_tol", consistency_tol, "converged needs the a-priori relative residuals of the "
                   "last p rows of the gamma regression at most this (the bounds hold for exact data only)")]
        + _structure(h_beta, H_theta, H_delta),
        inputs=[Port("u", 1, "plant input u(k), taken at the step start", scalar=True),
                Port("y", 1, "measured output y(k), taken at the step start", scalar=True)],
        outputs=[
            Port("x_hat", n, "state estimate x_hat = phi_x eta_hat + e_hat"),
            Port("gamma_hat", len(names), f"estimate of [{coefficients}]"),
            Port("eta_hat", model.N, "estimate of eta = xi at restart_time"),
            Port("beta_hat", 1, "estimate of beta(k)", scalar=True),
            Port("theta_hat", n, "estimate of theta(k)"),
            Port("excited", 1, "1 when both regressions have been exciting (nu_gamma, nu_eta < excitation_tol), "
                               "else 0: do not trust the estimates", scalar=True),
            Port("nu_gamma", 1, "guaranteed error factor of sigma_hat: prod k/(k + Delta^2)", scalar=True),
            Port("nu_eta", 1, "guaranteed error factor of eta_hat since restart_time", scalar=True),
            Port("restart_time", 1, "time of the last restart of the GPEBO filters", "s", scalar=True),
        ] + contract_ports(GPEBO_CONTRACT),
        options=_observer_options(f, gamma_unknown),
    )
