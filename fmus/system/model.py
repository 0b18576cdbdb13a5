"""The checked system of a file, and the :class:`~fmus.scenarios.Scenario` it runs as.

:meth:`SystemSpec.scenario` makes a scenario like a paper's: its FMUs (``<name>_<component>``), the
instances in the order of the file, the connections, the explicit input values as start values, the
experiment's defaults, and a summary and figure from ``[[report.compare]]``: per comparison the final
error and the convergence time (from when ``|truth - estimate|`` stays below the tolerance), per
component; the figure shows truth vs estimate per entry and the error, with the FMUs' units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["ComponentSpec", "SystemSpec"]

#: an own system without ``[report] reference`` prints no reference line (docs/your-own-system.md says how to add one)
NO_REFERENCE = ""


@dataclass
class ComponentSpec:
    """One component: its type, its field values (defaults filled in), the fields given, its FMU definitions."""

    instance: str
    kind: str
    values: dict
    given: set
    definitions: list


@dataclass
class SystemSpec:
    """A checked system file (see :func:`fmus.system.load.load_system`)."""

    name: str
    description: str
    time_unit: str
    components: dict[str, ComponentSpec]
    connections: list
    values: dict[str, dict[str, float]]
    experiment: dict
    compares: list[dict]
    notes: list[str] = field(default_factory=list)   #: the designed gains and poles
    path: str = ""
    reference: Path | None = None                     #: a CSV of the same columns to compare with
    fastest: tuple[float, str] | None = None          #: the fastest rate of its dynamics and signals, and whose
    plotted: list[list[str]] = field(default_factory=list)   #: ``[plot] signals``: the columns of each panel

    def definitions(self) -> list:
        """Every component's FMU definitions; one without a DefaultExperiment gets the file's ``[experiment]``."""
        from dataclasses import replace

        from ..runtime.definition import experiment
        default = experiment(self.experiment["stop_time"], self.experiment["step"])
        return [d if d.default_experiment is not None else replace(d, default_experiment=default)
                for spec in self.components.values() for d in spec.definitions]

    def scenario(self):
        """The :class:`~fmus.scenarios.Scenario` of this system: run, export, sweep and report work on it.

        Returns
        -------
        fmus.scenarios.Scenario
            Named as the file; its FMUs ``<name>_<component>``, instances in the file's order, the
            ``[values]`` as start values, the experiment as defaults, summary, figure and sweep measure
            from ``[[report.compare]]``.
        """
        from ..scenarios import Scenario
        experiment = self.experiment
        return Scenario(
            name=self.name, description=self.description or f"system file {self.path}",
            definitions=self.definitions,
            components=[(instance, spec.definitions[0].model_name, dict(self.values.get(instance, {})))
                        for instance, spec in self.components.items()],
            connections=list(self.connections), stop_time=experiment["stop_time"], step=experiment["step"],
            order=experiment["master"], coupling=experiment["coupling"], summarize=self.summarize,
            plot=self.plot if self.compares or self.plotted else None, time_unit=self.time_unit,
            output_interval=experiment["output_interval"], measure=self.measure(), tolerance=experiment["tolerance"],
            ramp=experiment["ramp"], claim="",
            system_file=Path(self.path) if self.path else None, fastest=self.fastest)

    def measure(self):
        """What ``obsfmu sweep`` measures: the largest convergence time and final error of the comparisons."""
        if not self.compares:
            return None
        from ..campaign.measures import Measure
        estimates = [c for compare in self.compares for c in compare["estimate_columns"]]
        tolerances = ", ".join(f"{compare['tolerance']:g}" for compare in self.compares)
        noise = tuple((f"fluctuation {c}", compare["tolerance"]) for compare in self.compares
                      for c in compare["estimate_columns"])
        return Measure(tuple(f"convergence_time {c}" for c in estimates), tuple(f"final_error {c}" for c in estimates),
                       f"every |truth - estimate| below its tolerance ({tolerances})", "max final |truth - estimate|",
                       noise=noise)

    # ------------------------------------------------------------------ summary and figure
    def _pairs(self, result, compare) -> tuple[np.ndarray, np.ndarray]:
        estimate = np.column_stack([result[c] for c in compare["estimate_columns"]])
        truth = np.column_stack([result[c] for c in compare["truth_columns"]])
        return estimate, truth

    def labels(self) -> dict[str, str]:
        """Column -> the name its plant gave the entry (``state_names`` ...): ``{"plant.x[1]": "current"}``."""
        from ..runtime.definition import column_labels
        return column_labels((instance, definition) for instance, component in self.components.items()
                             for definition in component.definitions)

    def summarize(self, result):
        """Final error and convergence time per compared entry; the reference line (none, or the CSV's)."""
        from ..metrics import HOLD, fluctuation, format_time, time_to_stay_below
        from ..scenarios import Summary
        lines, metrics = [], {}
        unit, labels = result.time_unit, self.labels()
        for compare in self.compares:
            estimate, truth = self._pairs(result, compare)
            error = truth - estimate
            for j, (e_name, t_name) in enumerate(zip(compare["estimate_columns"], compare["truth_columns"])):
                converged = time_to_stay_below(result.time, error[:, j], compare["tolerance"])
                final = float(abs(error[-1, j]))
                metrics[f"final_error {e_name}"] = final
                metrics[f"convergence_time {e_name}"] = converged
                column_unit = f" {result.unit(t_name)}" if result.unit(t_name) else ""
                named = f" ({labels[t_name]})" if t_name in labels else ""
                lines.append(f"{e_name} vs {t_name}{named}: final |error| {final:.3g}{column_unit}, "
                             f"below {compare['tolerance']:g} from {format_time(converged, unit)}")
                spread = metrics[f"fluctuation {e_name}"] = fluctuation(result.time, error[:, j])
                if 3.0 * spread > compare["tolerance"]:
                    lines.append(f"  noise: over the last {100 * HOLD:g} % of the run the error fluctuates by 3 "
                                 f"standard deviations = {3.0 * spread:.3g}{column_unit}, above the tolerance "
                                 f"{compare['tolerance']:g}: the tolerance is below the noise-induced error")
        if not lines:
            lines.append("nothing compared (add [[report.compare]] tables with estimate and truth)")
        return Summary(lines, metrics, self._reference(result))

    def _reference(self, result) -> str:
        if self.reference is None:
            return NO_REFERENCE
        from ..result import Result
        try:
            reference = Result.from_csv(self.reference)
        except (OSError, ValueError) as exc:
            return f"reference: {self.reference} cannot be read ({exc})"
        common = [c for c in reference.columns if c in result.columns]
        if not common:
            return f"reference: {self.reference} has none of the run's columns"
        inside = (reference.time >= result.time[0]) & (reference.time <= result.time[-1])
        deviation = max(float(np.max(np.abs(np.interp(reference.time[inside], result.time, result[c])
                                            - reference[c][inside]), initial=0.0)) for c in common)
        return (f"reference: {self.reference.name}, max |run - reference| {deviation:.3g} over {len(common)} "
                f"columns at its {int(inside.sum())} times")

    def plot(self, result, path: Path) -> list[Path]:
        """Truth vs estimate per compared entry and the errors (log scale), with the FMUs' units."""
        from ..plotting import Curve, Panel, figure
        panels, errors, limits, labels = [], [], set(), self.labels()
        key = 0                           # one colour per compared quantity, across every comparison
        for compare in self.compares:
            estimate, truth = self._pairs(result, compare)
            for j, (e_name, t_name) in enumerate(zip(compare["estimate_columns"], compare["truth_columns"])):
                unit = result.unit(t_name)
                title = f"{t_name} ({labels[t_name]})" if t_name in labels else t_name
                panels.append(Panel(title, [Curve(t_name, result.time, truth[:, j], unit, "true", key),
                                             Curve(e_name, result.time, estimate[:, j], unit, "estimate", key)]))
                errors.append(Curve(f"{t_name} - {e_name}", result.time, truth[:, j] - estimate[:, j], unit,
                                    "error", key))
                key += 1
            if compare["tolerance"] not in limits:         # one line per distinct tolerance (was one per comparison)
                limits.add(compare["tolerance"])
                errors.append(Curve(f"tolerance {compare['tolerance']:g}", result.time,
                                    np.full(result.time.shape, compare["tolerance"]), role="limit"))
        for columns in self.plotted:                     # [plot] signals: a panel each, named and with units
            title = columns[0].rsplit("[", 1)[0] if len(columns) > 1 else columns[0]
            panels.append(Panel(title, [Curve(c if c not in labels else f"{c} ({labels[c]})", result.time, result[c],
                                              result.unit(c), "signal", key + k) for k, c in enumerate(columns)]))
        if errors:
            panels.append(Panel("|error|", errors, log=True))
        return figure(path, f"{self.name}: {self.description}" if self.description else self.name, panels,
                      result.time_unit)
