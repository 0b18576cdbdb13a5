"""Scenario ``ship`` -- paper 002: modal observer and state feedback for ship course stabilisation.

Three FMUs built from ``ship.toml``: the unstable plant (eig(A) = {1, 2}),
the Luenberger observer (N = [83; 1847], eig(A - N C) = {-40, -40}) and the
state feedback u = -K x_hat (K = [398, 43], eig(A - B K) = {-20, -20}).
Free motion from x(0) = [0.05; 0.2], x_hat(0) = 0, zero reference, 0..1 s.

The summary compares the run with the exact composite solution ``expm(Ae t) xe0`` (eq. (12)) and
with the paper's printed table (``paper_table.csv``).  Default: 2e-5 s, Gauss-Seidel, linear
coupling -- the step at which every printed digit is reproduced (the measurements:
``docs/paper002.md``, section 3).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from observers.integrators import expm

from ...config import LinearDesign, design_from_config, load_config
from ...master import Connection
from ...metrics import format_time, settling_time, time_to_stay_below
from ...plotting import Curve, Panel, figure
from ...result import Result
from .. import Scenario, Summary, changed_parameters
from .measures import MEASURE

HERE = Path(__file__).parent
CONFIG = HERE / "ship.toml"
PAPER_TABLE = HERE / "paper_table.csv"
TABLE_COLUMNS = ("y", "x1", "x2", "x1_hat", "x2_hat")


@lru_cache(maxsize=1)
def design() -> LinearDesign:
    return design_from_config(load_config(CONFIG))


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


def composite_matrices(parameters: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(Ae, be)`` of the closed loop ``xe' = Ae xe + be r``, ``xe = [x, x_hat]`` (eq. (12)).

    The plant, the observer's own model, ``N``, ``K`` and the constant reference ``r`` are read
    from ``parameters`` (``instance.variable``, see :class:`~fmus.result.RunInfo`; default: the
    paper's design), so a run with other parameters has its own exact solution.
    """
    d = design()
    n, m, p = d.model.n, d.model.m, d.model.p
    if parameters is None:
        model = (d.model.A, d.model.B, d.model.C, d.model.D)
        plant = observer = model
        N, K, r = d.N, d.K, np.zeros(m)
    else:
        values = {instance: {k.partition(".")[2]: v for k, v in parameters.items() if k.startswith(instance + ".")}
                  for instance in ("plant", "observer", "controller")}
        plant, observer = (tuple(_matrix(values[instance], name, shape) for name, shape in
                                 (("A", (n, n)), ("B", (n, m)), ("C", (p, n)), ("D", (p, m))))
                           for instance in ("plant", "observer"))
        N = _matrix(values["observer"], "N", (n, p))
        K = _matrix(values["controller"], "K", (m, n))
        r = _matrix(values["controller"], "r", (m, 1), default=0.0)[:, 0]
    (Ap, Bp, Cp, Dp), (Ao, Bo, Co, Do) = plant, observer
    Bu = Bo + N @ (Dp - Do)                    # how u enters x_hat' (y = Cp x + Dp u)
    Ae = np.block([[Ap, -Bp @ K], [N @ Cp, Ao - N @ Co - Bu @ K]])
    return Ae, np.concatenate([Bp @ r, Bu @ r])


def composite_solution(times, x0=None, x_hat0=None, parameters: dict[str, float] | None = None) -> np.ndarray:
    """Exact ``xe(t)`` of the composite system (eq. (12), plus a constant reference ``r``)."""
    d = design()
    Ae, be = composite_matrices(parameters)
    size = Ae.shape[0]
    augmented = np.zeros((size + 1, size + 1))
    augmented[:size, :size], augmented[:size, size] = Ae, be
    xe0 = np.concatenate([d.x0 if x0 is None else x0, d.x_hat0 if x_hat0 is None else x_hat0, [1.0]])
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


def definitions():
    return design().definitions()


CLAIM = (
        "Paper 002 designs, by pole placement on the binomial standard form, a full-order observer "
        "(N = [83; 1847], eig(A - N C) = {-40, -40}) and a state feedback (K = [398, 43], "
        "eig(A - B K) = {-20, -20}) for an unstable course model (eig(A) = {1, 2}). For the free motion "
        "from x(0) = [0.05; 0.2] with x_hat(0) = 0 it prints a table of y = x1 - x1_hat and "
        "xe = [x1, x2, x1_hat, x2_hat] every 0.01 s to four decimals (for example xe(0.01) = "
        "[0.0513, 0.0106, 0.0309, 0.4386]), and its figures show the loop settled within 0.3 s.")

SCENARIO = Scenario(
    name="ship",
    description="paper 002: ship course observer + modal state feedback (free motion, 0..1 s)",
    definitions=definitions,
    components=[("plant", "ship_plant", {}), ("observer", "ship_observer", {}),
                ("controller", "ship_controller", {"r": 0.0})],
    connections=[
        Connection("plant.y", "observer.y"),
        Connection("controller.u", "observer.u"),
        Connection("controller.u", "plant.u"),
        Connection("observer.x_hat", "controller.x_hat"),
    ],
    stop_time=1.0,
    step=2e-5,
    order="gauss-seidel",
    coupling="linear",
    summarize=summarize,
    plot=plot,
    claim=CLAIM,
    measure=MEASURE,
    output_interval=1e-3,
)
