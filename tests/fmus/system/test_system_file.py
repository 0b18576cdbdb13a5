"""The system file (issue 26): a DC motor with observer, state feedback, a chirp reference and noisy
measurements, run through the CLI and compared with an independent scipy solution; every bad file is
one line, exit 2, no traceback and no FMU; the checked-in field reference is the generated one."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import place_poles

from obsfmu.observers.checks import ParameterError

ROOT = Path(__file__).resolve().parents[3]

# the motor: L di/dt = -R i - k w + V, J dw/dt = k i - b w, dtheta/dt = w (R 2, L 0.5, k 0.1, J 0.02, b 0.2)
A = np.array([[-4.0, -0.2, 0.0], [5.0, -10.0, 0.0], [0.0, 1.0, 0.0]])
B = np.array([[2.0], [0.0], [0.0]])
C = np.array([[0.0, 0.0, 1.0]])
X0 = np.array([0.0, 0.0, 0.1])
OBSERVER_POLES, CONTROLLER_POLES = [-40.0, -45.0, -50.0], [-15.0, -18.0, -20.0]
CHIRP = dict(amplitude=0.5, f0_hz=0.1, f1_hz=5.0, t1=2.0)


def motor_file(noise_std: float = 0.0) -> str:
    """The system file of the test (noise-free: std 0)."""
    return f'''name = "dcmotor"
description = "DC motor: current, speed, angle; observer + state feedback"
connections = [
    "reference.y -> controller.r",
    "plant.y -> sensor.u",
    "sensor.y -> observer.y",
    "controller.u -> plant.u",
    "controller.u -> observer.u",
    "observer.x_hat -> controller.x_hat",
]

[experiment]
stop_time = 2.0
step = 1e-4

[components.reference]
kind = "chirp"
amplitude = {CHIRP["amplitude"]}
f0_hz = {CHIRP["f0_hz"]}
f1_hz = {CHIRP["f1_hz"]}
t1 = {CHIRP["t1"]}
unit = "V"

[components.plant]
kind = "lti"
A = {A.tolist()}
B = {B.tolist()}
C = {C.tolist()}
x0 = {X0.tolist()}
state_units = ["A", "rad/s", "rad"]
input_units = "V"
output_units = "rad"

[components.sensor]
kind = "added-noise"
std = {noise_std}
seed = 7
unit = "rad"

[components.observer]
kind = "luenberger"
plant = "plant"
poles = {OBSERVER_POLES}

[components.controller]
kind = "state-feedback"
plant = "plant"
poles = {CONTROLLER_POLES}

[[report.compare]]
estimate = "observer.x_hat"
truth = "plant.x"
tolerance = 1e-3
'''


def obsfmu(*args, cwd: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "obsfmu", *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=600)


def reference_solution(times: np.ndarray) -> np.ndarray:
    """Plant and observer in closed loop, one ODE of 6 states (scipy only): columns x, x_hat."""
    K = place_poles(A, B, CONTROLLER_POLES).gain_matrix
    N = place_poles(A.T, C.T, OBSERVER_POLES).gain_matrix.T
    T = CHIRP["t1"]

    def r(t):
        phase = 2 * np.pi * (CHIRP["f0_hz"] * t + (CHIRP["f1_hz"] - CHIRP["f0_hz"]) * t ** 2 / (2 * T))
        return CHIRP["amplitude"] * np.sin(phase)

    def rhs(t, z):
        x, x_hat = z[:3], z[3:]
        u = -K @ x_hat + r(t)
        return np.concatenate([A @ x + B @ u, A @ x_hat + B @ u + N @ (C @ x - C @ x_hat)])

    solution = solve_ivp(rhs, (times[0], times[-1]), np.concatenate([X0, np.zeros(3)]), t_eval=times,
                         method="DOP853", rtol=1e-11, atol=1e-13)
    return solution.y.T


def read_csv(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    header = path.read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return data[:, 0], {name: data[:, j] for j, name in enumerate(header)}


def test_dc_motor_through_the_cli_agrees_with_scipy(tmp_path):
    """Noise-free: the co-simulation (Gauss-Seidel, linear coupling, h = 0.1 ms) within 2e-4 of the monolithic
    solution in every state and estimate, relative to the largest value of each (measured: 8.7e-5; the coupling
    error is second order in h: 8.3e-3 at h = 1 ms, 5.4e-4 at 0.25 ms)."""
    (tmp_path / "dcmotor.toml").write_text(motor_file())
    done = obsfmu("run", "--config", "dcmotor.toml", "--csv", "out.csv", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "observer.x_hat[1] vs plant.x[1]" in done.stdout and "none applies" not in done.stdout   # own-system wording (issue 38)
    time, columns = read_csv(tmp_path / "out.csv")
    assert time[-1] == pytest.approx(2.0)
    run = np.column_stack([columns[f"plant.x[{i}]"] for i in (1, 2, 3)]
                          + [columns[f"observer.x_hat[{i}]"] for i in (1, 2, 3)])
    reference = reference_solution(time)
    scale = np.abs(reference).max(axis=0)
    deviation = np.abs(run - reference).max(axis=0) / scale
    assert deviation.max() < 2e-4, deviation
    assert np.abs(columns["plant.x[3]"]).max() > 0.05          # it moved: the comparison is not of zeros


def test_noisy_measurements_run_plot_export_and_report(tmp_path):
    (tmp_path / "dcmotor.toml").write_text(motor_file(noise_std=1e-4))
    done = obsfmu("run", "--config", "dcmotor.toml", "--csv", "out.csv", "--plot", "out.png", "--build-dir",
                  "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    time, columns = read_csv(tmp_path / "out.csv")
    noise = columns["sensor.y"] - columns["plant.y"]
    assert 0.5e-4 < noise.std() < 2e-4                          # the noise is there, of its std
    assert (tmp_path / "out.png").exists() and (tmp_path / "out.svg").exists()
    exported = obsfmu("export", "--config", "dcmotor.toml", "--format", "ssp", "--out", "ssp", "--build-dir",
                      "build", cwd=tmp_path)
    assert exported.returncode == 0, exported.stderr
    assert (tmp_path / "ssp" / "dcmotor.ssp").exists()
    reported = obsfmu("report", "--config", "dcmotor.toml", "--out", "results", "--build-dir", "build", cwd=tmp_path)
    assert reported.returncode == 0, reported.stderr
    page = (tmp_path / "results" / "report.html").read_text()
    assert 'id="dcmotor"' in page and (tmp_path / "results" / "dcmotor.csv").exists()
    from obsfmu.fmus import report                     # a plain 'obsfmu report' there keeps the file's entry
    assert report.other_runs(tmp_path / "results") == ["dcmotor"]
    assert 'id="dcmotor"' in report.write_report(tmp_path / "results", tmp_path / "build").read_text()


def test_build_prints_the_designed_gains_and_writes_fmus_with_the_umask(tmp_path):
    text = motor_file().replace(f"poles = {OBSERVER_POLES}", 't_settle = 0.2\nform = "binomial"')
    (tmp_path / "dcmotor.toml").write_text(text)
    done = obsfmu("build", "--config", "dcmotor.toml", "--out", "fmus", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    observer = next(line for line in done.stdout.splitlines() if line.startswith("components.observer: N = "))
    assert "eig(A - N C) = [" in observer
    assert any(line.startswith("components.controller: K = ") for line in done.stdout.splitlines())
    fmus = sorted(p.name for p in (tmp_path / "fmus").glob("*.fmu"))
    assert fmus == [f"dcmotor_{n}.fmu" for n in ("controller", "observer", "plant", "reference", "sensor")]
    umask = os.umask(0)
    os.umask(umask)
    assert all((p.stat().st_mode & 0o777) == 0o666 & ~umask for p in (tmp_path / "fmus").glob("*.fmu"))
    left = sorted(p.name for p in (tmp_path / "fmus").glob(".*"))   # no temporary folder or file left:
    assert left == [f".{name}.built" for name in fmus]               # only the build records


def _bad(text: str, old: str, new: str) -> str:
    assert old in text, old
    return text.replace(old, new)


def line_of(text: str, fragment: str) -> int:
    return text.count("\n", 0, text.index(fragment)) + 1


GOOD = motor_file()
EXPRESSION = GOOD + '\n[components.pendulum]\nkind = "expression"\nf = ["x[2]", "-sin(x[1]) + os.system(1)"]\nh = ["x[1]"]\n'
BAD_FILES = {
    "ragged matrix": (_bad(GOOD, "A = [[-4.0, -0.2, 0.0], [5.0, -10.0, 0.0]", "A = [[-4.0, -0.2, 0.0], [5.0]"),
                      f":{line_of(GOOD, 'A = [[')}: components.plant.A: row 2 has 1 entry, row 1 has 3"),
    "unknown field": (_bad(GOOD, "poles = [-40.0", "polse = [-40.0"),
                      "components.observer.polse: unknown field; did you mean 'poles'?"),
    "unknown component": (_bad(GOOD, '"sensor.y -> observer.y"', '"sensr.y -> observer.y"'),
                          f":{line_of(GOOD, 'sensor.y -> ')}: connections[3]: unknown component 'sensr'; did you mean "
                          "'sensor'?"),
    "unconnected input": (_bad(GOOD, '    "controller.u -> observer.u",\n', ""),
                          "observer.u is not connected: connect it or give it a value in [values]"),
    "size mismatch": (_bad(GOOD, '"observer.x_hat -> controller.x_hat"', '"observer.x_hat -> controller.r"'),
                      "connections[6]: 'observer.x_hat -> controller.r' joins 3 outputs to 1 inputs"),
    "bad expression": (EXPRESSION, f":{line_of(EXPRESSION, 'os.system')}:28: "
                                   "components.pendulum.f[2]: unknown function"),
    "control character": (_bad(GOOD, 'description = "DC', 'description = "\\u001bDC'),
                          ":2: description: holds the control character U+001B"),
    "raw control character": (_bad(GOOD, 'description = "DC', 'description = "\x07DC'),
                              ":2:16: control character U+0007"),
    "huge matrix": (_bad(GOOD, "A = [[-4.0, -0.2, 0.0], [5.0, -10.0, 0.0], [0.0, 1.0, 0.0]]",
                         "A = " + str([[0.0] * 3] * 100_000)), "components.plant.A: 100000 rows, more than the limit"),
    "too-long file": (GOOD + "#" * (4 * 2 ** 20), "more than 4 MiB, the limit of a system file"),
    "step beyond the stop time": (_bad(GOOD, "step = 1e-4", "step = 3"),
                                  "experiment.step: 3 is longer than the stop time 2"),
    "unknown kind": (_bad(GOOD, 'kind = "chirp"', 'kind = "chrip"'), "did you mean 'chirp'?"),
    "not TOML": (GOOD + "\n[[[", "not valid TOML"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_a_bad_file_is_one_line_exit_2_and_builds_nothing(tmp_path, case):
    text, expected = BAD_FILES[case]
    (tmp_path / "bad.toml").write_text(text)
    for command in (["build", "--config", "bad.toml", "--out", "fmus"],
                    ["run", "--config", "bad.toml", "--csv", "out.csv", "--build-dir", "fmus"]):
        done = obsfmu(*command, cwd=tmp_path)
        assert done.returncode == 2, (done.stdout, done.stderr)
        assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
        assert done.stderr.startswith("obsfmu: error: bad.toml"), done.stderr
        assert expected in done.stderr, done.stderr
    assert not list(tmp_path.glob("fmus/**/*.fmu")) and not (tmp_path / "out.csv").exists()


def test_values_stand_for_an_unconnected_input():
    from obsfmu.fmus.system.load import parse_system
    text = _bad(GOOD, '    "reference.y -> controller.r",\n', "") + '\n[values]\n"controller.r" = 0.25\n'
    scenario = parse_system(text, "f.toml").scenario()
    assert dict((i, s) for i, _, s in scenario.components)["controller"] == {"r": 0.25}


def test_the_field_reference_is_the_generated_one():
    from obsfmu.fmus.system import field_reference
    checked_in = (ROOT / "docs" / "system-file-reference.md").read_text()
    assert checked_in == field_reference(), "regenerate: obsfmu show --fields > docs/system-file-reference.md"
    for kind in ("lti", "expression", "luenberger", "state-feedback", "chirp", "csv", "noise", "added-noise"):
        assert f"### `{kind}`" in checked_in


PENDULUM = '''name = "pendulum"
connections = ["torque.y -> plant.u"]

[experiment]
stop_time = 3.0
step = 1e-3

[components.torque]
kind = "sine"
amplitude = 0.5
frequency_hz = 0.7

[components.plant]
kind = "expression"
inputs = 1
parameters = { g = 9.81, l = 0.5, c = 0.2 }
parameter_units = { g = "m/s2", l = "m", c = "1/s" }
f = ["x[2]", "-g / l * sin(x[1]) - c * x[2] + u[1]"]
h = ["x[1]"]
x0 = [0.5, 0]
max_substep = 1e-4
state_units = ["rad", "rad/s"]
'''


def test_an_expression_plant_driven_by_a_source_agrees_with_scipy(tmp_path):
    """The pendulum with friction by expressions, driven by a sine torque: within 1e-6 rad of scipy."""
    (tmp_path / "pendulum.toml").write_text(PENDULUM)
    done = obsfmu("run", "--config", "pendulum.toml", "--csv", "out.csv", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "nothing compared" in done.stdout
    time, columns = read_csv(tmp_path / "out.csv")

    def rhs(t, x):
        return [x[1], -9.81 / 0.5 * np.sin(x[0]) - 0.2 * x[1] + 0.5 * np.sin(2 * np.pi * 0.7 * t)]

    reference = solve_ivp(rhs, (0, 3), [0.5, 0], t_eval=time, method="DOP853", rtol=1e-12, atol=1e-12).y.T
    assert np.abs(columns["plant.x[1]"] - reference[:, 0]).max() < 1e-6
    assert np.abs(columns["plant.x[2]"] - reference[:, 1]).max() < 1e-5


def test_sweep_varies_a_parameter_of_a_component(tmp_path):
    (tmp_path / "pendulum.toml").write_text(PENDULUM)
    done = obsfmu("sweep", "--config", "pendulum.toml", "--vary", "plant.c=0.1,0.3", "--workers", "1",
                  "--no-plots", "--out", "sweep", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 2 and "no default measure: give --time-metric" in done.stderr, done.stderr
    (tmp_path / "dcmotor.toml").write_text(motor_file())
    done = obsfmu("sweep", "--config", "dcmotor.toml", "--vary", "plant.x0[3]=0.05,0.2", "--workers", "1",
                  "--no-plots", "--out", "sweep", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "2 of 2 samples done (2 ok)" in done.stdout, done.stdout
    rows = (tmp_path / "sweep" / "samples.csv").read_text().splitlines()
    assert len(rows) == 3 and "plant.x0[3]" in rows[0]


def test_show_prints_the_reference_and_a_checked_file(tmp_path):
    from obsfmu.fmus.system import field_reference
    done = obsfmu("show", "--fields", cwd=tmp_path)
    assert done.returncode == 0 and done.stdout == field_reference()
    (tmp_path / "dcmotor.toml").write_text(motor_file())
    done = obsfmu("show", "--config", "dcmotor.toml", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "observer (luenberger, FMU dcmotor_observer): inputs u[1], y[1]; outputs x_hat[3], y_hat[1]" in done.stdout
    assert "observer.x_hat[3] -> controller.x_hat[3]" in done.stdout
    # issue 38: each port's columns, units and layout
    lines = done.stdout.splitlines()
    assert any(line.strip().startswith("out observer.x_hat[1..3] (") and "estimate" in line for line in lines), lines
    assert any(line.strip().startswith("in observer.y") for line in lines)


def test_the_output_interval_and_a_reference_csv_named_by_the_file(tmp_path):
    text = motor_file().replace("step = 1e-4\n", "step = 1e-4\noutput_interval = 0.01\n")
    (tmp_path / "dcmotor.toml").write_text(text)
    done = obsfmu("run", "--config", "dcmotor.toml", "--csv", "ref.csv", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    time, _ = read_csv(tmp_path / "ref.csv")
    assert len(time) == 201 and np.allclose(np.diff(time), 0.01)
    (tmp_path / "dcmotor.toml").write_text(text.replace("[[report.compare]]", '[report]\nreference = "ref.csv"\n\n'
                                                                               "[[report.compare]]"))
    done = obsfmu("run", "--config", "dcmotor.toml", "--build-dir", "build", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    line = next(line for line in done.stdout.splitlines() if line.startswith("reference: "))
    assert line.startswith("reference: ref.csv, max |run - reference| 0 over ") and "at its 201 times" in line, line


def test_a_system_file_read_from_a_pipe(tmp_path):
    """``obsfmu run --config <(obsfmu show ...)``: the file is read once, from a pipe."""
    fifo = tmp_path / "system"
    os.mkfifo(fifo)
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "obsfmu", "run", "--config", str(fifo), "--step", "1e-3",
                                "--build-dir", "build"], cwd=tmp_path, env=environment, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    fifo.write_text(motor_file())
    out, err = process.communicate(timeout=600)
    assert process.returncode == 0, err
    assert out.startswith("dcmotor: 2000 steps to t = 2 s"), out


def test_the_figure_gives_every_compared_quantity_its_own_colour(monkeypatch, tmp_path):
    """Two more [[report.compare]] tables of one entry each: every error curve its own colour."""
    import obsfmu.fmus.plotting as plotting
    from obsfmu.fmus.result import Result
    from obsfmu.fmus.system import load_system
    path = tmp_path / "two.toml"
    path.write_text(motor_file() + '\n[[report.compare]]\nestimate = "observer.x_hat[1]"\ntruth = "plant.x[1]"\n'
                    '\n[[report.compare]]\nestimate = "observer.x_hat[3]"\ntruth = "plant.x[3]"\n')
    spec = load_system(path)
    captured = {}
    monkeypatch.setattr(plotting, "figure", lambda path, title, panels, unit: captured.setdefault("p", panels))
    columns = [f"{port}[{i}]" for port in ("plant.x", "observer.x_hat") for i in (1, 2, 3)]
    spec.plot(Result(np.linspace(0, 1, 5), columns, np.ones((5, 6))), tmp_path / "f.png")
    keys = [curve.key for curve in captured["p"][-1].curves if curve.role == "error"]
    assert len(keys) == len(spec.compares[0]["estimate_columns"]) + 2 and len(set(keys)) == len(keys)


def test_a_file_step_long_against_its_fastest_dynamics_warns_naming_them(capsys):
    """The pendulum example at 2e-2 s instead of its 1e-3 s (observer poles down to -30 1/s): one line naming the
    observer's poles, the expected error and the step that keeps it small; the file's own step says nothing."""
    from obsfmu.fmus.scenarios import check_step
    from obsfmu.fmus.system import load_system
    scenario = load_system(ROOT / "examples" / "pendulum.toml").scenario()
    rate, what = scenario.fastest
    assert what == "components.observer.eig(A - N C)" and rate == pytest.approx(30.0)
    check_step(scenario, stop_time=10.0, step=scenario.step, order="gauss-seidel", coupling="linear")
    assert capsys.readouterr().err == ""
    check_step(scenario, stop_time=10.0, step=2e-2, order="gauss-seidel", coupling="linear")
    (line,) = [line for line in capsys.readouterr().err.splitlines() if "h |lambda|" in line]
    assert line.startswith("obsfmu: warning: step 0.02 s: h |lambda| = 0.6 for the fastest dynamics "
                           "(components.observer.eig(A - N C), |lambda| = 30 1/s)")
    assert "a step of at most 0.0058 s keeps it below 0.01" in line
    check_step(scenario, stop_time=10.0, step=2e-3, order="gauss-seidel", coupling="hold")   # h |lambda| / 3 = 0.02
    assert "coupling error of up to about 0.02" in capsys.readouterr().err


BIG = "1" + "0" * 400                         # a TOML integer beyond a float (issue 37: OverflowError traceback)
LTV = (ROOT / "examples" / "ltv_mass_spring_damper.toml").read_text()
FOUND_BY_ISSUES_36_37 = {
    "401-digit stop time": (_bad(GOOD, "stop_time = 2.0", f"stop_time = {BIG}"),
                            f"f.toml:{line_of(GOOD, 'stop_time')}: experiment.stop_time: 1000"),
    "401-digit matrix entry": (_bad(GOOD, "A = [[-4.0, -0.2", f"A = [[{BIG}, -0.2"),
                               f"f.toml:{line_of(GOOD, 'A = [[')}: components.plant.A[1][1]: 1000"),
    "bidi override escaped in a text": (_bad(GOOD, 'description = "DC', 'description = "\\u202eDC'),
                                        "f.toml:2: description: holds the invisible format character U+202E"),
    "bidi override in the file": (_bad(GOOD, 'description = "DC', 'description = "\u202eDC'),
                                  "f.toml:2:16: bidirectional control character U+202E"),
    "expression of another kind: its line": (LTV.replace('f = "y**3"', 'f = "y**3 + os.system(1)"', 1),
                                             f"f.toml:{line_of(LTV, 'f = ')}: components.plant.f[1] (line 1, column 8"),
    "comment inside an expression": (EXPRESSION.replace("os.system(1)", "1  # the spring"),
                                     f"f.toml:{line_of(EXPRESSION, 'os.system')}: components.pendulum.f[2]: '#' (character 17) is not part of"),
}


@pytest.mark.parametrize("case", sorted(FOUND_BY_ISSUES_36_37))
def test_what_the_audit_found_is_one_line_naming_the_line(case):
    """In process (the CLI's one-line, rc 2 path is the one above): the field, the file line, no traceback."""
    from obsfmu.fmus.system.load import parse_system
    text, expected = FOUND_BY_ISSUES_36_37[case]
    with pytest.raises(ParameterError) as refused:
        parse_system(text, "f.toml")
    assert expected in str(refused.value) and "\n" not in str(refused.value), str(refused.value)


@pytest.mark.parametrize("character", ["202E", "200B", "00AD", "061C", "2066"])
def test_a_name_with_a_format_character_is_refused_and_the_message_shows_it_escaped(character):
    """Issue 37.9: U+202E (and every format character, category Cf: zero-width, soft hyphen, Arabic letter mark,
    isolates) in a component's name, written as a TOML escape.  Refused, and the message -- which names the
    field, and so the name -- carries none of them raw (it would read reversed in a terminal)."""
    import unicodedata

    from obsfmu.fmus.system.load import parse_system
    text = _bad(GOOD, "[components.sensor]", f'[components."sen\\u{character}sor"]')
    with pytest.raises(ParameterError) as refused:
        parse_system(text, "f.toml")
    message = str(refused.value)
    assert f"components.sen\\u{character}sor: holds the invisible format character U+{character}" in message, message
    assert not [c for c in message if unicodedata.category(c) in ("Cc", "Cf")] and "\n" not in message
