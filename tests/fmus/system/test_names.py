"""Issue 38: names of a plant's states, inputs and outputs (``state_names``, ``input_names``, ``output_names`` of
an ``lti`` component), carried by its observer and feedback: in the FMUs' variable descriptions, ``show``, the
summaries and the figures.  The CSV columns keep ``plant.x[i]`` (connections, ``--set`` and scripts stay as they
are); numpy's ``genfromtxt`` reads them with ``deletechars=""`` (docs/python.md)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from obsfmu.fmus.runtime.slave import BlockSlave
from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE = (ROOT / "examples" / "dcmotor.toml").read_text()
NAMES = 'state_names = ["current", "speed", "angle"]\ninput_names = ["voltage"]\noutput_names = ["measured angle"]\n'
NAMED = EXAMPLE.replace('output_units = "rad"\n', 'output_units = "rad"\n' + NAMES, 1)


def definition(spec, instance):
    return spec.components[instance].definitions[0]


def test_names_reach_the_ports_of_the_plant_its_observer_and_its_feedback():
    assert NAMED != EXAMPLE
    spec = parse_system(NAMED, str(ROOT / "examples" / "named.toml"))
    ports = {(instance, port.name): port.labels for instance in ("plant", "observer", "controller")
             for port in definition(spec, instance).inputs + definition(spec, instance).outputs}
    assert ports[("plant", "x")] == ports[("observer", "x_hat")] == ports[("controller", "x_hat")] == \
        ["current", "speed", "angle"]
    assert ports[("plant", "u")] == ports[("controller", "u")] == ["voltage"]
    assert ports[("plant", "y")] == ports[("observer", "y_hat")] == ["measured angle"]
    assert spec.labels()["plant.x[2]"] == "speed" and spec.labels()["observer.x_hat[3]"] == "angle"


def test_the_fmus_variables_are_described_by_name(tmp_path):
    plant = definition(parse_system(NAMED, str(ROOT / "examples" / "named.toml")), "plant")
    (tmp_path / "plant.json").write_text(plant.to_json())

    class Plant(BlockSlave):
        definition_file = "plant.json"

    instance = Plant(instance_name="plant", resources=str(tmp_path), visible=False, logger=None)
    described = {variable.name: variable.description for variable in instance.vars.values()}
    assert described["x[1]"] == "true state x: current" and described["x[3]"] == "true state x: angle"
    assert described["u"] == "plant input u: voltage"


def test_show_and_the_summary_name_the_entries(tmp_path):
    (tmp_path / "named.toml").write_text(NAMED)
    shown = subprocess.run([sys.executable, "-m", "obsfmu", "show", "--config", "named.toml"], cwd=tmp_path,
                           capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert shown.returncode == 0, shown.stderr
    assert "out plant.x[1..3] (A, rad/s, rad): true state x = [current, speed, angle]" in shown.stdout


@pytest.mark.parametrize("fields, message", [
    ('state_names = ["current", "speed"]\n', r"components.plant.state_names: expected 3 names \(one per state\), got 2"),
    ('state_names = ["current", "speed", "current"]\n', r"state_names\[3\]: 'current' is named twice"),
    ('state_names = ["current", "", "angle"]\n', r"state_names\[2\]: a name must not be empty"),
    ('input_names = "voltage"\n', "input_names: expected a list of names"),
])
def test_wrong_names_are_refused_naming_the_field(fields, message):
    with pytest.raises(ParameterError, match=message):
        parse_system(EXAMPLE.replace('output_units = "rad"\n', 'output_units = "rad"\n' + fields, 1),
                     str(ROOT / "examples" / "named.toml"))


PLOT = '\n[plot]\nsignals = ["reference.y", "controller.u", "plant.x[2]"]\n'


def test_a_plot_section_adds_panels_of_the_signals_it_names(tmp_path, build_dir):
    """Issue 38: the figure drew the comparisons only (a road input or an actuator force never).  [plot] signals
    adds a panel per output, with its units and names; a signal that is no output is refused naming it."""
    spec = parse_system(NAMED + PLOT, str(ROOT / "examples" / "named.toml"))
    assert spec.plotted == [["reference.y"], ["controller.u"], ["plant.x[2]"]]
    (tmp_path / "named.toml").write_text(NAMED + PLOT)
    done = subprocess.run([sys.executable, "-m", "obsfmu", "run", "--config", "named.toml", "--stop-time", "0.05",
                           "--build-dir", str(build_dir), "--plot", "figure.png"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    svg = (tmp_path / "figure.svg").read_text()
    assert "controller.u (voltage)" in svg and "plant.x[2] (speed)" in svg and "reference.y" in svg
    with pytest.raises(ParameterError, match=r"plot.signals\[2\]: plant has no output 'z'; known: y, x"):
        parse_system(NAMED + PLOT.replace('"controller.u"', '"plant.z"'), str(ROOT / "examples" / "named.toml"))
    with pytest.raises(ParameterError, match=r"plot.panels: unknown field; known: signals"):
        parse_system(NAMED + "\n[plot]\npanels = 1\n", str(ROOT / "examples" / "named.toml"))
