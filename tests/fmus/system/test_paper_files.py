"""The paper scenarios as system files (issue 26 item 5): every scenario with a ``system_file`` is that file.

For each: ``obsfmu show NAME`` prints the file exactly, and the file written from that output, run with
``obsfmu run --config``, writes the same CSV as ``obsfmu run NAME``, bit for bit, both with no option but
``--csv`` (both at the file's ``[experiment] output_interval``).  Everything goes through the command line
(subprocesses); the runs share the session's build folder, so each FMU is built once.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from obsfmu.fmus.scenarios import SCENARIOS

ROOT = Path(__file__).resolve().parents[3]
FILES = sorted(name for name, scenario in SCENARIOS.items() if scenario.system_file is not None)


def obsfmu(*args, cwd: Path | None = None) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "obsfmu", *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=900)


def run_csv(arguments: list, csv: Path, build_dir: Path) -> bytes:
    """The bytes of the CSV ``obsfmu run ARGUMENTS --csv csv`` writes."""
    done = obsfmu("run", *arguments, "--csv", csv, "--build-dir", build_dir)
    assert done.returncode == 0, done.stderr
    return csv.read_bytes()


@pytest.fixture(scope="module")
def scenario_csv(build_dir, tmp_path_factory):
    """``name -> bytes`` of the CSV of ``obsfmu run NAME`` (each run once)."""
    made: dict[str, bytes] = {}

    def csv(name: str) -> bytes:
        if name not in made:
            made[name] = run_csv([name], tmp_path_factory.mktemp(name) / "scenario.csv", build_dir)
        return made[name]
    return csv


@pytest.mark.parametrize("name", FILES)
def test_show_prints_the_scenarios_file_exactly(name):
    shown = obsfmu("show", name)
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout == SCENARIOS[name].system_file.read_text(encoding="utf-8")


@pytest.mark.parametrize("name", FILES)
def test_the_shown_file_runs_as_the_scenario_bit_for_bit(name, scenario_csv, build_dir, tmp_path):
    shown = obsfmu("show", name)
    assert shown.returncode == 0, shown.stderr
    (tmp_path / "copy.toml").write_text(shown.stdout, encoding="utf-8")
    done = obsfmu("run", "--config", tmp_path / "copy.toml", "--csv", tmp_path / "file.csv", "--build-dir", build_dir)
    assert done.returncode == 0, done.stderr
    from_file = (tmp_path / "file.csv").read_bytes()
    assert from_file.count(b"\n") > 2                      # a header and rows, not an empty file
    assert from_file == scenario_csv(name)
    # issue 38: a copy (README: "a working start") reports its comparisons, not "nothing compared"
    assert " vs plant." in done.stdout and "nothing compared" not in done.stdout, done.stdout


def test_every_paper_scenario_is_a_system_file():
    without = sorted(name for name, scenario in SCENARIOS.items() if scenario.system_file is None)
    assert not without, f"scenarios without a system file: {', '.join(without)}"


def test_run_reads_the_file_from_a_pipe_and_sweep_refuses_one(scenario_csv, build_dir, tmp_path):
    """``obsfmu run --config <(obsfmu show ship)`` from bash (a /dev/fd/N pipe, read once) writes the
    scenario's CSV; ``obsfmu sweep`` reads its file again in each worker: a pipe is one line naming --config."""
    show = f"{sys.executable} -m obsfmu show ship"
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(["bash", "-c", f'{sys.executable} -m obsfmu run --config <({show}) --csv pipe.csv '
                          f'--build-dir "{build_dir}"'], cwd=tmp_path, env=environment, capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "pipe.csv").read_bytes() == scenario_csv("ship")
    sweep = subprocess.run(["bash", "-c", f"{sys.executable} -m obsfmu sweep --config <({show}) --vary "
                            f"'plant.x0[1]=0,0.1' --out sweep --build-dir \"{build_dir}\""], cwd=tmp_path,
                           env=environment, capture_output=True, text=True, timeout=900)
    assert sweep.returncode == 2
    assert sweep.stderr.startswith("obsfmu: error: --config /dev/fd/") and sweep.stderr.count("\n") == 1, sweep.stderr
    assert "not a regular file (a pipe?)" in sweep.stderr and not (tmp_path / "sweep").exists()
