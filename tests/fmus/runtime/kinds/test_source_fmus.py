"""The source kinds (fmus/runtime/kinds/sources.py) as FMUs, against the waveforms' formulas written here."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from fmpy import read_model_description

from obsfmu.fmus.runtime.kinds import sources as kinds
from kinds_support import build_all, simulate, started
from obsfmu.observers.checks import ParameterError
from obsfmu.plants.sources import PRBS

STOP, STEP = 2.0, 0.01


def chirp_phase(t):
    """Phase of the linear chirp below (0.5 Hz at t0 = 0.25 s to 4 Hz at t1 = 1.75 s), then 4 Hz."""
    tau = np.clip(t - 0.25, 0.0, 1.5)
    return 2 * np.pi * (0.5 * tau + 3.5 * tau ** 2 / 3.0 + 4.0 * np.maximum(t - 1.75, 0.0))

#: model -> (definition, y(t) written from the formula of the source's docstring)
CASES = {
    "constant": (kinds.constant_source_definition("constant", 1.5, unit="V"), lambda t: 1.5 + 0 * t),
    "step": (kinds.step_source_definition("step", time=0.505, height=2.0, offset=-1.0, unit="V"),
             lambda t: np.where(t >= 0.505, 1.0, -1.0)),
    "ramp": (kinds.ramp_source_definition("ramp", start_time=0.5, slope=3.0, offset=1.0, end_time=1.5, unit="m"),
             lambda t: 1.0 + 3.0 * np.clip(t - 0.5, 0.0, 1.0)),
    "sine": (kinds.sine_source_definition("sine", 2.0, 1.5, 0.3, 0.5, unit="V"),
             lambda t: 0.5 + 2.0 * np.sin(2 * np.pi * 1.5 * t + 0.3)),
    "multisine": (kinds.multisine_source_definition("multisine", [1.0, 0.5], [0.5, 3.0], [0.0, 1.0], 0.1),
                  lambda t: 0.1 + np.sin(np.pi * t) + 0.5 * np.sin(6 * np.pi * t + 1.0)),
    "chirp": (kinds.chirp_source_definition("chirp", 1.2, 0.5, 4.0, t0=0.25, t1=1.75, offset=0.2, unit="V"),
              lambda t: 0.2 + 1.2 * (t >= 0.25) * np.sin(chirp_phase(t))),
    "square": (kinds.square_source_definition("square", 2.0, period=0.4, duty=0.25, offset=1.0),
               lambda t: np.where(np.mod(t + 1e-9, 0.4) < 0.1 - 1e-9, 3.0, -1.0)),
    "table": (kinds.table_source_definition("table", [0.0, 0.5, 1.0, 1.6], [0.0, 1.0, -1.0, 2.0], unit="N"),
              lambda t: np.interp(t, [0.0, 0.5, 1.0, 1.6], [0.0, 1.0, -1.0, 2.0])),
    "previous": (kinds.table_source_definition("previous", [0.3, 0.805], [2.0, 5.0], "previous"),
                 lambda t: np.where(t >= 0.805, 5.0, 2.0)),
    "prbs": (kinds.prbs_source_definition("prbs", 0.5, bit_period=0.05, seed=9, register_length=5),
             lambda t: PRBS(0.5, 0.05, 9, 5).value(t)),     # the sequence itself: tests/plants/test_sources.py
}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build_all([definition for definition, _ in CASES.values()], tmp_path_factory.mktemp("sources"))


@pytest.mark.parametrize("model", sorted(CASES))
def test_each_source_fmu_gives_its_formula_at_every_communication_point(fmus, model):
    result = simulate(fmus[model], STOP, STEP)
    expected = CASES[model][1](result["time"])
    np.testing.assert_allclose(result["y"], expected, rtol=1e-12, atol=1e-12)


def test_every_numeric_setting_is_a_parameter_that_a_start_value_changes(fmus):
    result = simulate(fmus["sine"], 1.0, STEP, amplitude=3.0, frequency_hz=0.25, phase=0.0, offset=0.0)
    np.testing.assert_allclose(result["y"], 3.0 * np.sin(0.5 * np.pi * result["time"]), atol=1e-12)
    result = simulate(fmus["table"], 1.0, STEP, **{"values[2]": 4.0})
    np.testing.assert_allclose(result["y"], np.interp(result["time"], [0, 0.5, 1, 1.6], [0, 4, -1, 2]), atol=1e-12)
    result = simulate(fmus["prbs"], 1.0, STEP, seed=3.0)
    np.testing.assert_array_equal(result["y"], PRBS(0.5, 0.05, 3, 5).value(result["time"]))


def test_options_and_units_are_in_the_model_description(fmus):
    description = read_model_description(str(fmus["chirp"]))
    units = {v.name: v.unit for v in description.modelVariables}
    assert units["y"] == "V" and units["f0_hz"] == "Hz" and units["t1"] == "s" and units["amplitude"] == "V"
    assert description.coSimulation.maxOutputDerivativeOrder == 1
    assert {v.name for v in description.modelVariables if v.causality == "parameter"} == \
        {"amplitude", "f0_hz", "f1_hz", "t0", "t1", "phase", "offset"}


def test_a_csv_column_is_read_at_build_time_and_the_fmu_needs_no_file(tmp_path):
    data = tmp_path / "profile.csv"
    data.write_text("time,speed,other\n0,1.0,9\n0.5,2.0,9\n\n1.0,0.0,9\n")
    path, = build_all([kinds.csv_source_definition("profile", data, "speed", unit="m/s")], tmp_path / "out").values()
    data.unlink()
    result = simulate(path, 1.5, 0.05)
    np.testing.assert_allclose(result["y"], np.interp(result["time"], [0, 0.5, 1.0], [1.0, 2.0, 0.0]), atol=1e-12)
    assert read_model_description(str(path)).modelVariables[0].name == "times[1]"


@pytest.mark.parametrize("make, field", [
    (lambda: kinds.chirp_source_definition("c", t0=2.0, t1=1.0), "t1"),
    (lambda: kinds.table_source_definition("t", [0.0, 1.0, 1.0], [1, 2, 3]), "times"),
    (lambda: kinds.table_source_definition("t", [0.0, 1.0], [1, 2], "cubic"), "interpolation"),
    (lambda: kinds.prbs_source_definition("p", register_length=40), "register_length"),
    (lambda: kinds.square_source_definition("s", duty=1.5), "duty"),
    (lambda: kinds.csv_source_definition("v", "/nonexistent/file.csv", "speed"), "path"),
])
def test_a_bad_setting_is_refused_at_build_time_naming_it(make, field):
    with pytest.raises(ParameterError, match=f"^{field}"):
        make()


@pytest.mark.parametrize("model, derivative", [
    ("sine", lambda t: 2.0 * 3 * np.pi * np.cos(3 * np.pi * t + 0.3)),
    ("ramp", lambda t: 3.0 * (0.5 <= t < 1.5)),
    ("chirp", lambda t: 1.2 * 2 * np.pi * (0.5 + 3.5 * np.clip(t - 0.25, 0, 1.5) / 1.5) * np.cos(chirp_phase(t))
     * (t >= 0.25)),
    ("table", lambda t: [2.0, -4.0, 5.0, 0.0][int(np.searchsorted([0.5, 1.0, 1.6], t, side="right"))]),
    ("step", lambda t: 0.0),
])
def test_the_exact_output_derivative_is_given_by_fmi2GetRealOutputDerivatives(fmus, model, derivative):
    slave, refs = started(fmus[model], model)
    t, h = 0.0, 0.07
    try:
        for _ in range(25):
            slave.doStep(t, h)
            t += h
            got, = slave.getRealOutputDerivatives([refs["y"]], [1])
            assert got == pytest.approx(derivative(t), rel=1e-12, abs=1e-12), t
        with pytest.raises(Exception, match="status 3"):
            slave.getRealOutputDerivatives([refs["y"]], [2])                  # order 2: refused ...
        assert slave.getRealOutputDerivatives([refs["y"]], [1]) == [pytest.approx(derivative(t), abs=1e-12)]
    finally:
        slave.terminate()
        slave.freeInstance()


def test_the_derivative_of_a_smooth_source_makes_the_linear_input_of_a_step_exact(fmus):
    """A master sending y(t) and dy/dt(t) of a ramp as the input and its derivative: the consumer's
    linear input is exact over the whole step (what the derivative is for)."""
    slave, refs = started(fmus["ramp"], "ramp")
    try:
        slave.doStep(0.0, 0.6)
        value, = slave.getReal([refs["y"]])
        slope, = slave.getRealOutputDerivatives([refs["y"]], [1])
        slave.doStep(0.6, 0.5)
        end, = slave.getReal([refs["y"]])
        assert value + 0.5 * slope == pytest.approx(end, abs=1e-12) == 1.0 + 3.0 * 0.6
        assert math.isclose(slope, 3.0)
    finally:
        slave.terminate()
        slave.freeInstance()


# ------------------------------------------------------------------ csv sources a stranger's file cannot abuse (issue 37)
def _csv_file(path: str, extra: str = "") -> str:
    return (f'name = "c"\nconnections = []\n[experiment]\nstop_time = 1.0\nstep = 0.1\n[components.src]\n'
            f'kind = "csv"\npath = "{path}"\ncolumn = "u"\n{extra}')


@pytest.mark.parametrize("path, extra, message", [
    ("/dev/zero", "outside_folder = true", "/dev/zero is not a regular file"),     # grew to 3.85 GB before
    ("fifo", "", "is not a regular file"),                                         # blocked forever before
    ("/etc/passwd", "", "'/etc/passwd' is outside the system file's folder"),
    ("../x.csv", "", "'../x.csv' is outside the system file's folder"),
    ("big.csv", "", "more than the limit of 64 MiB"),                              # a sparse file: no disk used
    ("secret.txt", "", "its first line is not a header of comma-separated column names"),
    ("folder", "", "folder is not a regular file"),
    ("link.csv", "", "'link.csv' is outside the system file's folder"),                # a link leading out
    ("cells.csv", "", "row 2, column 'u': expected a number, got 'abcdefghijklmnopqrstuvwx'... (48 characters)"),
])
def test_a_csv_source_reads_regular_files_in_its_folder_within_a_limit_and_quotes_none(tmp_path, path, extra,
                                                                                        message):
    from obsfmu.fmus.system.load import parse_system
    os.mkfifo(tmp_path / "fifo")
    with open(tmp_path / "big.csv", "wb") as big:
        big.truncate(65 * 2 ** 20)
    (tmp_path / "secret.txt").write_text("root:$6$hash-not-to-be-quoted:19000:0:99999:7:::\n")
    (tmp_path / "folder").mkdir()
    (tmp_path / "link.csv").symlink_to(tmp_path.parent / "elsewhere.csv")
    (tmp_path / "cells.csv").write_text("time,u\n0,abcdefghijklmnopqrstuvwxyz-hash-not-to-be-quoted\n")
    with pytest.raises(ParameterError) as refused:
        parse_system(_csv_file(path, extra), "c.toml", tmp_path)
    text = str(refused.value)
    assert message in text and "hash-not-to-be-quoted" not in text and "\n" not in text, text


def test_a_csv_file_outside_the_folder_is_read_when_the_file_says_so(tmp_path):
    from obsfmu.fmus.system.load import parse_system
    (tmp_path / "data.csv").write_text("time,u\n0,1\n1,3\n")
    (tmp_path / "sub").mkdir()
    spec = parse_system(_csv_file("../data.csv", "outside_folder = true"), "c.toml", tmp_path / "sub")
    definition, = spec.components["src"].definitions
    values = next(p for p in definition.parameters if p.name == "values")
    np.testing.assert_array_equal(np.ravel(values.value), [1.0, 3.0])
