"""Summary and figure shared by the paper-004 scenarios (``state-affine-pendulum``, ``state-affine-chemostat``).

Not a scenario itself (no ``SCENARIO``).  Both scenarios have the instances ``source`` (the
input), ``plant`` (outputs ``y``, ``x`` and its true unknown parameters ``theta``) and
``observer`` (outputs ``x_hat``, ``theta_hat``, ``Delta``, ``nu``), and a reference file
``reference.csv`` in their folder: the independent monolithic solution
(``fmus/scenarios/state_affine_common/reference.py``, Radau, rtol 1e-10) for the default settings.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...metrics import format_time, time_to_stay_below
from ...plotting import Curve, Panel, figure
from ...result import Result
from .. import Summary, changed_parameters
from .measures import MEASURE, TOLERANCE

__all__ = ["TOLERANCE", "MEASURE", "NOT_ADAPTIVE", "load_reference", "errors", "summarize", "plot"]

MU = 0.98          #: the observers' default switching level (the summary reports nu < MU)
#: why the adaptive master is refused (measured with benchmarks/cosimulation_costs.py)
NOT_ADAPTIVE = ("step doubling measures the wrong error here: the finite-time DREM laws hold their regressors "
                "over each step (first order in the step) until they switch (nu < mu) and are exact from then "
                "on, so the error of the transient drives the step down while the final accuracy is set by "
                "the coupling (chemostat: tol 1e-6 took 120 s and 103 000 points for the error the default "
                "fixed step reaches in 7.9 s); run it with a fixed step (see the scenario's table)")


def load_reference(path: Path) -> dict[str, np.ndarray]:
    """Columns of a reference file: ``time``, ``x``, ``x_hat``, ``theta_hat`` (2-D), ``Delta``, ``nu``."""
    with open(path) as handle:
        names = handle.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    columns = {"time": data[:, 0], "Delta": data[:, names.index("Delta")], "nu": data[:, names.index("nu")]}
    for prefix in ("x", "x_hat", "theta_hat"):
        columns[prefix] = data[:, [i for i, n in enumerate(names) if n.startswith(prefix + "[")]]
    return columns


def errors(result: Result) -> tuple[np.ndarray, np.ndarray]:
    """``theta_hat - theta`` and ``x_hat - x`` at every communication point."""
    return (result.vector("observer.theta_hat") - result.vector("plant.theta"),
            result.vector("observer.x_hat") - result.vector("plant.x"))


def _reference_deviation(result: Result, reference: dict[str, np.ndarray]) -> dict[str, float] | None:
    """Max |co-simulation - reference| on the part of the reference grid the run covers."""
    times = reference["time"][reference["time"] <= result.time[-1] + 1e-12]
    if times.size < 2:
        return None
    deviation = {}
    for key, column in (("x", "plant.x"), ("x_hat", "observer.x_hat"), ("theta_hat", "observer.theta_hat")):
        values = result.vector(column)
        here = np.column_stack([np.interp(times, result.time, values[:, i]) for i in range(values.shape[1])])
        deviation[key] = float(np.max(np.abs(here - reference[key][:times.size])))
    return deviation


def summarize(result: Result, reference_file: Path, time_unit: str | None = None) -> Summary:
    """Final errors, times to 1e-4, switching time, and the deviation from the stored reference.

    The reference (the scenario's own parameters) applies only to runs that changed none.
    """
    unit = time_unit or result.time_unit
    t = result.time
    theta_error, x_error = errors(result)
    nu = result["observer.nu"]
    switched = np.nonzero(nu < MU)[0]
    metrics = {
        "final_theta_error": float(np.abs(theta_error[-1]).max()),
        "final_x_error": float(np.abs(x_error[-1]).max()),
        "theta_time_to_1e-4": time_to_stay_below(t, theta_error, TOLERANCE),
        "x_time_to_1e-4": time_to_stay_below(t, x_error, TOLERANCE),
        "switch_time": float(t[switched[0]]) if switched.size else float("inf"),
    }
    theta_hat, theta = result.vector("observer.theta_hat")[-1], result.vector("plant.theta")[-1]
    lines = [
        f"theta_hat = {np.array2string(theta_hat, precision=8)} (true {np.array2string(theta, precision=8)}), "
        f"final |theta_hat - theta| = {metrics['final_theta_error']:.1e}",
        f"final |x_hat - x| = {metrics['final_x_error']:.1e}",
        f"finite-time estimator switched (nu < {MU}): {format_time(metrics['switch_time'], unit)}",
        f"time after which |theta_hat - theta| stays below {TOLERANCE:g}: "
        f"{format_time(metrics['theta_time_to_1e-4'], unit)}; |x_hat - x|: {format_time(metrics['x_time_to_1e-4'], unit)}",
    ]
    why_not = changed_parameters(result)
    deviation = None if why_not else _reference_deviation(result, load_reference(reference_file))
    if deviation is None:
        reference = f"the stored monolithic reference does not apply ({why_not or 'the run is too short'})"
    else:
        metrics.update({f"max_deviation_{k}": v for k, v in deviation.items()})
        labels = {"x": "plant x", "x_hat": "x_hat", "theta_hat": "theta_hat"}
        reference = (f"max |co-simulation - monolithic reference| (Radau, rtol 1e-10) up to t = {t[-1]:g} {unit}: "
                     + ", ".join(f"{labels[k]} {v:.1e}" for k, v in deviation.items()))
    return Summary(lines, metrics, reference=reference)


def plot(result: Result, path: Path, title: str, state_names: list[str], parameter_names: list[str],
         time_unit: str | None = None) -> list[Path]:
    """Each state and each unknown parameter with its estimate, the errors, the excitation."""
    t = result.time
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    theta, theta_hat = result.vector("plant.theta"), result.vector("observer.theta_hat")
    theta_error, x_error = errors(result)
    x_units = [result.unit(f"plant.x[{i + 1}]") for i in range(x.shape[1])]
    theta_units = [result.unit(f"plant.theta[{j + 1}]") for j in range(theta.shape[1])]
    panels = [Panel(name, [Curve(f"{name} (plant)", t, x[:, i], x_units[i], "true", i),
                           Curve(f"{name} estimate", t, x_hat[:, i], x_units[i], "estimate", i)])
              for i, name in enumerate(state_names)]
    keys = range(len(state_names), len(state_names) + len(parameter_names))
    panels += [Panel(f"parameter {name}", [Curve(f"{name} (true)", t, theta[:, j], theta_units[j], "true", k),
                                           Curve(f"{name} estimate", t, theta_hat[:, j], theta_units[j], "estimate", k)])
               for j, (name, k) in enumerate(zip(parameter_names, keys))]
    errors_panel = [Curve(f"|{name} error|", t, x_error[:, i], x_units[i], "error", i)
                    for i, name in enumerate(state_names)]
    errors_panel += [Curve(f"|{name} error|", t, theta_error[:, j], theta_units[j], "error", k)
                     for j, (name, k) in enumerate(zip(parameter_names, keys))]
    errors_panel.append(Curve(f"{TOLERANCE:g}", t[[0, -1]], np.full(2, TOLERANCE), role="limit"))
    panels.append(Panel("estimation errors", errors_panel, log=True))
    panels.append(Panel("excitation", [
        Curve("$|\\Delta|$", t, result["observer.Delta"], result.unit("observer.Delta"), "signal", 8),
        Curve("$\\nu$", t, result["observer.nu"], result.unit("observer.nu"), "signal", 9)], log=True))
    return figure(path, title, panels, time_unit or result.time_unit)
