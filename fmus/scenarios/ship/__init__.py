"""Scenario ``ship`` -- paper 002: modal observer and state feedback for ship course stabilisation.

Defined by its system file ``system.toml`` (``obsfmu show ship``): the unstable plant
(eig(A) = {1, 2}), the Luenberger observer (N = [83; 1847], eig(A - N C) = {-40, -40}) and the state
feedback u = -K x_hat (K = [398, 43], eig(A - B K) = {-20, -20}); free motion from x(0) = [0.05; 0.2],
x_hat(0) = 0, zero reference, 0..1 s.  Default: 2e-5 s, Gauss-Seidel, linear coupling -- the step at
which every printed digit is reproduced (the measurements: ``docs/paper002.md``, section 3).

This module adds what only the paper gives: the summary against the exact composite solution
``expm(Ae t) xe0`` (eq. (12)) and the paper's printed table (``paper_table.csv``), the figure, the
sweep measure and the claim.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from obsfmu.observers.integrators import expm

from ...metrics import format_time, settling_time, time_to_stay_below
from ...plotting import Curve, Panel, figure
from ...result import Result
from ...system import SystemSpec, load_system
from ...system.papers import paper_scenario
from .. import Summary, changed_parameters
from .measures import MEASURE

HERE = Path(__file__).parent
SYSTEM_FILE = HERE / "system.toml"
PAPER_TABLE = HERE / "paper_table.csv"
TABLE_COLUMNS = ("y", "x1", "x2", "x1_hat", "x2_hat")
INSTANCES = ("plant", "observer", "controller")


@lru_cache(maxsize=1)
def system() -> SystemSpec:
    """The checked system file of the scenario (read once)."""
    return load_system(SYSTEM_FILE)


def file_parameters() -> dict[str, float]:
    """``instance.variable -> value`` of every FMU parameter and ``[values]`` input of the system file
    (the paper's design: the file's matrices and the gains designed from its poles)."""
    spec = system()
    values = {}
    for instance, component in spec.components.items():
        for parameter in (p for definition in component.definitions for p in definition.parameters):
            values.update({f"{instance}.{name}": value for name, value in zip(parameter.element_names,
                                                                               parameter.value)})
        values.update({f"{instance}.{name}": value for name, value in spec.values.get(instance, {}).items()})
    return values


def paper_table() -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Times and columns of the printed lsim table (NaN where the paper elides)."""
    data = np.genfromtxt(PAPER_TABLE, delimiter=",", comments="#", skip_header=5, filling_values=np.nan)
    return data[:, 0], {name: data[:, i + 1] for i, name in enumerate(TABLE_COLUMNS)}


def _matrix(values: dict[str, float], name: str, shape: tuple[int, int], default: float | None = None) -> np.ndarray:
    """Matrix ``name`` of ``shape`` from element-wise FMU variables (``A[1,2]``, ``B[2]``, ``D``)."""
    matrix = np.zeros(shape)
    for index in np.ndindex(*shape):
        names = [f"{name}[{index[0] + 1},{index[1] + 1}]",
                 f"{name}[{index[1] + 1 if shape[0] == 1 else index[0] + 1}]", name]
        matrix[index] = next((values[n] for n in names if n in values), default)
    return matrix


@dataclass(frozen=True)
class Loop:
    """The numbers of the closed loop: the plant's and the observer's ``(A, B, C, D)``, the gains, the
    constant reference and the initial states."""

    plant: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    observer: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    N: np.ndarray
    K: np.ndarray
    r: np.ndarray
    x0: np.ndarray
    x_hat0: np.ndarray


def loop(parameters: dict[str, float] | None = None) -> Loop:
    """The closed loop of ``parameters`` (``instance.variable``, see :class:`~fmus.result.RunInfo`;
    default: the system file's, :func:`file_parameters`), so that a run with other parameters has its own."""
    values = file_parameters() if parameters is None else parameters
    shapes = {p.name: p.shape for p in system().components["plant"].definitions[0].parameters}
    (n, m), p = shapes["B"], shapes["C"][0]
    own = {instance: {k.partition(".")[2]: v for k, v in values.items() if k.startswith(instance + ".")}
           for instance in INSTANCES}
    plant, observer = (tuple(_matrix(own[instance], name, shape) for name, shape in
                             (("A", (n, n)), ("B", (n, m)), ("C", (p, n)), ("D", (p, m))))
                       for instance in ("plant", "observer"))
    column = {"x0": ("plant", n), "x_hat0": ("observer", n), "r": ("controller", m)}
    x0, x_hat0, r = (_matrix(own[instance], name, (size, 1), default=0.0)[:, 0]
                     for name, (instance, size) in column.items())
    return Loop(plant, observer, _matrix(own["observer"], "N", (n, p)), _matrix(own["controller"], "K", (m, n)),
                r, x0, x_hat0)


def composite_matrices(parameters: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(Ae, be)`` of the closed loop ``xe' = Ae xe + be r``, ``xe = [x, x_hat]`` (eq. (12)), of
    :func:`loop` ``(parameters)``."""
    closed = loop(parameters)
    (Ap, Bp, Cp, Dp), (Ao, Bo, Co, Do) = closed.plant, closed.observer
    N, K, r = closed.N, closed.K, closed.r
    Bu = Bo + N @ (Dp - Do)                    # how u enters x_hat' (y = Cp x + Dp u)
    Ae = np.block([[Ap, -Bp @ K], [N @ Cp, Ao - N @ Co - Bu @ K]])
    return Ae, np.concatenate([Bp @ r, Bu @ r])


def composite_solution(times, x0=None, x_hat0=None, parameters: dict[str, float] | None = None) -> np.ndarray:
    """Exact ``xe(t)`` of the composite system (eq. (12), plus a constant reference ``r``); the initial
    states default to those of ``parameters``."""
    Ae, be = composite_matrices(parameters)
    size = Ae.shape[0]
    augmented = np.zeros((size + 1, size + 1))
    augmented[:size, :size], augmented[:size, size] = Ae, be
    if x0 is None or x_hat0 is None:
        closed = loop(parameters)
        x0, x_hat0 = closed.x0 if x0 is None else x0, closed.x_hat0 if x_hat0 is None else x_hat0
    xe0 = np.concatenate([x0, x_hat0, [1.0]])
    return np.array([expm(augmented * t) @ xe0 for t in np.asarray(times, dtype=float)])[:, :size]


def _table_columns(result: Result) -> dict[str, np.ndarray]:
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    return {"y": x[:, 0] - x_hat[:, 0], "x1": x[:, 0], "x2": x[:, 1], "x1_hat": x_hat[:, 0], "x2_hat": x_hat[:, 1]}


def table_deviation(result: Result) -> float:
    """Largest |co-simulation - printed value| over every printed table entry."""
    times, table = paper_table()
    columns = _table_columns(result)
    rows = [result.index_at(t) for t in times]
    worst = 0.0
    for name in TABLE_COLUMNS:
        printed = table[name]
        mask = ~np.isnan(printed)
        worst = max(worst, float(np.max(np.abs(columns[name][rows][mask] - printed[mask]))))
    return worst


def paper_table_applies(result: Result) -> str:
    """``""`` when the printed table is this run's (paper's parameters, table covered), else why not."""
    horizon = paper_table()[0][-1]
    if result.time[-1] < horizon - 1e-9:
        return f"the run ends at {result.time[-1]:g} s, the table at {horizon:g} s"
    return changed_parameters(result)


def summarize(result: Result) -> Summary:
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    error = x - x_hat
    grid = [result.index_at(t) for t in np.arange(0.0, result.time[-1] + 1e-12, 0.01)]
    parameters = result.info.parameters if result.info else None
    reference = composite_solution(result.time[grid], x[0], x_hat[0], parameters)
    deviation = float(np.max(np.abs(np.column_stack([x, x_hat])[grid] - reference)))
    metrics = {
        "final_error_x1": float(error[-1, 0]),
        "final_error_x2": float(error[-1, 1]),
        "max_error_vs_exact": deviation,
        "settling_time_y": settling_time(result.time, error[:, 0]),
        "settling_time_x1": settling_time(result.time, x[:, 0]),
        "observer_convergence_time": time_to_stay_below(result.time, error, 0.05 * np.abs(error).max()),
    }
    lines = [
        f"final estimation error x - x_hat = [{metrics['final_error_x1']:.3e}, {metrics['final_error_x2']:.3e}]",
        f"settling time (5 % of peak) of Ye = x1 - x1_hat: {format_time(metrics['settling_time_y'], result.time_unit)} "
        f"(paper fig. 4: <= 0.3 s); of x1: {format_time(metrics['settling_time_x1'], result.time_unit)}",
        f"observer error below 5 % of its peak after {format_time(metrics['observer_convergence_time'], result.time_unit)}",
    ]
    why_not = paper_table_applies(result)
    if not why_not:
        metrics["max_deviation_from_paper_table"] = table_deviation(result)
        lines.append(f"max |co-simulation - paper's printed table| = "
                     f"{metrics['max_deviation_from_paper_table']:.2e} (4 printed decimals: < 5e-5 reproduces them)")
    else:
        lines.append(f"the paper's printed table does not apply: {why_not}")
    changed = changed_parameters(result)
    own = f" of this run's parameters ({changed})" if changed and result.info else ""
    reference_line = (f"max |co-simulation - exact solution expm(Ae t) xe0{own}| on t = 0:0.01:{result.time[-1]:g} s: "
                      f"{deviation:.2e}")
    return Summary(lines, metrics, reference=reference_line)


def plot(result: Result, path: Path) -> list[Path]:
    t = result.time
    columns = _table_columns(result)
    show_table = not paper_table_applies(result)
    times, table = paper_table()
    panels = []
    for i in (1, 2):
        unit = result.unit(f"plant.x[{i}]")
        curves = [Curve(f"$x_{i}$ (plant)", t, columns[f"x{i}"], unit, "true", i - 1),
                  Curve(f"$\\hat x_{i}$ (observer)", t, columns[f"x{i}_hat"], unit, "estimate", i - 1)]
        if show_table:
            curves.append(Curve("paper's table", times, table[f"x{i}"], unit, "reference"))
        panels.append(Panel(f"state $x_{i}$", curves))
    unit = result.unit("plant.x[1]")
    error = [Curve("$x_1 - \\hat x_1$ (co-simulation)", t, columns["y"], unit, "error", 2)]
    if show_table:
        error.append(Curve("paper's table", times, table["y"], unit, "reference"))
    panels.append(Panel("output error $y_e = x_1 - \\hat x_1$", error))
    return figure(path, "paper 002: ship course stabilisation, plant + observer + state feedback FMUs", panels,
                  result.time_unit)


CLAIM = (
        "Paper 002 designs, by pole placement on the binomial standard form, a full-order observer "
        "(N = [83; 1847], eig(A - N C) = {-40, -40}) and a state feedback (K = [398, 43], "
        "eig(A - B K) = {-20, -20}) for an unstable course model (eig(A) = {1, 2}). For the free motion "
        "from x(0) = [0.05; 0.2] with x_hat(0) = 0 it prints a table of y = x1 - x1_hat and "
        "xe = [x1, x2, x1_hat, x2_hat] every 0.01 s to four decimals (for example xe(0.01) = "
        "[0.0513, 0.0106, 0.0309, 0.4386]), and its figures show the loop settled within 0.3 s.")

SCENARIO = paper_scenario(SYSTEM_FILE, "ship", summarize=summarize, plot=plot, claim=CLAIM, measure=MEASURE)
