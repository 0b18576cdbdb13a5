"""Kinds for paper 003: the disturbed LTV plant and the UIO + finite-time DREM observer.

* ``ltv-disturbed-plant`` -- :class:`plants.uio.DisturbedLTVPlant`: no inputs;
  outputs ``y``, ``x``, ``theta``, ``xi``, ``f``.  The disturbance (``amplitude``,
  ``omega``, ``phase``, one entry per sinusoid), ``x0``, ``xi0`` and the
  measurement noise are parameters (``--set plant.omega=2``).
* ``uio-ftdrem-observer`` -- :class:`observers.uio.UIOFiniteTimeObserver`: input
  ``y``; outputs ``x_hat``, ``x_tilde0_hat``, ``xi0_hat``, ``theta_hat``,
  ``omega_hat``, ``f_hat``, ``identified[1..4]``, ``t_identified[1..4]``.  The
  number of sinusoids is fixed when the FMU is built (it sizes ports);
  ``r`` and every gain are parameters.
"""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError
from obsfmu.observers.integrators import DEFAULT_SUBSTEP_BUDGET
from obsfmu.observers.uio import UIOFiniteTimeObserver, UIOSettings
from obsfmu.plants.uio import DisturbedLTVPlant
from obsfmu.plants.signals import SampledNoise

from ..definition import FmuDefinition, Parameter, Port
from . import register
from .diagnostics import UIO_CONTRACT, contract_parameters, contract_ports, contract_values

__all__ = ["ltv_plant_definition", "uio_observer_definition"]


def _integer(p, name: str) -> int:
    value = float(p[name])
    if value != int(value):
        raise ParameterError(f"{name}: expected an integer, got {value:g}")
    return int(value)


@register("ltv-disturbed-plant")
def _plant(p, options):
    noise = None
    if float(p["noise_std"]) != 0.0:
        noise = SampledNoise(float(p["noise_std"]), float(p["noise_dt"]), float(p["noise_seed"]))
    return DisturbedLTVPlant(p["A"], p["B"], p["C"], p["H"], p["Gamma"], p["xi0"], p["x0"],
                             p["amplitude"], p["omega"], p["phase"], noise,
                             p.get("substep_budget", DEFAULT_SUBSTEP_BUDGET))


@register("uio-ftdrem-observer")
def _observer(p, options):
    order = _integer(p, "filter_order")
    settings = UIOSettings(
        lambdas=(p["lambda1"], p["lambda2"], p["lambda3"]), gamma=p["gamma"], mu=p["mu"],
        rates=[p[f"rates{k}"] for k in range(1, 5)], settle_tol=p["settle_tol"],
        settle_window=p["settle_window"], t_identify=p["t_identify"], normalize=bool(float(p["normalize"])),
        filter_order=None if order == 0 else order,
        substep_budget=p.get("substep_budget", DEFAULT_SUBSTEP_BUDGET),
        **dict(zip(("converged_tolerance", "decay_rate"), contract_values(p, UIO_CONTRACT))))
    return UIOFiniteTimeObserver(p["A"], p["B"], p["C"], _integer(p, "r"), p["L"], p["H"], p["B_bar"], p["z0"],
                                 p["xi0_free"], p["xi0_known"], int(options["harmonics"]), settings, Gamma=p["Gamma"])


def _sines(name: str, value, text: str, unit=None) -> Parameter:
    value = np.asarray(value, dtype=float).ravel()
    return Parameter.of(name, value, text, unit, drop_axes=(0,))


def ltv_plant_definition(model_name: str, A, B, C, H, Gamma, xi0, x0, amplitude, omega, phase, *,
                         noise_std=0.0, noise_dt=1e-3, noise_seed=0, description: str = "") -> FmuDefinition:
    """Plant FMU of paper 003 (kind ``ltv-disturbed-plant``); ``len(amplitude)`` sinusoids."""
    A = np.asarray(A, dtype=float)
    n, m = A.shape[0], np.asarray(H, dtype=float).shape[1]
    return FmuDefinition(
        model_name=model_name,
        kind="ltv-disturbed-plant",
        description=description or ("x' = A x + B [theta^T x + f(t)], y = C x + noise, theta = H xi, "
                                    "xi' = Gamma xi, f = sum amplitude sin(omega t + phase) (paper 003, eq. (1))"),
        parameters=[
            Parameter.of("A", A, "state matrix"),
            Parameter.of("B", np.reshape(B, (n, 1)), "input vector (theta^T x + f enters through B)", drop_axes=(1,)),
            Parameter.of("C", np.reshape(C, (1, n)), "output row, y = C x", drop_axes=(0,)),
            Parameter.of("H", np.reshape(H, (n, m)), "theta = H xi"),
            Parameter.of("Gamma", np.reshape(Gamma, (m, m)), "generator of the parameters, xi' = Gamma xi"),
            Parameter.of("xi0", xi0, "initial generator state xi(0)"),
            Parameter.of("x0", x0, "initial state x(0)"),
            _sines("amplitude", amplitude, "amplitudes of the sinusoids of f"),
            _sines("omega", omega, "angular frequencies of the sinusoids of f", "rad/s"),
            _sines("phase", phase, "phases of the sinusoids of f", "rad"),
            Parameter.scalar("noise_std", noise_std, "standard deviation of the sample-and-hold measurement noise on y"),
            Parameter.scalar("noise_dt", noise_dt, "hold interval of the noise", "s"),
            Parameter.scalar("noise_seed", noise_seed, "seed of the noise (a non-negative integer)"),
            Parameter.substep_budget(),
        ],
        inputs=[],
        outputs=[
            Port("y", 1, "measured output y = C x (+ noise)", scalar=True),
            Port("x", n, "true state x"),
            Port("theta", n, "true parameters theta = H xi"),
            Port("xi", m, "true generator state xi"),
            Port("f", 1, "true disturbance f", scalar=True),
            Port("f_omega", np.size(amplitude), "angular frequencies of f (constant)", "rad/s",
                 scalar=np.size(amplitude) == 1),
        ],
    )


def uio_observer_definition(model_name: str, A, B, C, r, L, H, B_bar, z0, xi0_free, xi0_known, *,
                            harmonics: int = 1, settings: UIOSettings | None = None, Gamma=None,
                            description: str = "") -> FmuDefinition:
    """Observer FMU of paper 003 (kind ``uio-ftdrem-observer``); the block checks every value.

    ``Gamma``: the known generator of ``theta`` (absent: zero, constant ``theta``)."""
    s = settings or UIOSettings()
    A = np.asarray(A, dtype=float)
    n, m = A.shape[0], np.asarray(H, dtype=float).shape[1]
    N = int(harmonics)
    Gamma = np.zeros((m, m)) if Gamma is None else Gamma
    probe = UIOFiniteTimeObserver(A, B, C, r, L, H, B_bar, z0, xi0_free, xi0_known, N, s, Gamma)   # fails early
    return FmuDefinition(
        model_name=model_name,
        kind="uio-ftdrem-observer",
        description=description or ("paper 003: unknown-input observer + finite-time DREM; estimates x, "
                                     "xi(0), omega and f from y alone"),
        parameters=[
            Parameter.of("A", A, "plant state matrix"),
            Parameter.of("B", np.reshape(B, (n, 1)), "plant input vector", drop_axes=(1,)),
            Parameter.of("C", np.reshape(C, (1, n)), "plant output row", drop_axes=(0,)),
            Parameter.scalar("r", r, "relative degree (C A^k B = 0 for k < r - 1, rank C A^(r-1) B = rank B)"),
            Parameter.of("L", np.reshape(L, (n, 1)), "gain of (2): F = M - L C must be Hurwitz", drop_axes=(1,)),
            Parameter.of("H", np.reshape(H, (n, m)), "theta = H xi"),
            Parameter.of("Gamma", np.reshape(Gamma, (m, m)), "known generator xi' = Gamma xi (0: constant theta)"),
            Parameter.of("B_bar", np.reshape(B_bar, (1, n)), "row with B_bar B = 1 (row of (16))", drop_axes=(0,)),
            Parameter.of("z0", z0, "initial state z_r(0) of the chain (7)"),
            Parameter.of("xi0_free", xi0_free, "1: estimate this entry of xi(0), 0: known"),
            Parameter.of("xi0_known", xi0_known, "values of the known entries of xi(0)"),
            Parameter.scalar("lambda1", s.lambdas[0], "rate of the filter of (10)", "1/s"),
            Parameter.scalar("lambda2", s.lambdas[1], "rate of the filter of (14)", "1/s"),
            Parameter.scalar("lambda3", s.lambdas[2], "rate of the filter of (17)", "1/s"),
            Parameter.scalar("filter_order", 0 if s.filter_order is None else s.filter_order,
                   "order of the filter of (14), >= r; 0: r + 1"),
            Parameter.of("gamma", np.asarray(s.gamma, dtype=float), "FT-DREM gains of stages 1-4"),
            Parameter.scalar("mu", s.mu, "FT-DREM switching level in (0, 1)"),
        ] + [Parameter.of(f"rates{k + 1}", rates, f"extension filter rates of the stage-{k + 1} DREM", "1/s")
             for k, rates in enumerate(probe.rates)] + [
            Parameter.scalar("normalize", float(s.normalize), "1: row-normalise the DREM mixing, 0: raw det"),
            Parameter.scalar("settle_tol", s.settle_tol, "relative tolerance of the identification test"),
            Parameter.scalar("settle_window", s.settle_window, "quiet window of the identification test", "s"),
            Parameter.scalar("t_identify", s.t_identify, "a stage still running this long after its start is stopped", "s"),
            Parameter.substep_budget(s.substep_budget),
        ] + contract_parameters(UIO_CONTRACT, converged_tolerance=s.converged_tolerance,
                                decay_rate=s.decay_rate or probe.decay_rate),
        inputs=[Port("y", 1, "measured output y", scalar=True)],
        outputs=[
            Port("x_hat", n, "state estimate"),
            Port("x_tilde0_hat", n, "stage 1: estimate of x_tilde(0), the initial error of the UIO (8)"),
            Port("xi0_hat", m, "stage 2: estimate of xi(0)"),
            Port("theta_hat", n, "estimate of theta = H e^(Gamma t) xi(0)"),
            Port("omega_hat", N, "stage 2: frequencies of f", "rad/s", scalar=N == 1),
            Port("f_hat", 1, "stage 3: disturbance estimate, (23)", scalar=True),
            Port("identified", 4, "per stage (x_tilde0, xi0/omega, amplitudes, state): 0 running, "
                                  "1 identified, 2 stopped at t_identify without settling"),
            Port("t_identified", 4, "time each stage was identified (-1 before)", "s"),
        ] + contract_ports(UIO_CONTRACT),
        options={"harmonics": N},
    )
