"""The scenarios replayed FMU by FMU in fmusim agree with the project's master (issue 28.6).

The master runs a scenario (``run(..., order="jacobi")``, what ``obsfmu run --master jacobi`` runs; no start-up
ramp, as fmusim steps a regular grid); then each FMU runs alone in fmusim 0.0.39 with an input CSV of what
the master fed it -- its connected inputs at every communication point -- and its outputs are compared with
the master's columns of that instance.

How fmusim feeds inputs (``FMIApplyInput``, ``fmusim/FMIStaticInput.c``): before ``doStep(t, h)`` it sets the
input to the CSV's value at ``t``, linearly interpolated between rows -- at the CSV's own times, the recorded
value itself -- and nothing else: no input derivatives, the value held over the step unless the FMU does
more.  Our master's Jacobi round with linear coupling sends each input's value at ``t`` and the slope of the
last step, ``(u(t) - u(t - h)) / h``, as its derivative; ``<port>_interpolation = 1`` (extrapolate from the
previous communication point) makes the FMU compute that same slope from the values it is given.  So the
replay sets every connected input's ``_interpolation`` to 1 (``--start-value``) and the scenario's start
values, and must agree with the master to round-off: ``RTOL`` relative to each output's largest magnitude
(fmusim writes 16 digits; measured at most 9.5e-14 on ship, 6.7e-13 on ltv-ls-bounded's observer, whose least
squares amplify the last bits; with ``_interpolation = 0``, held inputs, ship's plant is off by 3e-4).
A direct-feedthrough FMU (ship's controller) is sampled by fmusim after ``doStep(t - h, h)`` and before the
inputs of ``t`` are set, so its row at ``t`` holds the outputs of the inputs at ``t - h``: compared so
(measured 2e-16).
"""

from __future__ import annotations

import csv

import numpy as np
import pytest
from fmpy import read_model_description

from obsfmu.fmus.fmi3.elements import elements
from obsfmu.fmus.scenarios import ensure_fmus, get, run
from test_third_party import fmusim, read_csv, run_tool, vendor_dir  # noqa: F401  (fixtures)

#: (scenario, stop time): ship's feedback loop (its controller a direct feedthrough) and paper 001's bounded case
CASES = [("ship", 0.05), ("ltv-ls-bounded", 2.0)]
RTOL = 1e-11


def connected_inputs(scenario, instance: str, names: list[str]) -> dict[str, str]:
    """FMU input element (FMI 2.0 name) -> the master's column that feeds it."""
    feeds = {}
    for connection in scenario.connections:
        target, port = connection.target.split(".", 1)
        if target != instance:
            continue
        targets = [n for n in names if n == port or n.startswith(port + "[")]
        suffixes = [n[len(port):] for n in targets]
        feeds.update({t: connection.source + s for t, s in zip(targets, suffixes)})
    return feeds


def write_inputs(path, master, feeds: dict[str, str], table: dict) -> None:
    """fmusim's input CSV: ``time`` and one column per input variable (an FMI 3.0 array: its elements, spaced)."""
    columns: dict[str, list[str]] = {}
    for element in feeds:
        columns.setdefault(table[element].variable, []).append(element)
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", *columns])
        for row, t in enumerate(master.time):
            writer.writerow([repr(float(t))] + [" ".join(repr(float(master[feeds[e]][row])) for e in elements_)
                                                for elements_ in columns.values()])


def start_values(start: dict[str, float], table: dict, fmi_version: int) -> list[str]:
    """``--start-value NAME VALUE`` for every start value (an FMI 3.0 array: all its elements, the rest declared)."""
    def literal(element, value) -> str:
        return repr(float(value)) if element.type in ("Real", "Float64") else str(int(value))

    if fmi_version == 2:
        return [item for name, value in start.items() for item in ("--start-value", name, literal(table[name], value))]
    options = []
    for variable in dict.fromkeys(table[name].variable for name in start):
        members = [e for e in table.values() if e.variable == variable]
        values = [literal(e, start[e.name]) if e.name in start else str(e.start) for e in members]
        options += ["--start-value", variable, " ".join(values)]
    return options


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("name, stop", CASES)
def test_each_fmu_alone_in_fmusim_reproduces_the_master(fmusim, build_dir, tmp_path, name, stop, fmi_version):
    scenario = get(name)
    fmus = ensure_fmus(scenario, build_dir, fmi_version=fmi_version)
    master, _ = run(name, build_dir, stop_time=stop, order="jacobi", fmi_version=fmi_version, ramp=0)
    step = scenario.step
    worst = {}
    for instance, model, start in scenario.components:
        description = read_model_description(str(fmus[model]))
        table = elements(description)
        feedthrough = any(unknown.dependencies for unknown in description.outputs)
        feeds = connected_inputs(scenario, instance, list(table))
        modes = {f"{table[e].variable}_interpolation": 1 for e in feeds if f"{table[e].variable}_interpolation" in table}
        options = start_values({**start, **modes}, table, fmi_version)
        (work := tmp_path / instance).mkdir()
        if feeds:
            write_inputs(work / "inputs.csv", master, feeds, table)
            options += ["--input-file", work / "inputs.csv"]
        out = work / "out.csv"
        completed = run_tool([fmusim, "--interface-type", "cs", "--start-time", "0", "--stop-time", repr(stop),
                              "--output-interval", repr(step), "--output-file", out, *options, fmus[model]], work)
        assert completed.returncode == 0, (instance, (completed.stdout + completed.stderr)[-2000:])
        names, theirs = read_csv(out)
        assert len(theirs) == len(master.time), (instance, len(theirs), len(master.time))
        np.testing.assert_allclose(theirs[:, 0], master.time, rtol=0, atol=1e-12)
        outputs = [n for n, e in table.items() if e.causality == "output"]
        ours = np.column_stack([master[f"{instance}.{n}"] for n in outputs])
        assert theirs.shape[1] - 1 == len(outputs), (names, outputs)
        if feedthrough:  # fmusim samples after doStep(t - h, h), before it sets the inputs of t: at t it records
            ours = np.vstack([ours[:1], ours[:-1]])  # the outputs of the inputs at t - h (at 0: of those at 0)
        scale = np.abs(ours).max(axis=0)
        worst[instance] = float((np.abs(theirs[:, 1:] - ours) / np.where(scale > 0, scale, 1)).max())
    assert max(worst.values()) < RTOL, worst
