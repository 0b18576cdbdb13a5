"""What a sample measures: its convergence time and final error, taken from the scenario's summary.

Every scenario's ``summarize`` already reports its metrics (final estimation
errors, times after which an error stays below a stated tolerance); a
campaign keeps all of them and names two: the *convergence time* (the
largest of some ``time_to_stay_below`` metrics: every estimate has
converged; ``inf`` when one never does) and the *final error*.  A sample
*converged* when its run finished and its convergence time is finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..scenarios import Scenario
from ..scenarios import discrete_gpebo, ltv_ls, state_affine_common
from .errors import CampaignError

__all__ = ["Measure", "measure_for", "DEFAULT_MEASURES"]


@dataclass(frozen=True)
class Measure:
    """Convergence time = max of the ``time`` metrics; final error = max ``|.|`` of the ``error`` metrics."""

    time: tuple[str, ...]
    error: tuple[str, ...]
    time_label: str   #: what the convergence time is, with the tolerance, e.g. "all |theta_hat - theta| < 1e-3"
    error_label: str
    time_unit: str | None = None  #: None: the scenario's unit of time

    def evaluate(self, metrics: dict[str, float]) -> tuple[float, float]:
        """``(convergence time, final error)`` of one sample's summary metrics."""
        missing = [name for name in self.time + self.error if name not in metrics]
        if missing:
            raise CampaignError(f"summary metric(s) {', '.join(missing)} not reported by the scenario; "
                                f"it reports: {', '.join(sorted(metrics))} (see --time-metric/--error-metric)")
        time = max(float(metrics[name]) for name in self.time)
        error = max(abs(float(metrics[name])) for name in self.error)
        return (time if not math.isnan(time) else math.inf), error


_LTV = Measure(("parameter_convergence_time",), ("final_parameter_error",),
               f"time until all 8 |theta_hat - theta| stay below {ltv_ls.TOLERANCE:g}",
               "final max |theta_hat - theta|")
_STATE_AFFINE = Measure(("theta_time_to_1e-4", "x_time_to_1e-4"), ("final_theta_error", "final_x_error"),
                        f"time until |theta_hat - theta| and |x_hat - x| stay below {state_affine_common.TOLERANCE:g}",
                        "final max(|theta_hat - theta|, |x_hat - x|)")

#: the default measure of every shipped scenario
DEFAULT_MEASURES: dict[str, Measure] = {
    "ltv-ls": _LTV,
    "ltv-ls-bounded": _LTV,
    "discrete-gpebo": Measure(
        ("gamma_samples_to_tolerance", "state_samples_to_tolerance"), ("final_state_error",),
        f"samples until |gamma_hat - gamma| and |x - x_hat| stay below {discrete_gpebo.TOLERANCE:g}",
        "final max |x - x_hat|", time_unit="samples"),
    "uio-ftdrem": Measure(
        ("t_omega_1e-4", "t_xi0_1e-4", "t_f_1e-3", "t_x_1e-5"), ("f_error_last20",),
        "time until omega_hat, xi0_hat stay within 1e-4, f_hat within 1e-3, x_hat within 1e-5 (relative)",
        "max |f_hat - f| over the last 20 % of the run"),
    "state-affine-pendulum": _STATE_AFFINE,
    "state-affine-chemostat": _STATE_AFFINE,
    "ship": Measure(("observer_convergence_time",), ("final_error_x1", "final_error_x2"),
                    "time until |x - x_hat| stays below 5 % of its peak", "final max |x - x_hat|"),
}


def _names(option: str, text: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    names = tuple(n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip())
    if not names:
        raise CampaignError(f"{option}: expected one or more summary metric names, got {text!r}")
    return names


def measure_for(scenario: Scenario, time_metric=None, error_metric=None) -> Measure:
    """The scenario's default measure, with the time and/or error metrics replaced when given."""
    default = DEFAULT_MEASURES.get(scenario.name)
    if default is None and (time_metric is None or error_metric is None):
        raise CampaignError(f"scenario {scenario.name!r} has no default measure: give --time-metric and "
                            f"--error-metric (names of its summary metrics)")
    measure = default
    if time_metric is not None:
        names = _names("--time-metric", time_metric)
        unit = "samples" if all("samples" in name for name in names) else None
        measure = Measure(names, measure.error if measure else (), "max(" + ", ".join(names) + ")",
                          measure.error_label if measure else "", unit)
    if error_metric is not None:
        names = _names("--error-metric", error_metric)
        measure = Measure(measure.time, names, measure.time_label, "max |" + "|, |".join(names) + "|",
                          measure.time_unit)
    return measure
