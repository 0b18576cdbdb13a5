"""What the paper-001 scenarios ``ltv-ls`` and ``ltv-ls-bounded`` share: summary, figure, references, measures.

Not a scenario itself (no ``SCENARIO``).  Each scenario is its folder's ``system.toml`` (three FMUs,
stepped in this order, Gauss-Seidel: the source ``u = sin t``, the plant (1) ``x' = A(t) x + k C^T x
+ b u + m sin(y)``, ``y = x1``, and the observer: filters (2)-(6), regression (7), least squares with
forgetting, estimate (10)); each file builds its own FMUs ``<name>_<instance>`` (``ltv_ls_plant``,
``ltv_ls_bounded_plant``), so each FMU's DefaultExperiment and start values are its scenario's.  The
two differ in the plant's unknowns and in the stepping settings chosen against their stored
references (``reference.csv`` in each folder, written by :mod:`.reference`, the independent
monolithic solution).  Why these defaults, and what they cost: ``docs/paper001.md``, section 3.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...metrics import format_time, time_to_stay_below
from ...plotting import Curve, Panel, figure
from ...result import Result
from ...system.papers import paper_scenario
from .. import Summary, changed_parameters
from .measures import MEASURE, TOLERANCE

ROOT = Path(__file__).parent.parent
C = [1.0, 0.0]
#: the stored monolithic reference of each case (``python -m fmus.scenarios.ltv_common.reference --write``)
REFERENCES = {"paper": ROOT / "ltv_ls" / "reference.csv", "bounded": ROOT / "ltv_ls_bounded" / "reference.csv"}
#: which case's reference applies to a run of each scenario
CASES = {"ltv-ls": "paper", "ltv-ls-bounded": "bounded"}
NAMES = ["-x0[1]", "-x0[2]", "k[1]", "k[2]", "b[1]", "b[2]", "m[1]", "m[2]"]  #: Theta's entries


def errors(result: Result) -> dict[str, np.ndarray]:
    """Parameter error ``theta_hat - theta`` and relative state error ``|x_hat - x| / (1 + |x|)``."""
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    return {"theta": result.vector("observer.theta_hat") - result.vector("plant.theta"),
            "x_relative": np.abs(x_hat - x) / (1.0 + np.abs(x))}


def load_reference(case: str) -> dict[str, np.ndarray] | None:
    path = REFERENCES[case]
    if not path.exists():
        return None
    data = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    return {"t": data[:, 0], "theta": data[:, 1:9], "theta_hat": data[:, 9:17], "x": data[:, 17:19],
            "x_hat": data[:, 19:21]}


def measurement_noise(result: Result) -> np.ndarray:
    """The noise on the measured output, ``y - C^T x``."""
    return result["plant.y"] - result.vector("plant.x") @ np.asarray(C)


def reference_deviation(result: Result) -> dict | None:
    """How far the run is from a stored reference that is this run's, or None.

    The references are noise-free runs of the scenarios' own parameters (``paper`` for
    ``ltv-ls``, ``bounded`` for ``ltv-ls-bounded``); they apply only to runs that changed none,
    compared on the part of the reference's grid the run covers.  ``theta``/``x``: the largest
    ``|theta_hat - ref|`` and relative ``|x_hat - ref|``, at the run's communication points when
    they include the grid (``on_grid``), else through a cubic spline of the run (:meth:`Result.at`:
    the adaptive master's runs, other steps) -- which adds the spline's own error where the run's
    steps are long.  ``shared``: off the grid, the same at the reference points the run passes
    through (``count`` of ``total``; None if it passes through none), free of that error.
    """
    case = CASES.get(result.info.scenario if result.info else "")
    reference = load_reference(case) if case and not changed_parameters(result) else None
    if reference is None:
        return None
    keep = (reference["t"] >= result.time[0] - 1e-9) & (reference["t"] <= result.time[-1] + 1e-9)
    times = reference["t"][keep]
    if times.size == 0:
        return None
    rows = np.array([result.index_at(t) for t in times])
    passed = np.abs(result.time[rows] - times) <= 1e-9
    ref_theta, ref_x_hat, ref_x = reference["theta_hat"][keep], reference["x_hat"][keep], reference["x"][keep]

    def deviation(theta_hat, x_hat, where):
        return (float(np.abs(theta_hat - ref_theta[where]).max()),
                float((np.abs(x_hat - ref_x_hat[where]) / (1.0 + np.abs(ref_x[where]))).max()))

    at_rows = (result.vector("observer.theta_hat")[rows[passed]], result.vector("observer.x_hat")[rows[passed]])
    found = {"case": case, "on_grid": bool(passed.all()), "shared": None, "total": int(times.size)}
    if found["on_grid"]:
        found["theta"], found["x"] = deviation(*at_rows, passed)
    else:
        found["theta"], found["x"] = deviation(result.at(times, "observer.theta_hat"),
                                               result.at(times, "observer.x_hat"), slice(None))
        if passed.any():
            found["shared"] = (int(passed.sum()), *deviation(*at_rows, passed))
    return found


def summarize(result: Result) -> Summary:
    e = errors(result)
    t = result.time
    unit = result.time_unit
    theta_error = np.abs(e["theta"]).max(axis=1)
    metrics = {
        "final_parameter_error": float(theta_error[-1]),
        "parameter_convergence_time": time_to_stay_below(t, e["theta"], TOLERANCE),
        "final_relative_state_error": float(e["x_relative"][-1].max()),
        "state_convergence_time": time_to_stay_below(t, e["x_relative"], TOLERANCE),
        "max_F": float(np.max(result["observer.F_max"])),
        "max_abs_y": float(np.max(np.abs(result["plant.y"]))),
    }
    final = ", ".join(f"{n} {v:+.1e}" for n, v in zip(NAMES, e["theta"][-1]))
    lines = [
        f"parameter error |theta_hat - theta| at t = {t[-1]:g} {unit}: {metrics['final_parameter_error']:.2e} ({final})",
        f"time after which all 8 stay below {TOLERANCE:g}: "
        f"{format_time(metrics['parameter_convergence_time'], unit, 2)}",
        f"relative state error |x_hat - x|/(1 + |x|): {metrics['final_relative_state_error']:.2e}, "
        f"stays below {TOLERANCE:g} after {format_time(metrics['state_convergence_time'], unit, 2)}",
        f"max |y| = {metrics['max_abs_y']:.3g}; largest eigenvalue of F: {metrics['max_F']:.3g}",
    ]
    noise = measurement_noise(result)
    if np.any(noise):
        metrics["noise_std"] = float(np.std(noise))
        late = t >= t[-1] / 2
        metrics["max_parameter_error_second_half"] = float(theta_error[late].max())
        lines.append(f"measurement noise on y: std {metrics['noise_std']:.3g}; over the second half of the run "
                     f"|theta_hat - theta| <= {metrics['max_parameter_error_second_half']:.3g}, relative state error "
                     f"<= {e['x_relative'][late].max():.3g}")
    deviation = reference_deviation(result)
    if deviation:
        metrics["max_deviation_from_reference"] = deviation["theta"]
        metrics["max_relative_x_hat_deviation_from_reference"] = deviation["x"]
        found = f"max |theta_hat - ref| = {deviation['theta']:.2e}, max relative x_hat deviation = {deviation['x']:.2e}"
        reference = f"vs the monolithic Radau reference ({deviation['case']} case, stored, up to t = {t[-1]:g} {unit}): "
        if deviation["on_grid"]:
            reference += found
        else:
            total = deviation["total"]
            if deviation["shared"]:
                count, theta_dev, x_dev = deviation["shared"]
                metrics["max_deviation_from_reference_at_shared_points"] = theta_dev
                reference += (f"at the {count} of its {total} points the run passes through, max |theta_hat - ref| = "
                              f"{theta_dev:.2e}, max relative x_hat deviation = {x_dev:.2e}; at all {total}, ")
            else:
                reference += f"at its {total} points, "
            reference += (f"read through a cubic spline of the run (which adds its own error where the run's steps "
                          f"are long): {found}")
    else:
        reason = changed_parameters(result) or "the stored reference does not cover the run"
        reference = f"no stored monolithic reference applies to this run ({reason})"
    return Summary(lines, metrics, reference=reference)


def plot(result: Result, path: Path) -> list[Path]:
    t = result.time
    e = errors(result)
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    tolerance = Curve(f"{TOLERANCE:g}", t[[0, -1]], np.full(2, TOLERANCE), role="limit")
    panels = [
        Panel("parameter error $|\\hat\\Theta - \\Theta|$", [
            Curve(n, t, e["theta"][:, j], result.unit(f"plant.theta[{j + 1}]"), "error", j)
            for j, n in enumerate(NAMES)] + [tolerance], log=True),
        Panel("relative state error\n$|\\hat x - x| / (1 + |x|)$", [
            Curve(f"$x_{i + 1}$", t, e["x_relative"][:, i], "", "error", i) for i in range(x.shape[1])]
            + [tolerance], log=True),
    ]
    for i in range(x.shape[1]):
        unit = result.unit(f"plant.x[{i + 1}]")
        panels.append(Panel(f"state $x_{i + 1}$", [
            Curve(f"$x_{i + 1}$ (plant)", t, x[:, i], unit, "true", i),
            Curve(f"$\\hat x_{i + 1}$ (observer)", t, x_hat[:, i], unit, "estimate", i)]))
    panels.append(Panel("largest eigenvalue of $F$", [
        Curve("$F_{max}$", t, result["observer.F_max"], result.unit("observer.F_max"), "signal", 3)], log=True))
    return figure(path, "paper 001: adaptive observer (least squares with forgetting) of a nonlinear LTV plant",
                  panels, result.time_unit)


def scenario(name: str, claim: str, adaptive_floor=None):
    """The scenario ``name`` of its folder's ``system.toml``, with the paper's summary, figure, measure and claim."""
    folder = ROOT / name.replace("-", "_")
    return paper_scenario(folder / "system.toml", name, summarize=summarize, plot=plot, measure=MEASURE, claim=claim,
                          adaptive_floor=adaptive_floor)
