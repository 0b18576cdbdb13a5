"""Acceptance of paper 002's ship scenario through FMUs (issue 3).

The monolithic reference (``fmus/scenarios/ship/reference.py``) is independent of the project: the
composite system ``xe' = Ae xe`` of paper 002, eq. (12), solved by the matrix exponential.
"""

import numpy as np
import pytest
from scipy.linalg import expm

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.result import Result
from obsfmu.fmus.scenarios import ensure_fmus, get, run
from obsfmu.fmus.scenarios.ship import paper_table

from obsfmu.fmus.scenarios.ship.reference import exact

GRID = np.round(np.arange(101) * 0.01, 2)


def reference_error(result: Result) -> float:
    rows = [result.index_at(t) for t in GRID]
    simulated = np.column_stack([result.vector("plant.x"), result.vector("observer.x_hat")])[rows]
    return float(np.max(np.abs(simulated - exact(result.time[rows]))))


def test_transcribed_table_matches_the_exact_solution():
    """The printed table (as transcribed) is the rounded exact solution: a check of the transcription."""
    times, table = paper_table()
    xe = exact(times)
    columns = {"y": xe[:, 0] - xe[:, 2], "x1": xe[:, 0], "x2": xe[:, 1], "x1_hat": xe[:, 2], "x2_hat": xe[:, 3]}
    for name, printed in table.items():
        mask = ~np.isnan(printed)
        assert np.max(np.abs(columns[name][mask] - printed[mask])) <= 5e-5 + 1e-12, name
    assert sum(int(np.sum(~np.isnan(v))) for v in table.values()) == 25 + 4 * 31


def test_the_system_file_holds_the_papers_numbers():
    """The scenario's system file (its matrices, the gains designed from its poles, x(0), x_hat(0), r)
    is the loop of the independent reference, exactly; so is its composite matrix Ae (eq. (12))."""
    from obsfmu.fmus.scenarios import ship
    from obsfmu.fmus.scenarios.ship import reference

    loop = ship.loop()
    assert [np.array_equal(a, b) for a, b in zip(loop.plant, loop.observer)] == [True] * 4
    for mine, paper in zip(loop.plant[:3] + (loop.N, loop.K), (reference.A, reference.B, reference.C,
                                                               reference.N, reference.K)):
        np.testing.assert_array_equal(mine, paper)
    np.testing.assert_array_equal(np.concatenate([loop.x0, loop.x_hat0]), reference.XE0)
    assert not loop.plant[3].any() and not loop.r.any()
    Ae, be = ship.composite_matrices()
    np.testing.assert_array_equal(Ae, reference.AE)
    assert not be.any()
    assert get("ship").system_file == ship.SYSTEM_FILE


@pytest.fixture(scope="module")
def default_run(build_dir, tmp_path_factory):
    """``obsfmu run ship --csv out.csv`` with the default step, through the command line."""
    ensure_fmus(get("ship"), build_dir)
    csv = tmp_path_factory.mktemp("ship") / "out.csv"
    assert cli.main(["run", "ship", "--csv", str(csv), "--build-dir", str(build_dir)]) == 0
    return csv


def test_csv_layout(default_run):
    header = default_run.read_text().splitlines()[0].split(",")
    assert header == ["time", "plant.y", "plant.x[1]", "plant.x[2]", "observer.x_hat[1]", "observer.x_hat[2]",
                      "observer.y_hat", "controller.u"]
    result = Result.from_csv(default_run)
    assert result.time[0] == 0.0 and result.time[-1] == pytest.approx(1.0)
    np.testing.assert_allclose(result.values[0, :5], [0.05, 0.05, 0.2, 0.0, 0.0])


def test_default_run_reproduces_every_printed_digit(default_run):
    result = Result.from_csv(default_run)
    times, table = paper_table()
    x, x_hat = result.vector("plant.x"), result.vector("observer.x_hat")
    columns = {"y": x[:, 0] - x_hat[:, 0], "x1": x[:, 0], "x2": x[:, 1], "x1_hat": x_hat[:, 0], "x2_hat": x_hat[:, 1]}
    rows = [result.index_at(t) for t in times]
    np.testing.assert_allclose(result.time[rows], times, atol=1e-12)
    for name, printed in table.items():
        mask = ~np.isnan(printed)
        deviation = np.abs(columns[name][rows][mask] - printed[mask])
        assert deviation.max() < 5e-5, (name, deviation.max())
        np.testing.assert_array_equal(np.round(columns[name][rows][mask], 4) + 0.0, printed[mask] + 0.0)
    assert reference_error(result) < 5e-7  # measured 2.0e-7


@pytest.fixture(scope="module")
def convergence(build_dir):
    """Error against the exact solution for steps 1e-2, 1e-3, 1e-4, both orders, both couplings."""
    errors = {}
    for order in ("gauss-seidel", "jacobi"):
        for coupling in ("linear", "hold"):
            for step in (1e-2, 1e-3, 1e-4):
                result, _ = run("ship", build_dir, step=step, order=order, coupling=coupling)
                errors[order, coupling, step] = reference_error(result)
    return errors


@pytest.mark.parametrize("order", ["gauss-seidel", "jacobi"])
def test_cosimulation_converges_to_the_monolithic_reference(convergence, order):
    linear = [convergence[order, "linear", h] for h in (1e-2, 1e-3, 1e-4)]
    hold = [convergence[order, "hold", h] for h in (1e-2, 1e-3, 1e-4)]
    # linear coupling is second order (x100 per decade), held inputs first order (x10)
    assert linear[1] / linear[2] > 80
    assert 8 < hold[1] / hold[2] < 12
    assert linear[2] < 1e-5 and hold[2] < 2e-3          # measured: GS 4.9e-6 / 1.3e-3, Jacobi 6.3e-6 / 1.6e-3
    assert all(l <= h_ for l, h_ in zip(linear, hold))   # interpolation never hurts here


def test_gauss_seidel_beats_jacobi(convergence):
    for coupling in ("linear", "hold"):
        assert convergence["gauss-seidel", coupling, 1e-4] < convergence["jacobi", coupling, 1e-4]


def test_summary_settling_times(build_dir):
    _, summary = run("ship", build_dir, step=1e-4)
    assert summary.metrics["settling_time_y"] <= 0.3          # paper: transient of Ye within 0.3 s
    assert summary.metrics["observer_convergence_time"] < 0.2
    assert abs(summary.metrics["final_error_x1"]) < 1e-12


def test_nomoto_observer_from_toml_decays_as_its_poles_say(tmp_path):
    """A different plant (3rd-order Nomoto model) from a TOML file, through the CLI and the master."""
    from obsfmu.fmus.config import design_from_config, load_config
    from obsfmu.fmus.runtime.kinds.signals import source_definition
    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.master import Component, Connection, System, cosimulate

    config = "examples/nomoto3.toml"
    assert cli.main(["build", "--config", config, "--out", str(tmp_path)]) == 0
    source = build_fmu(source_definition("rudder", sines=1, amplitude=[0.1], omega=[0.05]), tmp_path)
    system = System(
        [Component("rudder", source), Component("plant", tmp_path / "nomoto3_plant.fmu"),
         Component("observer", tmp_path / "nomoto3_observer.fmu")],
        [Connection("rudder.y", "plant.u"), Connection("rudder.y", "observer.u"),
         Connection("plant.y", "observer.y")])
    result = cosimulate(system, stop_time=12.0, step=0.01)
    design = design_from_config(load_config(config))
    H = design.model.A - design.N @ design.model.C
    e0 = design.x0 - design.x_hat0
    error = result.vector("plant.x") - result.vector("observer.x_hat")
    expected = np.array([expm(H * t) @ e0 for t in result.time])
    assert np.max(np.abs(error - expected)) < 1e-6 * np.max(np.abs(e0))
    assert np.max(np.abs(error[-1])) < 1e-4 * np.max(np.abs(e0))  # triple pole at -1.5: (1.5 t)^2/2 e^-1.5t


def test_cli_errors_are_clear(build_dir, capsys):
    assert cli.main(["run", "nonesuch", "--build-dir", str(build_dir)]) == 2
    assert "unknown scenario 'nonesuch'" in capsys.readouterr().err
    assert cli.main(["run", "ship", "--build-dir", str(build_dir), "--set", "observer.N[3]=1"]) == 2
    assert "observer.N[3]: no such variable; did you mean" in capsys.readouterr().err
    assert cli.main(["run", "ship", "--build-dir", str(build_dir), "--set", "observer.N[2]"]) == 2
    assert "expected INSTANCE.VARIABLE=VALUE" in capsys.readouterr().err
    assert cli.main(["run", "ship", "--build-dir", str(build_dir), "--set", "ghost.x=1"]) == 2
    assert "unknown instance 'ghost'" in capsys.readouterr().err
    assert cli.main(["run", "ship", "--build-dir", str(build_dir), "--step", "-1"]) == 2
    assert "argument --step: must be a positive finite number" in capsys.readouterr().err


def test_set_changes_the_plant_and_the_result_follows(build_dir):
    result, _ = run("ship", build_dir, step=1e-4, stop_time=0.3,
                    overrides=[("plant", "x0[1]", -0.02), ("observer", "x_hat0[2]", 0.1)])
    xe0 = np.array([-0.02, 0.2, 0.0, 0.1])
    rows = [result.index_at(t) for t in (0.1, 0.2, 0.3)]
    simulated = np.column_stack([result.vector("plant.x"), result.vector("observer.x_hat")])[rows]
    expected = exact(result.time[rows], xe0)
    assert np.max(np.abs(simulated - expected)) < 1e-5
