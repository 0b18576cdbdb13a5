"""The worked examples of ``examples/`` (issue 26, item 8), each run through the CLI once per session and
compared with an independent scipy solution of the same equations.

The references are written out here from the physics in each file's comments: the composite ODE of
plant, observer and controller as one system, integrated by ``solve_ivp`` (DOP853, rtol 1e-10), the gains
by ``scipy.signal.place_poles`` or by hand.  Nothing of obsfmu is imported (``observers``, ``plants``,
``fmus``); the files' numbers are read with ``tomllib`` and checked against the physical constants.
The noisy example's reference is its own run without noise (``--set sensor.std=0``), compared tightly,
and its noisy run's error statistics against the observer's noise gain (a discrete Lyapunov equation).
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm, solve_discrete_lyapunov
from scipy.signal import place_poles

from examples_support import ROOT, columns, obsfmu, run_config, stays_below

EXAMPLES = ROOT / "examples"
_SUMMARY = re.compile(r"^(\S+) vs (\S+): final \|error\| (\S+)(?: \S+)?, below (\S+) from (.+)$")


@dataclass
class Run:
    """One ``obsfmu run`` of an example: its summary lines and CSV columns."""

    stdout: str
    time: np.ndarray
    columns: dict
    build_stdout: str = ""        #: what ``obsfmu build`` printed (the designed gains), where it ran first

    def block(self, port: str, n: int) -> np.ndarray:
        """The columns ``port[1] .. port[n]`` side by side."""
        return columns(self.columns, port, n)

    def convergence(self, estimate: str) -> float:
        """The summary's convergence time of ``estimate`` (inf: "not reached")."""
        for line in self.stdout.splitlines():
            match = _SUMMARY.match(line)
            if match and match[1] == estimate:
                return float("inf") if match[5] == "not reached" else float(match[5].removesuffix(" s"))
        raise AssertionError(f"no summary line for {estimate}:\n{self.stdout}")


def config(name: str) -> dict:
    with open(EXAMPLES / f"{name}.toml", "rb") as file:
        return tomllib.load(file)


def run_example(name: str, folder: Path, build: Path, *options: str, tag: str = "") -> Run:
    """``obsfmu run --config examples/NAME.toml --csv ...`` with ``options``; its summary and CSV."""
    data, stdout = run_config(EXAMPLES / f"{name}.toml", folder / f"{name}{tag}.csv", "--build-dir", build, *options,
                              cwd=folder)
    return Run(stdout, data["time"], data)


def solve(rhs, z0, times: np.ndarray, breaks=()) -> np.ndarray:
    """``z' = rhs(t, z)`` at ``times`` (rtol 1e-10), restarted at the ``breaks`` where the input has a kink."""
    edges = [times[0], *[b for b in breaks if times[0] < b < times[-1]], times[-1]]
    rows, z = [], np.asarray(z0, dtype=float)
    for start, stop in zip(edges[:-1], edges[1:]):
        inside = times[(times >= start) & ((times < stop) | (stop == times[-1]))]
        evaluated = np.union1d(inside, [stop])
        piece = solve_ivp(rhs, (start, stop), z, t_eval=evaluated, method="DOP853", rtol=1e-10, atol=1e-13)
        assert piece.success, piece.message
        rows.append(piece.y.T[np.isin(evaluated, inside)])
        z = piece.y[:, -1]
    return np.vstack(rows)


def deviation(run: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per column: max |co-simulation - reference|."""
    return np.abs(run - reference).max(axis=0)


@pytest.fixture(scope="session")
def build(tmp_path_factory) -> Path:
    """One build folder for the session: each example's FMUs are built once."""
    return tmp_path_factory.mktemp("examples_build")


@pytest.fixture(scope="session")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("examples_runs")


# ---------------------------------------------------------------------------------------------- DC motor
# The motor of examples/dcmotor.toml (CTMS "DC Motor Speed"): L di/dt = -R i - Ke w + V, J dw/dt = Kt i - b w.
R, L, KE, KT, J, B_FRICTION = 1.0, 0.5, 0.01, 0.01, 0.01, 0.1
MOTOR_A = np.array([[-R / L, -KE / L, 0.0], [KT / J, -B_FRICTION / J, 0.0], [0.0, 1.0, 0.0]])
MOTOR_B = np.array([[1 / L], [0.0], [0.0]])
MOTOR_C = np.array([[0.0, 0.0, 1.0]])


def ramp(source: dict):
    """The ramp of the file's source table: offset + slope clip(t - start_time, 0, end_time - start_time)."""
    return lambda t: source.get("offset", 0.0) + source["slope"] * np.clip(
        t - source["start_time"], 0.0, source["end_time"] - source["start_time"])


@pytest.fixture(scope="session")
def dcmotor(folder, build) -> Run:
    done = obsfmu("build", "--config", EXAMPLES / "dcmotor.toml", "--out", build, cwd=folder)
    assert done.returncode == 0, done.stderr
    run = run_example("dcmotor", folder, build)
    run.build_stdout = done.stdout
    return run


def dcmotor_solution(time: np.ndarray) -> np.ndarray:
    """Motor + observer + state feedback as one ODE of 6 states: columns x (3), x_hat (3), u."""
    file = config("dcmotor")
    parts = file["components"]
    K = place_poles(MOTOR_A, MOTOR_B, parts["controller"]["poles"]).gain_matrix
    N = place_poles(MOTOR_A.T, MOTOR_C.T, parts["observer"]["poles"]).gain_matrix.T
    r = ramp(parts["reference"])

    def rhs(t, z):
        x, x_hat = z[:3], z[3:]
        u = -K @ x_hat + r(t)
        return np.concatenate([MOTOR_A @ x + MOTOR_B @ u, MOTOR_A @ x_hat + MOTOR_B @ u + N @ (MOTOR_C @ (x - x_hat))])

    z0 = np.concatenate([parts["plant"]["x0"], parts["observer"]["x_hat0"]])
    breaks = (parts["reference"]["start_time"], parts["reference"]["end_time"])
    z = solve(rhs, z0, time, breaks)
    u = -z[:, 3:] @ K.T + r(time)[:, None]
    return np.column_stack([z, u])


@pytest.fixture(scope="session")
def dcmotor_reference(dcmotor) -> np.ndarray:
    return dcmotor_solution(dcmotor.time)


def test_the_dc_motor_file_holds_the_motor_of_its_comments():
    """A, B, C are the CTMS motor's; the voltage reference is K[3] times the wanted angle (the loop settles
    at th = r / K[3]), with K the gain of the file's closed-loop poles."""
    parts = config("dcmotor")["components"]
    np.testing.assert_allclose(parts["plant"]["A"], MOTOR_A, rtol=1e-12)
    np.testing.assert_allclose(parts["plant"]["B"], MOTOR_B, rtol=1e-12)
    np.testing.assert_allclose(parts["plant"]["C"], MOTOR_C, rtol=1e-12)
    K = place_poles(MOTOR_A, MOTOR_B, parts["controller"]["poles"]).gain_matrix
    assert parts["reference"]["slope"] == pytest.approx(K[0, 2] * parts["target"]["slope"], rel=1e-9)
    for key in ("start_time", "end_time"):
        assert parts["reference"][key] == parts["target"][key]


def test_the_dc_motor_build_prints_the_gains_scipy_places(dcmotor):
    """``obsfmu build`` prints N and K; they are scipy's for the file's poles (to the 6 digits printed)."""
    parts = config("dcmotor")["components"]
    expected = {"observer": place_poles(MOTOR_A.T, MOTOR_C.T, parts["observer"]["poles"]).gain_matrix.T,
                "controller": place_poles(MOTOR_A, MOTOR_B, parts["controller"]["poles"]).gain_matrix}
    for instance, gain in expected.items():
        line = next(line for line in dcmotor.build_stdout.splitlines() if line.startswith(f"components.{instance}:"))
        printed = re.search(r"= \[([^\]]*)\]", line)[1]
        values = np.array([[float(v) for v in row.split(",")] for row in printed.split(";")])
        np.testing.assert_allclose(values.reshape(gain.shape), gain, rtol=1e-5)


def test_the_dc_motor_agrees_with_scipy(dcmotor, dcmotor_reference):
    """Every state, estimate and the voltage within 1e-3 of the monolithic solution, relative to each one's
    largest value, and within 1e-4 after the observer's first 0.5 s.  Measured (h = 1 ms, linear coupling):
    4.4e-4, the current at t = 10 ms while the observer makes its first correction, and 2.4e-5 after
    0.5 s; the coupling error is second order in h (2.3e-4 at 0.5 ms, 1.8e-3 at 2 ms); held inputs give 8e-3."""
    run = np.column_stack([dcmotor.block("plant.x", 3), dcmotor.block("observer.x_hat", 3),
                           dcmotor.columns["controller.u"]])
    assert dcmotor.time[-1] == pytest.approx(config("dcmotor")["experiment"]["stop_time"])
    scale = np.abs(dcmotor_reference).max(axis=0)
    relative = deviation(run, dcmotor_reference) / scale
    assert relative.max() < 1e-3, relative
    late = dcmotor.time >= 0.5
    relative = deviation(run[late], dcmotor_reference[late]) / scale
    assert relative.max() < 1e-4, relative
    assert scale[2] > 0.19                                  # the angle moved (0.2 rad): not a comparison of zeros


def test_the_dc_motor_estimate_converges_and_the_loop_tracks(dcmotor, dcmotor_reference):
    """The summary's convergence times are the reference's (within one CSV row, 10 ms), and within the
    bounds the file states: estimate within 1e-4 of the state by 0.8 s, the angle within 2e-3 rad of the
    wanted 0.2 rad by 3.5 s (measured 0.69 s and 3.39 s)."""
    compares = config("dcmotor")["report"]["compare"]
    target = ramp(config("dcmotor")["components"]["target"])(dcmotor.time)
    for i in range(3):
        error = dcmotor_reference[:, i] - dcmotor_reference[:, 3 + i]
        expected = stays_below(dcmotor.time, error, compares[0]["tolerance"])
        assert dcmotor.convergence(f"observer.x_hat[{i + 1}]") == pytest.approx(expected, abs=0.0101)
        assert dcmotor.convergence(f"observer.x_hat[{i + 1}]") < 0.8
    expected = stays_below(dcmotor.time, dcmotor_reference[:, 2] - target, compares[1]["tolerance"])
    assert dcmotor.convergence("plant.y") == pytest.approx(expected, abs=0.0101)
    assert dcmotor.convergence("plant.y") < 3.5
    assert abs(dcmotor.columns["plant.y"][-1] - 0.2) < 5e-4


# ------------------------------------------------------------------------------------- chirp and noise
# The oscillator of examples/chirp_noisy.toml: m x'' = -k x - c x' + F.
MASS, SPRING, DAMPER = 0.5, 500.0, 1.0
OSC_A = np.array([[0.0, 1.0], [-SPRING / MASS, -DAMPER / MASS]])
OSC_B = np.array([[0.0], [1 / MASS]])
OSC_C = np.array([[1.0, 0.0]])


def chirp(source: dict):
    """The linear sweep of the file's chirp table (from t0 = 0; the file ends at t1)."""
    f0, f1, t1 = source["f0_hz"], source["f1_hz"], source["t1"]
    return lambda t: source["amplitude"] * np.sin(2 * np.pi * (f0 * t + (f1 - f0) * t ** 2 / (2 * t1)))


def observer_gain_chirp() -> np.ndarray:
    return place_poles(OSC_A.T, OSC_C.T, config("chirp_noisy")["components"]["observer"]["poles"]).gain_matrix.T


@pytest.fixture(scope="session")
def chirp_noisy(folder, build) -> Run:
    return run_example("chirp_noisy", folder, build)


@pytest.fixture(scope="session")
def chirp_clean(folder, build) -> Run:
    return run_example("chirp_noisy", folder, build, "--set", "sensor.std=0", tag="_clean")


def test_the_chirp_file_holds_the_oscillator_of_its_comments():
    parts = config("chirp_noisy")["components"]
    np.testing.assert_allclose(parts["plant"]["A"], OSC_A, rtol=1e-12)
    np.testing.assert_allclose(parts["plant"]["B"], OSC_B, rtol=1e-12)
    assert parts["force"]["t0"] == 0 and parts["force"]["sweep"] == "linear"


def chirp_solution(time: np.ndarray) -> np.ndarray:
    """Oscillator and observer (noise-free) as one ODE of 4 states: columns x (2), x_hat (2)."""
    parts = config("chirp_noisy")["components"]
    N, force = observer_gain_chirp(), chirp(parts["force"])

    def rhs(t, z):
        x, x_hat = z[:2], z[2:]
        F = force(t)
        return np.concatenate([OSC_A @ x + OSC_B[:, 0] * F,
                               OSC_A @ x_hat + OSC_B[:, 0] * F + N[:, 0] * (OSC_C @ (x - x_hat))])

    return solve(rhs, np.concatenate([parts["plant"]["x0"], parts["observer"]["x_hat0"]]), time)


def test_the_chirp_without_noise_agrees_with_scipy(chirp_clean):
    """Noise-free (std 0): displacement, velocity and their estimates within 1e-4 of the monolithic solution,
    relative to each one's largest value.  Measured (h = 0.5 ms, linear coupling): 4.5e-5, the estimates at
    resonance (4.3 s); second order in h (1.8e-4 at 1 ms, 1.1e-5 at 0.25 ms); held inputs give 1.6e-2."""
    reference = chirp_solution(chirp_clean.time)
    run = np.column_stack([chirp_clean.block("plant.x", 2), chirp_clean.block("observer.x_hat", 2)])
    scale = np.abs(reference).max(axis=0)
    assert (deviation(run, reference) / scale).max() < 1e-4, deviation(run, reference) / scale
    noise = chirp_clean.columns["sensor.y"] - chirp_clean.columns["plant.y"]
    assert np.abs(noise).max() < 1e-15                      # std 0: no noise (round-off of y = u + 0 only)
    assert scale[0] > 0.01                                  # it resonated (20 mm): not a comparison of zeros


def noise_gain() -> np.ndarray:
    """Standard deviations of the observer error for held white noise on y (the file's comments): the
    stationary solution of P = Phi P Phi' + s^2 G G' at the noise's sample interval."""
    sensor = config("chirp_noisy")["components"]["sensor"]
    N = observer_gain_chirp()
    dt, F = sensor["sample_interval"], OSC_A - N @ OSC_C
    augmented = expm(np.block([[F, -N], [np.zeros((1, 3))]]) * dt)
    Phi, G = augmented[:2, :2], augmented[:2, 2:]
    return np.sqrt(np.diag(solve_discrete_lyapunov(Phi, sensor["std"] ** 2 * G @ G.T)))


def test_the_noisy_run_has_the_noise_of_the_file(chirp_noisy):
    """The sensor adds noise of the file's std (8000 samples: the estimate within 3 %)."""
    noise = chirp_noisy.columns["sensor.y"] - chirp_noisy.columns["plant.y"]
    std = config("chirp_noisy")["components"]["sensor"]["std"]
    assert 0.97 * std < noise.std() < 1.03 * std
    assert abs(noise.mean()) < 0.1 * std


def test_the_noisy_estimate_error_is_the_observer_noise_gain(chirp_noisy, chirp_clean):
    """The error the noise adds (noisy run - noise-free run: the model is linear, the rest cancels) has, over
    0.5-8 s, the RMS of the noise gain within 15 % (measured ratios 1.01 and 1.01), and the tolerances of the
    file are 4 of those standard deviations (within 5 %)."""
    sigma = noise_gain()
    window = chirp_noisy.time >= 0.5
    for i in range(2):
        error = chirp_noisy.block("plant.x", 2)[:, i] - chirp_noisy.block("observer.x_hat", 2)[:, i]
        clean = chirp_clean.block("plant.x", 2)[:, i] - chirp_clean.block("observer.x_hat", 2)[:, i]
        rms = np.sqrt(np.mean((error - clean)[window] ** 2))
        assert 0.85 * sigma[i] < rms < 1.15 * sigma[i], (i, rms, sigma[i])
        assert np.abs(clean[window]).max() < 0.05 * sigma[i]      # without noise the error is far below it
        tolerance = config("chirp_noisy")["report"]["compare"][i]["tolerance"]
        assert tolerance == pytest.approx(4 * sigma[i], rel=0.05)


def test_the_noisy_estimate_converges_within_its_tolerance(chirp_noisy, chirp_clean):
    """Both estimates are within 4 noise standard deviations by 0.1 s and stay there (measured 0.057 s and
    0.075 s), as in the noise-free run (within 10 ms: the noise moves the last crossing)."""
    for i in (1, 2):
        noisy, clean = chirp_noisy.convergence(f"observer.x_hat[{i}]"), chirp_clean.convergence(f"observer.x_hat[{i}]")
        assert noisy < 0.1 and abs(noisy - clean) < 0.01, (noisy, clean)


def test_a_tolerance_below_the_noise_is_named_by_the_summary(chirp_noisy, folder, build):
    """Issue 38: with three times the sensor noise the file's tolerances (4 standard deviations of the file's
    noise) are below the noise-induced error: the summary says so with the error's 3 standard deviations, which
    are the noise gain's within 25 % (measured 2.8e-4 m against 2.5e-4 m: 10 % of the run, a 2 % window).  The
    file's own noise keeps below them: no such line."""
    louder = run_example("chirp_noisy", folder, build, "--set", "sensor.std=3e-4", tag="_loud")
    sigma = 3.0 * noise_gain()
    lines = louder.stdout.splitlines()
    for i, unit in enumerate(("m", "m/s")):
        at = next(k for k, line in enumerate(lines) if line.startswith(f"observer.x_hat[{i + 1}] vs"))
        noise = re.match(r"  noise: over the last 10 % of the run the error fluctuates by 3 standard deviations = "
                         rf"(\S+) {re.escape(unit)}, above the tolerance", lines[at + 1])
        assert noise, lines[at:at + 2]
        assert float(noise[1]) == pytest.approx(3 * sigma[i], rel=0.25)
    assert "noise:" not in chirp_noisy.stdout


# ------------------------------------------------------------------------------------------- pendulum
G, LENGTH, FRICTION = 9.81, 0.5, 0.3


def pendulum_gain(t_settle: float) -> np.ndarray:
    """The observer gain for (T s + 1)^2, T = t_settle / 6, of the linearisation [[0, 1], [-a, -c]], C = [1, 0]:
    det(s I - A + N C) = s^2 + (N1 + c) s + (a + N2 + c N1) = s^2 + 2 p s + p^2, p = 1 / T."""
    p, a = 6 / t_settle, G / LENGTH
    n1 = 2 * p - FRICTION
    return np.array([n1, p ** 2 - a - FRICTION * n1])


@pytest.fixture(scope="session")
def pendulum(folder, build) -> Run:
    return run_example("pendulum", folder, build)


def pendulum_reference(time: np.ndarray, x0) -> np.ndarray:
    """The nonlinear pendulum, the observer of its linearisation and the free linear model as one ODE of 6
    states: columns x (2), x_hat (2), x_linear (2)."""
    parts = config("pendulum")["components"]
    N, a = pendulum_gain(parts["observer"]["t_settle"]), G / LENGTH
    A = np.array([[0.0, 1.0], [-a, -FRICTION]])

    def rhs(t, z):
        x, x_hat, x_linear = z[:2], z[2:4], z[4:]
        pendulum = [x[1], -a * np.sin(x[0]) - FRICTION * x[1]]
        return np.concatenate([pendulum, A @ x_hat + N * (x[0] - x_hat[0]), A @ x_linear])

    return solve(rhs, np.concatenate([x0, parts["observer"]["x_hat0"], x0]), time)


def test_the_pendulum_file_holds_the_pendulum_of_its_comments():
    parts = config("pendulum")["components"]
    assert parts["plant"]["parameters"] == {"g": G, "l": LENGTH, "c": FRICTION}
    np.testing.assert_allclose(parts["linearised"]["A"], [[0, 1], [-G / LENGTH, -FRICTION]], rtol=1e-12)
    assert parts["linearised"]["x0"] == parts["plant"]["x0"]


def test_the_pendulum_agrees_with_scipy(pendulum):
    """Angle, speed, their estimates and the linear model within 5e-6 of the monolithic solution, relative to
    each one's largest value.  Measured (h = 1 ms, linear coupling): 1.6e-6, the estimates in the first
    0.1 s; the plant alone (RK4, 1 ms sub-steps) 1e-10; second order in h (6.2e-6 at 2 ms, 3.9e-7 at
    0.5 ms); held inputs give 1.9e-3."""
    reference = pendulum_reference(pendulum.time, config("pendulum")["components"]["plant"]["x0"])
    run = np.column_stack([pendulum.block("plant.x", 2), pendulum.block("observer.x_hat", 2),
                           pendulum.block("linearised.x", 2)])
    scale = np.abs(reference).max(axis=0)
    assert (deviation(run, reference) / scale).max() < 5e-6, deviation(run, reference) / scale


def test_the_pendulum_estimate_converges_in_the_files_regime(pendulum):
    """From 0.5 rad: the angle estimate within 1e-3 rad by 0.3 s, the speed within 1e-2 rad/s by 2 s
    (measured 0.27 s and 1.59 s, as the scipy solution: within one CSV row); the linear model alone never
    gets there (its period is off)."""
    reference = pendulum_reference(pendulum.time, config("pendulum")["components"]["plant"]["x0"])
    for i, (tolerance, bound) in enumerate(((1e-3, 0.3), (1e-2, 2.0))):
        expected = stays_below(pendulum.time, reference[:, i] - reference[:, 2 + i], tolerance)
        assert pendulum.convergence(f"observer.x_hat[{i + 1}]") == pytest.approx(expected, abs=0.0101)
        assert pendulum.convergence(f"observer.x_hat[{i + 1}]") < bound
    assert pendulum.convergence("linearised.x[1]") == float("inf")


def test_the_pendulum_observer_error_is_the_filtered_linearisation_error(pendulum):
    """The comments' account: e' = (A - N C) e + [0, d], d = (g/l)(th - sin th), so after the start the angle
    error is about d / p^2 (p = 30 1/s): its largest value after 1 s within a factor 2 of max |d| / p^2."""
    p = 6 / config("pendulum")["components"]["observer"]["t_settle"]
    late = pendulum.time >= 1.0
    theta = pendulum.columns["plant.x[1]"][late]
    d = G / LENGTH * (theta - np.sin(theta))
    error = np.abs(theta - pendulum.columns["observer.x_hat[1]"][late]).max()
    assert 0.5 < error / (np.abs(d).max() / p ** 2) < 2.0
