"""A campaign's table (its samples' rows, in sample order, with the measure applied) and its text summary."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pyarrow as pa

from ..metrics import HOLD
from .design import Plan
from .measures import Measure
from .store import rows_to_table

__all__ = ["measured", "campaign_table", "summary_text", "stop_in_time_unit", "LEADING_COLUMNS", "HOLD"]

#: columns after the sample id and the inputs, in this order; the scenario's summary metrics follow
LEADING_COLUMNS = ("status", "reason", "converged", "convergence_time", "final_error", "t_end", "wall_time",
                   "cpu_time", "setup_time", "run_in_session", "worker", "invocation", "finished_at", "fmu_set",
                   "warnings")
QUANTILES = (0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 1.0)


def stop_in_time_unit(plan) -> float:
    """The stop time in the unit of the convergence time (samples for a measure in samples)."""
    return plan.settings["stop_time"] / (plan.settings["step"] if plan.time_unit == "samples" else 1.0)


def measured(row: dict, measure: Measure, stop: float) -> dict:
    """``row`` with ``converged``, ``convergence_time`` and ``final_error`` from its summary metrics; converged
    when the convergence time leaves at least :data:`HOLD` of the run (``stop``, in its unit) to the end."""
    if row.get("status") != "ok":
        return {**row, "converged": False, "convergence_time": math.nan, "final_error": math.nan}
    time, error = measure.evaluate(row)
    return {**row, "converged": bool(time <= (1.0 - HOLD) * stop), "convergence_time": time, "final_error": error}


def campaign_table(plan: Plan, stored: pa.Table | None, any_fmus: bool = False) -> pa.Table:
    """The rows of ``plan``'s samples computed with its FMUs (``any_fmus``: with any), in sample order,
    measured with its measure."""
    if stored is None:
        return rows_to_table([])
    wanted = {sample.id: k for k, sample in enumerate(plan.samples)}
    rows = [row for row in stored.to_pylist()
            if row["sample_id"] in wanted and (any_fmus or row.get("fmu_set") == plan.fmu_set)]
    rows.sort(key=lambda row: wanted[row["sample_id"]])
    rows = [measured({k: v for k, v in row.items() if v is not None}, plan.measure, stop_in_time_unit(plan))
            for row in rows]
    inputs = list(plan.campaign.specs)   # the id hashes the input names: a selected row has exactly these
    present = set(name for row in rows for name in row)
    order = ["sample_id"] + inputs + [c for c in LEADING_COLUMNS if c in present]
    order += [name for name in dict.fromkeys(n for row in rows for n in row) if name not in order]
    table = rows_to_table([{name: row.get(name) for name in order} for row in rows]) if rows else rows_to_table([])
    return table.replace_schema_metadata({
        "scenario": plan.scenario.name, "time_unit": plan.time_unit,
        "convergence_time": plan.measure.time_label, "final_error": plan.measure.error_label})


def _quantiles(values: np.ndarray, fmt: str) -> str:
    if values.size == 0:
        return "none"
    q = np.quantile(values, QUANTILES)
    names = ("min", "5 %", "25 %", "median", "75 %", "95 %", "max")
    return ", ".join(f"{n} {format(v, fmt)}" for n, v in zip(names, q))


def summary_text(plan: Plan, table: pa.Table) -> str:
    """How many converged, quantiles of the convergence time and the final error, the failures."""
    total, rows = len(plan.samples), table.to_pylist()
    status = Counter(row["status"] for row in rows)
    unit = plan.time_unit
    counts = ", ".join(f"{status[s]} {s}" for s in ("ok", "error", "timeout", "crashed") if status[s])
    lines = [f"{plan.scenario.name}: {len(rows)} of {total} samples done" + (f" ({counts})" if counts else "")]
    if len(rows) < total:
        lines.append(f"  {total - len(rows)} samples missing: run the same command again (without --report-only) "
                     f"to compute them")
    converged = np.array([row["convergence_time"] for row in rows if row.get("converged")], dtype=float)
    finished = np.array([row["final_error"] for row in rows if row["status"] == "ok"], dtype=float)
    stop = plan.settings["stop_time"]
    late = sum(1 for row in rows if not row.get("converged") and math.isfinite(row.get("convergence_time", math.nan)))
    share = f"{100 * converged.size / len(rows):.1f} %" if rows else "-"
    lines.append(f"converged: {converged.size} of {len(rows)} ({share}) -- convergence: {plan.measure.time_label}, "
                 f"from then on to the stop time {stop:g} {plan.scenario.time_unit}, held at least the last "
                 f"{100 * HOLD:g} % of the run")
    if late:
        lines.append(f"  {late} sample(s) came within tolerance only in the last {100 * HOLD:g} % of the run: not "
                     "counted as converged (a dip of a noisy error, or a run too short: raise the stop time, or the "
                     "tolerance above the noise-induced error)")
    lines += _noise_lines(plan.measure, rows)
    lines.append(f"convergence time, {unit} (converged samples): {_quantiles(converged, '.4g')}")
    lines.append(f"{plan.measure.error_label} (finished samples): {_quantiles(finished[np.isfinite(finished)], '.3g')}")
    failed = [row for row in rows if row["status"] != "ok"]
    if failed:
        reasons = Counter(f"{row['status']}: {row['reason'][:400]}" for row in failed)
        lines.append(f"failures: {len(failed)}; most frequent reasons:")
        lines += [f"  {count} x {reason}" for reason, count in reasons.most_common(3)]
    walls = np.array([row["wall_time"] for row in rows if row.get("wall_time") is not None
                      and math.isfinite(row["wall_time"])])
    setups = np.array([row["setup_time"] for row in rows if row.get("setup_time")])
    setup = np.median(setups) if setups.size else 0.0
    if walls.size:
        lines.append(f"wall time per sample: median {np.median(walls):.3g} s, total {walls.sum():.4g} s of runs; "
                     f"{setups.size} session set-ups (extract + instantiate), median {setup:.3g} s")
    return "\n".join(lines)


def _noise_lines(measure: Measure, rows: list[dict]) -> list[str]:
    """A warning when the error of some samples fluctuates at the end of the run (3 standard deviations about its
    trend) above its tolerance: the tolerance is below the noise-induced error, so ``converged`` says more about
    the noise than about the observer."""
    noisy = [ratio for row in rows if row["status"] == "ok" and (ratio := measure.noise_ratio(row)) > 1.0]
    if not noisy:
        return []
    return [(f"  noise: in {len(noisy)} of {len(rows)} sample(s) the error fluctuates over the last {100 * HOLD:g} % "
             f"of the run by 3 standard deviations up to {max(noisy):.3g} times its tolerance (median "
             f"{np.median(noisy):.3g}): the tolerance is below the noise-induced error, so whether such a sample "
             "counts as converged depends on the noise; raise the tolerance above it, or lower the noise")]
