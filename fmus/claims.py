"""The papers' claims as checks of the measured metrics, and where each number of a run holds.

``obsfmu report`` prints every scenario's claim (``Scenario.claim``, our words and the paper's
numbers).  Here each number of a claim becomes a :class:`Check` of one summary metric -- met when
the metric is at most the claimed bound -- so the page marks every claim **met** or **not met**
with both numbers; a metric missing from a run (e.g. the paper's table on changed parameters) is
"not measured in this run".  :func:`holds_over` says over which interval of the run a metric
holds (at its end, over the whole run, over its last 20 %, ...), :data:`REFERENCE_INTERVAL` the same
for the agreement with the monolithic reference.

The checks name metrics of the scenarios' summaries; ``tests/fmus/test_report.py`` holds them to every
scenario (each check's metric exists, every metric has an interval).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = ["Check", "CHECKS", "verdict", "holds_over", "reference_interval"]


@dataclass(frozen=True)
class Check:
    """One number of a claim: ``metric`` at most ``bound`` (``unit``: "time" for the scenario's unit of time)."""

    claim: str
    metric: str
    bound: float
    unit: str = ""


_TIME = "time"

CHECKS: dict[str, tuple[Check, ...]] = {
    "ship": (
        Check("the loop settles within 0.3 s (paper fig. 4; settling of y = x1 - x1_hat to 5 % of its peak)",
              "settling_time_y", 0.3, _TIME),
        Check("the printed lsim table, to its four decimals (a deviation below 5e-5)",
              "max_deviation_from_paper_table", 5e-5)),
    "ltv-ls": (
        Check("all eight parameters within 1e-3 after about 12.2 s (independent monolithic solution)",
              "parameter_convergence_time", 12.2, _TIME),
        Check("the parameter errors tend to zero (within 1e-3 at the end)", "final_parameter_error", 1e-3)),
    "ltv-ls-bounded": (
        Check("all eight parameters within 1e-3 after about 18 s (independent monolithic solution)",
              "parameter_convergence_time", 18.0, _TIME),
        Check("the parameter errors tend to zero (within 1e-3 at the end)", "final_parameter_error", 1e-3)),
    "uio-ftdrem": (
        Check("x_tilde(0) found exactly after about 0.055 s (stage 1)", "stage1_t_identified", 0.055, _TIME),
        Check("omega to 1e-4 by about 3.4 s", "t_omega_1e-4", 3.4, _TIME),
        Check("xi(0) to 1e-4 by about 3.6 s", "t_xi0_1e-4", 3.6, _TIME),
        Check("f to 1e-3 by about 3.7 s", "t_f_1e-3", 3.7, _TIME)),
    "discrete-gpebo": (
        Check("the generator coefficients exact to round-off within about 20 samples",
              "gamma_samples_to_tolerance", 20, "samples"),
        Check("the state exact to round-off within about 20 samples", "state_samples_to_tolerance", 20, "samples")),
    "state-affine-pendulum": (
        Check("the parameters within 1e-4 from 1.35 s", "theta_time_to_1e-4", 1.35, _TIME),
        Check("the state within 1e-4 from 2.85 s", "x_time_to_1e-4", 2.85, _TIME)),
    "state-affine-chemostat": (
        Check("S_in within 1e-4 from 1.63 h", "theta_time_to_1e-4", 1.63, _TIME),
        Check("the state within 1e-4 from 3.92 h", "x_time_to_1e-4", 3.92, _TIME)),
}


def _shown(value: float, unit: str) -> str:
    if math.isinf(value) and value > 0:
        return "not reached"
    return f"{value:.6g}" + (f" {unit}" if unit else "")


def verdict(check: Check, metrics: dict, time_unit: str) -> tuple[str, str]:
    """``("met" | "not met" | "not measured", "measured 4.168 s, claimed: at most 3.4 s")``."""
    unit = time_unit if check.unit == _TIME else check.unit
    claimed = f"claimed: at most {_shown(check.bound, unit)}"
    value = metrics.get(check.metric)
    if not isinstance(value, (int, float)) or math.isnan(value):
        return "not measured", f"{check.metric} is not measured in this run; {claimed}"
    return ("met" if value <= check.bound else "not met"), f"measured {_shown(value, unit)}, {claimed}"


#: where a metric holds, by its name (the first pattern that matches); None: not stated
_WHERE = (
    (r"_last20$|^reference_deviation_", "last 20 %"),
    (r"_paper_table$", "table"),
    (r"_at_(?P<t>[0-9.e+-]+)s$", "at t"),
    (r"^final_|_at_end$|^stage\d+_status$", "end"),
    (r"time|^t_|_t_identified$|_samples?_|_sample$|^max_|_residual$", "run"),
)


def _interval(kind: str, end: float, unit: str, at: str | None = None) -> str:
    if kind == "last 20 %":
        return f"over the last 20 % of the run, t = {0.8 * end:g} .. {end:g} {unit}"
    if kind == "at t":
        return f"at t = {at} s"
    if kind == "table":
        return "at the times of the paper's printed table, t = 0 .. 0.67 s"
    if kind == "end":
        return f"at the end of the run, t = {end:g} {unit}"
    return f"over the whole run, t = 0 .. {end:g} {unit}"


def holds_over(metric: str, end: float, unit: str) -> str | None:
    """Where ``metric`` of a run ending at ``end`` holds, in words with the times (None: not stated)."""
    for pattern, kind in _WHERE:
        match = re.search(pattern, metric)
        if match:
            return _interval(kind, end, unit, match.groupdict().get("t"))
    return None


#: the interval of each scenario's agreement with its monolithic reference (default: the whole run)
REFERENCE_INTERVAL = {"uio-ftdrem": "last 20 %"}


def reference_interval(scenario: str, end: float, unit: str) -> str:
    """Where the agreement with the reference of ``scenario`` holds."""
    return _interval(REFERENCE_INTERVAL.get(scenario, "run"), end, unit)
