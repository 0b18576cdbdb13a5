"""Figures of a campaign's table: convergence-time distribution; final error and convergence time
against each varied input.

Each figure is written as PNG and SVG.  Failed samples (status ``error``,
``timeout`` or ``crashed``) have no error value: they are drawn as red
crosses on the top edge of the panels at their input values (so are unconverged samples in the
convergence-time panels: their time is infinite).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa

from .design import Plan
from .table import HOLD, stop_in_time_unit

__all__ = ["plot_convergence", "plot_vs_inputs", "write_plots"]


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, title: str, stem: Path) -> list[Path]:
    """Title, layout, ``stem.png`` + ``stem.svg``, close."""
    fig.suptitle(title, fontsize=10)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".svg")]
    fig.savefig(paths[0], dpi=120)
    fig.savefig(paths[1])
    import matplotlib.pyplot as plt
    plt.close(fig)
    return paths


def _column(table: pa.Table, name: str) -> np.ndarray:
    if name not in table.column_names:
        return np.full(table.num_rows, np.nan)
    return np.array([np.nan if v is None else v for v in table[name].to_pylist()], dtype=float)


def plot_convergence(plan: Plan, table: pa.Table, stem: Path) -> list[Path]:
    """Histogram of the convergence time (converged samples) and its empirical CDF over all samples."""
    plt = _pyplot()
    converged = np.array(table["converged"].to_pylist() if table.num_rows else [], dtype=bool)
    times = np.sort(_column(table, "convergence_time")[converged])
    total = table.num_rows
    unit = plan.time_unit
    stop = stop_in_time_unit(plan)
    fig, (hist, cdf) = plt.subplots(1, 2, figsize=(11, 4.2), layout="constrained")
    label = f"convergence time, {unit}"
    if times.size:
        hist.hist(times, bins=min(30, max(5, int(np.sqrt(times.size)) + 1)), color="tab:blue", edgecolor="white")
    hist.set_xlabel(label)
    hist.set_ylabel("converged samples (count)")
    hist.set_title(f"{times.size} of {total} samples converged", fontsize=10)
    steps = np.concatenate([[0.0], times, [stop]])
    fractions = np.concatenate([[0.0], np.arange(1, times.size + 1) / max(total, 1), [times.size / max(total, 1)]])
    cdf.step(steps, fractions, where="post", color="tab:blue")
    cdf.plot(times, fractions[1:-1], "o", color="tab:blue", ms=3)      # visible even when all converge at once
    cdf.axvspan((1.0 - HOLD) * stop, stop, color="0.85", zorder=0,
                label=f"last {100 * HOLD:g} % of the run: within tolerance there is not converged")
    cdf.axhline(times.size / max(total, 1), color="k", ls=":", lw=1,
                label=f"converged by the stop time: {100 * times.size / max(total, 1):.1f} %")
    cdf.set_xlim(0, stop)
    cdf.set_ylim(0, 1.02)
    cdf.set_xlabel(label)
    cdf.set_ylabel("fraction of all samples converged")
    cdf.set_title("empirical CDF (failed and unconverged samples count as never)", fontsize=10)
    cdf.legend(fontsize=8, loc="lower right")
    for ax in (hist, cdf):
        ax.grid(True, alpha=0.4)
    return _save(fig, f"{plan.scenario.name}: {plan.measure.time_label}", stem)


def _decades(ax, x: np.ndarray) -> None:
    """A logarithmic x axis for non-negative inputs that span two decades or more (symlog when 0 is one)."""
    finite = x[np.isfinite(x)]
    positive = finite[finite > 0]
    if positive.size and np.all(finite >= 0) and positive.max() >= 100 * positive.min():
        if np.any(finite == 0):
            ax.set_xscale("symlog", linthresh=positive.min())
            ax.set_xlim(left=-positive.min() / 3)
        else:
            ax.set_xscale("log")


def plot_vs_inputs(plan: Plan, table: pa.Table, stem: Path, column: str, label: str, log: bool,
                   ceiling: float | None = None) -> list[Path]:
    """One panel per varied input: ``column`` against the input's value, converged / not converged /
    failed marked; samples without a value to draw (failed, never converged) sit on the top edge
    (``ceiling``, default: above the largest value)."""
    plt = _pyplot()
    names = list(plan.variables)
    columns = min(len(names), 2)
    rows_count = int(np.ceil(len(names) / columns))
    fig, axes = plt.subplots(rows_count, columns, figsize=(5.6 * columns, 3.8 * rows_count), squeeze=False,
                             layout="constrained")
    ok = np.array(table["status"].to_pylist(), dtype=object) == "ok"
    converged = np.array(table["converged"].to_pylist(), dtype=bool)
    values = _column(table, column)
    drawable = ok & np.isfinite(values) & ((values > 0) if log else True)
    known = values[drawable]
    top = ceiling or (known.max() * (10 if log else 1.1) if known.size else 1.0) or 1.0
    shown = np.where(drawable, values, top)
    groups = ((ok & converged, "o", "tab:blue", "converged"), (ok & ~converged, "s", "tab:orange", "not converged"),
              (~ok, "x", "red", "failed: error/timeout"))
    for ax, name in zip(axes.flat, names):
        x = _column(table, name)
        for mask, marker, color, text in groups:
            if mask.any():
                edge = ", top edge" if np.any(mask & ~drawable) else ""
                ax.plot(x[mask], shown[mask], marker, color=color, ms=6 if marker == "x" else 4, ls="none",
                        label=f"{text} ({mask.sum()}{edge})")
        if log:
            ax.set_yscale("log")
        _decades(ax, x)
        unit = plan.variables[name].unit
        ax.set_xlabel(f"{name}, {unit}" if unit else f"{name} (no unit declared)")
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    what = "final error" if column == "final_error" else column.replace("_", " ")
    return _save(fig, f"{plan.scenario.name}: {what} against the varied inputs ({table.num_rows} samples)", stem)


def write_plots(plan: Plan, table: pa.Table, out: Path) -> list[Path]:
    """``OUT/convergence``, ``OUT/error_vs_inputs`` and ``OUT/convergence_vs_inputs``, each ``.png`` + ``.svg``."""
    if table.num_rows == 0:
        return []
    out = Path(out)
    return (plot_convergence(plan, table, out / "convergence")
            + plot_vs_inputs(plan, table, out / "error_vs_inputs", "final_error", plan.measure.error_label, log=True)
            + plot_vs_inputs(plan, table, out / "convergence_vs_inputs", "convergence_time",
                             f"convergence time, {plan.time_unit} (top edge: the stop time)", log=False,
                             ceiling=stop_in_time_unit(plan)))
