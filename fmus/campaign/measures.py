"""What a sample measures: its convergence time and final error, taken from the scenario's summary.

Every scenario's ``summarize`` already reports its metrics (final estimation
errors, times after which an error stays below a stated tolerance); a
campaign keeps all of them and names two: the *convergence time* (the
largest of some ``time_to_stay_below`` metrics: every estimate has
converged; ``inf`` when one never does) and the *final error*.  A sample
*converged* when its run finished and its convergence time is finite.
A scenario's own measure is defined in its folder (``measures.py``) and
reached through the scenario, ``Scenario.measure``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import CampaignError

__all__ = ["Measure", "measure_for"]


@dataclass(frozen=True)
class Measure:
    """Convergence time = max of the ``time`` metrics; final error = max ``|.|`` of the ``error`` metrics."""

    time: tuple[str, ...]
    error: tuple[str, ...]
    time_label: str   #: what the convergence time is, with the tolerance, e.g. "all |theta_hat - theta| < 1e-3"
    error_label: str
    time_unit: str | None = None  #: None: the scenario's unit of time
    #: metric names of the errors' fluctuation at the end of the run (:func:`fmus.metrics.fluctuation`), with
    #: their tolerances: the noise check of a sweep (none: not checked)
    noise: tuple[tuple[str, float], ...] = ()

    def noise_ratio(self, metrics: dict) -> float:
        """The largest ``3 * fluctuation / tolerance`` of a sample (0 where its metrics have none)."""
        ratios = [3.0 * float(metrics[name]) / tolerance for name, tolerance in self.noise
                  if metrics.get(name) is not None and math.isfinite(float(metrics[name]))]
        return max(ratios, default=0.0)

    def evaluate(self, metrics: dict[str, float]) -> tuple[float, float]:
        """``(convergence time, final error)`` of one sample's summary metrics."""
        missing = [name for name in self.time + self.error if name not in metrics]
        if missing:
            raise CampaignError(f"summary metric(s) {', '.join(missing)} not reported by the scenario; "
                                f"it reports: {', '.join(sorted(metrics))} (see --time-metric/--error-metric)")
        time = max(float(metrics[name]) for name in self.time)
        error = max(abs(float(metrics[name])) for name in self.error)
        return (time if not math.isnan(time) else math.inf), error


def _names(option: str, text: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    names = tuple(n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip())
    if not names:
        raise CampaignError(f"{option}: expected one or more summary metric names, got {text!r}")
    return names


def measure_for(scenario, time_metric=None, error_metric=None) -> Measure:
    """The measure of ``scenario`` (a :class:`fmus.scenarios.Scenario`: its ``measure``, defined in its
    folder's ``measures.py``), with the time and/or error metrics replaced when given."""
    default = scenario.measure
    if default is None and (time_metric is None or error_metric is None):
        raise CampaignError(f"scenario {scenario.name!r} has no default measure: give --time-metric and "
                            f"--error-metric (names of its summary metrics)")
    measure = default
    if time_metric is not None:
        names = _names("--time-metric", time_metric)
        unit = "samples" if all("samples" in name for name in names) else None
        measure = Measure(names, measure.error if measure else (), "max(" + ", ".join(names) + ")",
                          measure.error_label if measure else "", unit, measure.noise if measure else ())
    if error_metric is not None:
        names = _names("--error-metric", error_metric)
        measure = Measure(measure.time, names, measure.time_label, "max |" + "|, |".join(names) + "|",
                          measure.time_unit, measure.noise)
    return measure
