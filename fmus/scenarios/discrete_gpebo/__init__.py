"""Scenario ``discrete-gpebo`` -- paper 000: discrete adaptive observer (GPEBO + DREM) of a generator-driven plant.

The system file ``system.toml`` beside this module (``obsfmu show discrete-gpebo``) holds every
number of the run.  Three FMUs: the signal source (``u`` sampled at the communication points,
``t = k Ts``), the discrete plant of the paper's example (``n = 2``,
``x1(k+1) = x2(k) + theta1(k) sin x1(k)``, ``x2(k+1) = beta(k) u(k)``,
``gamma_beta = -1``, ``gamma_theta = 1``; bounded, see :mod:`plants.gpebo`)
and the observer (:mod:`observers.gpebo`).  ``Ts = 1`` s, 40 samples.

The paper's three inputs (the default is the first)::

    obsfmu run discrete-gpebo                                       # u = sin t + sin 2t
    obsfmu run discrete-gpebo --set source.amplitude[1]=0 --set source.amplitude[2]=0 \\
                              --set source.offset=5                 # u = 5
    obsfmu run discrete-gpebo --set source.amplitude[1]=0 --set source.amplitude[2]=0 \\
                              --set source.exp_amplitude=1 --set source.exp_rate=0.5   # u = exp(-0.5 t)

Another plant: ``--set plant.gamma_beta[2]=-0.9 --set plant.xi_theta0[1]=0.7 --set plant.x0[2]=1``.
Another sampling period ``Ts`` must be set on both discrete FMUs and as the
step, with a stop time that is a whole number of samples, e.g. ``Ts = pi/2``::

    obsfmu run discrete-gpebo --step 1.5707963267948966 --stop-time 62.83185307179586 \\
        --set plant.Ts=1.5707963267948966 --set observer.Ts=1.5707963267948966

Step and coupling.  The plant and the observer are discrete: the step must be ``Ts`` (other steps
are refused) and every input must be its value at the step start, so the default order is Jacobi
(every block reads the values at ``t_k`` whatever the coupling).  The summary checks the recorded
plant trajectory against the model equations (``plant residual``); the orders and couplings
measured against it: ``docs/paper000.md``, section 4.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...metrics import NOT_REACHED, time_to_stay_below
from ...plotting import Curve, Panel, figure
from ...result import Result
from ...system.papers import paper_scenario
from .. import Summary
from .measures import MEASURE, TOLERANCE

SYSTEM_FILE = Path(__file__).parent / "system.toml"


def _recurrence_coefficient(signal: np.ndarray) -> float:
    """``g`` with ``s(k+2) = g s(k)`` by least squares over the record (exact for the example's generators)."""
    return float(signal[2:] @ signal[:-2] / (signal[:-2] @ signal[:-2]))


def true_gammas(result: Result) -> np.ndarray:
    """``[gamma_beta, gamma_theta]`` recovered from the recorded ``beta`` and ``theta1`` (example structure)."""
    return np.array([_recurrence_coefficient(result["plant.beta"]),
                     _recurrence_coefficient(result.vector("plant.theta")[:, 0])])


def plant_residual(result: Result) -> float:
    """Largest deviation of the recorded ``x(k+1)`` from eq. (7) with the recorded ``u(k)``, ``beta``, ``theta``."""
    x, theta = result.vector("plant.x"), result.vector("plant.theta")
    u, beta = result["source.y"], result["plant.beta"]
    f = np.sin(x[:-1, 0])
    predicted = np.column_stack([x[:-1, 1] + theta[:-1, 0] * f, beta[:-1] * u[:-1] + theta[:-1, 1] * f])
    return float(np.max(np.abs(x[1:] - predicted)))


def _samples(result: Result, time: float) -> float:
    Ts = result.time[1] - result.time[0]
    return time / Ts if np.isfinite(time) else float("inf")


def _count(samples: float) -> str:
    return f"{samples:g}" if np.isfinite(samples) else NOT_REACHED


def summarize(result: Result) -> Summary:
    gammas = true_gammas(result)
    gamma_error = result.vector("observer.gamma_hat") - gammas
    x_error = result.vector("plant.x") - result.vector("observer.x_hat")
    excited = result["observer.excited"]
    first_excited = np.nonzero(excited > 0.5)[0]
    metrics = {
        "plant_residual": plant_residual(result),
        "final_gamma_error": float(np.max(np.abs(gamma_error[-1]))),
        "final_state_error": float(np.max(np.abs(x_error[-1]))),
        "gamma_samples_to_tolerance": _samples(result, time_to_stay_below(result.time, gamma_error, TOLERANCE)),
        "state_samples_to_tolerance": _samples(result, time_to_stay_below(result.time, x_error, TOLERANCE)),
        "first_excited_sample": float(first_excited[0]) if first_excited.size else float("inf"),
        "excited_at_end": float(excited[-1]),
    }
    lines = [
        f"true gamma (from the recorded beta, theta1) = {np.round(gammas, 12).tolist()}, "
        f"final gamma_hat = {result.vector('observer.gamma_hat')[-1].tolist()}",
        f"final errors: |gamma - gamma_hat| = {metrics['final_gamma_error']:.1e}, "
        f"|x - x_hat| = {metrics['final_state_error']:.1e} (|x| = {np.max(np.abs(result.vector('plant.x')[-1])):.1e})",
        f"samples until the error stays below {TOLERANCE:g}: gamma {_count(metrics['gamma_samples_to_tolerance'])}, "
        f"x {_count(metrics['state_samples_to_tolerance'])}; observer says excited from sample "
        f"{_count(metrics['first_excited_sample'])}",
    ]
    if not metrics["excited_at_end"]:
        lines.append("WARNING: the observer reports excited = 0: the regressions were not exciting "
                     "(e.g. a constant input), its estimates are not determined by the data")
    reference = (f"monolithic check of the plant (eq. (7) stepped with the recorded u(k), beta, theta): "
                 f"max |x(k+1) - model(x(k), u(k))| = {metrics['plant_residual']:.1e} (0: every block used u(t_k))")
    return Summary(lines, metrics, reference=reference)


def plot(result: Result, path: Path) -> list[Path]:
    t = result.time
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    gammas, gamma_hat = true_gammas(result), result.vector("observer.gamma_hat")
    names = ["\\gamma_\\beta", "\\gamma_\\theta"]
    panels = [
        Panel("input $u(k)$", [Curve("$u$", t, result["source.y"], result.unit("source.y"), "signal", 4, ".")]),
        Panel("generator coefficients", [
            curve for j, name in enumerate(names) for curve in (
                Curve(f"${name}$ (true)", t, np.full_like(t, gammas[j]), "", "true", j),
                Curve(f"$\\hat{name}$", t, gamma_hat[:, j], result.unit(f"observer.gamma_hat[{j + 1}]"), "estimate",
                      j, "o"))]),
        Panel("state $x(k)$", [
            curve for i in range(2) for curve in (
                Curve(f"$x_{i + 1}$ (plant)", t, x[:, i], result.unit(f"plant.x[{i + 1}]"), "true", 2 + i),
                Curve(f"$\\hat x_{i + 1}$ (observer)", t, x_hat[:, i], result.unit(f"observer.x_hat[{i + 1}]"),
                      "estimate", 2 + i, "o"))]),
        Panel("errors and excitation", [
            Curve("$|x - \\hat x|$", t, np.max(np.abs(x - x_hat), axis=1), "", "error", 2, "o"),
            Curve("$|\\gamma - \\hat\\gamma|$", t, np.max(np.abs(gamma_hat - gammas), axis=1), "", "error", 0, "s"),
            Curve("$\\nu_\\gamma$", t, result["observer.nu_gamma"], "", "signal", 5),
            Curve("$\\nu_\\eta$", t, result["observer.nu_eta"], "", "signal", 6)], log=True),
        Panel("observer's excited flag", [Curve("excited", t, result["observer.excited"], "", "signal", 7, "o")]),
    ]
    return figure(path, "paper 000: GPEBO + DREM observer of the discrete generator-driven plant (t = k Ts)",
                  panels, result.time_unit)


CLAIM = (
        "Paper 000 observes a discrete plant whose time-varying parameters are outputs of linear "
        "generators with unknown coefficients (GPEBO with discrete DREM). Its example: "
        "x1(k+1) = x2(k) + theta1(k) sin x1(k), x2(k+1) = beta(k) u(k), generator coefficients "
        "gamma_beta = -1 and gamma_theta = 1, inputs u = sin t + sin 2t, u = 5 and u = exp(-0.5 t); it "
        "claims convergence of the estimates. Its regression for the example is not legible, so obsfmu "
        "derives its own (docs/paper000.md). An independent derivation: with u = sin t + sin 2t sampled "
        "at 1 s, the coefficients and the state are exact to round-off within about 20 samples; with "
        "u = 5 they are not identifiable.")

SCENARIO = paper_scenario(
    SYSTEM_FILE, "discrete-gpebo", summarize=summarize, plot=plot, claim=CLAIM, measure=MEASURE,
    not_adaptive="its plant and observer are discrete: their outputs jump at the sample instants, which step "
                 "doubling cannot estimate an error for (use a fixed step that divides Ts)")
