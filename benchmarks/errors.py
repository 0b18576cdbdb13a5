"""Error of a scenario's run against its independent reference, at the reference's points.

One function per continuous scenario (``ERRORS[name](result) -> float``), shared by
``benchmarks/issue14.py`` and ``benchmarks/master_study.py``.  Results whose communication points
miss the reference's grid (the adaptive master's) are read there through a cubic spline of the
run -- fourth order, unlike linear interpolation, which would measure itself rather than the run.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

__all__ = ["ERRORS"]


def _on_grid(result, columns, times):
    """``columns`` of ``result`` at ``times`` (cubic spline through the communication points)."""
    from scipy.interpolate import CubicSpline
    values = np.column_stack([result[c] for c in columns])
    return CubicSpline(result.time, values)(times)


def _ship_error(result):
    from fmus.scenarios.ship import composite_solution
    states = np.column_stack([result.vector("plant.x"), result.vector("observer.x_hat")])
    return float(np.max(np.abs(states - composite_solution(result.time))))


def _ltv_error(case):
    def error(result):
        from fmus.scenarios.ltv_ls import load_reference
        reference = load_reference(case)
        keep = reference["t"] <= result.time[-1] + 1e-9
        columns = [f"observer.theta_hat[{j}]" for j in range(1, 9)]
        return float(np.abs(_on_grid(result, columns, reference["t"][keep]) - reference["theta_hat"][keep]).max())
    return error


def _state_affine_error(folder):
    def error(result):
        from fmus.scenarios.state_affine_common import load_reference
        reference = load_reference(ROOT / "fmus" / "scenarios" / folder / "reference.csv")
        keep = reference["time"] <= result.time[-1] + 1e-9
        worst = 0.0
        for key in ("x_hat", "theta_hat"):
            columns = [c for c in result.columns if c.startswith(f"observer.{key}[")]
            worst = max(worst, float(np.abs(_on_grid(result, columns, reference["time"][keep])
                                            - reference[key][keep]).max()))
        return worst
    return error


#: the error of a run against the scenario's independent reference, at the reference's points
ERRORS = {"ship": _ship_error, "ltv-ls-bounded": _ltv_error("bounded"), "ltv-ls": _ltv_error("paper"),
          "state-affine-pendulum": _state_affine_error("state_affine_pendulum"),
          "state-affine-chemostat": _state_affine_error("state_affine_chemostat")}
