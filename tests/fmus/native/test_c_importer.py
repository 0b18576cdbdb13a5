"""The FMUs in a non-Python host: ``importer.c`` (no libpython in the process, empty environment).

One importer process co-simulates the ship loop, then the bounded LTV system, then the ship loop
again (instantiate -> free -> instantiate of the same binaries; six FMU kinds in one process),
with the same Jacobi rounds and the same linear input coupling (input derivatives) as
``obsfmu run <scenario> --master jacobi``, and must reproduce our master to 1e-9.
"""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from obsfmu.fmus.native import OVERRIDE
from obsfmu.fmus.scenarios import ensure_fmus, get, run
from native_harness import Unzipped, read_csv, run as run_importer, scenario_script

#: scenario -> (stop time, communication step): short runs, the scenario's own coupling (linear)
RUNS = {"ship": (0.2, 1e-4), "ltv-ls-bounded": (2.0, 1e-3)}
SEQUENCE = ["ship", "ltv-ls-bounded", "ship"]


def scenario_lines(name, build_dir, work, csv):
    scenario, (stop, step) = get(name), RUNS[name]
    return scenario_script(scenario, ensure_fmus(scenario, build_dir), work / csv.stem, csv, stop, step)


@pytest.fixture(scope="module")
def c_host(importer, build_dir, tmp_path_factory):
    work = tmp_path_factory.mktemp("c_host")
    csvs = [work / f"run{k}_{name}.csv" for k, name in enumerate(SEQUENCE)]
    lines = [line for name, csv in zip(SEQUENCE, csvs) for line in scenario_lines(name, build_dir, work, csv)]
    completed = run_importer(importer, lines, work)  # env -i: no PYTHONHOME, PYTHONPATH, LD_LIBRARY_PATH
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr
    return completed, [read_csv(csv) for csv in csvs]


@pytest.fixture(scope="module")
def master_runs(build_dir):
    return {name: run(name, build_dir, stop_time=RUNS[name][0], step=RUNS[name][1], order="jacobi",
                     ramp=0)[0]   # the importer steps on the plain grid
            for name in RUNS}


@pytest.mark.parametrize("index", range(len(SEQUENCE)), ids=[f"{k}-{n}" for k, n in enumerate(SEQUENCE)])
def test_c_importer_reproduces_the_jacobi_master(c_host, master_runs, index):
    _, results = c_host
    ours = master_runs[SEQUENCE[index]]
    theirs = results[index]
    assert theirs.shape == (len(ours.time), 1 + len(ours.columns))
    np.testing.assert_array_equal(theirs[:, 0], ours.time)
    deviation = np.max(np.abs(theirs[:, 1:] - ours.values))
    assert deviation <= 1e-9, deviation  # measured: 0 (bit for bit) on both systems


def test_one_c_process_runs_six_kinds_and_instantiates_again(c_host):
    completed, _ = c_host
    instantiations = [line.split() for line in completed.stdout.splitlines() if line.startswith("instantiate ")]
    assert [(name, status) for _, name, status, _ in instantiations] == [
        ("plant", "ok"), ("observer", "ok"), ("controller", "ok"),
        ("source", "ok"), ("plant", "ok"), ("observer", "ok"),
        ("plant", "ok"), ("observer", "ok"), ("controller", "ok")]
    kinds = {d.kind for name in RUNS for d in get(name).definitions()}
    assert len(kinds) == 6, kinds


def symbols(*command):
    return subprocess.run(list(map(str, command)), capture_output=True, text=True, check=True).stdout


def test_the_importer_links_no_python(importer):
    needed = symbols("readelf", "-d", importer)
    assert "NEEDED" in needed and "python" not in needed.lower()


def test_the_fmu_binaries_have_no_python_symbols_to_resolve(unzipped_plant):
    """The loader needs nothing from Python; the bridge names no libpython and exports one function."""
    binaries = Path(unzipped_plant.directory) / "binaries" / "linux64"
    loader, (bridge,) = binaries / "ship_plant.so", list(binaries.glob("obsfmu_bridge_*.so"))
    undefined = symbols("nm", "-D", "--undefined-only", loader)
    assert "dlopen" in undefined and not re.search(r"\b_?Py", undefined), undefined
    assert "python" not in symbols("readelf", "-d", loader).lower()
    assert "python" not in symbols("readelf", "-d", bridge).lower()
    assert re.search(r"\bU Py_InitializeFromConfig\b", symbols("nm", "-D", "--undefined-only", bridge))
    def exported(library):
        return {line.split()[-1] for line in symbols("nm", "-D", "--defined-only", library).splitlines()}
    assert exported(bridge) == {"obsfmu_bridge"}  # no fmi2* names to interpose
    assert {name for name in exported(loader) if name.startswith("fmi2")} >= {"fmi2Instantiate", "fmi2DoStep"}
    # the FMI 2.0 API, the one-call step and round of the project's master, the process-wide guard of the
    # first Python start (docs/portability.md), nothing else
    assert {name for name in exported(loader) if not name.startswith("fmi2")} == {
        "obsfmuDoStepBatched", "obsfmuDoStepPlanned", "obsfmuRound", "obsfmu_python_start_guard_1"}


@pytest.fixture(scope="module")
def unzipped_plant(build_dir, tmp_path_factory):
    fmus = ensure_fmus(get("ship"), build_dir)
    return Unzipped.of("plant", fmus["ship_plant"], tmp_path_factory.mktemp("plant"))


def one_step(unzipped, importer, work, env):
    lines = [unzipped.declaration(),
             f"calls one plant {unzipped.vr('u')} {unzipped.vr('x[1]')} {unzipped.vr('u_interpolation')} "
             "setupExperiment enterInitializationMode exitInitializationMode doStep getReal"]
    return run_importer(importer, lines, work, env=env)


def test_no_usable_python_is_one_clear_message(importer, unzipped_plant, tmp_path):
    completed = one_step(unzipped_plant, importer, tmp_path, env={OVERRIDE: str(tmp_path / "nowhere")})
    assert completed.returncode == 2 and "instantiate plant null" in completed.stdout
    (message,) = [line for line in completed.stdout.splitlines() if line.startswith("log ")]
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    for part in (f"no usable Python {version}", f"{OVERRIDE}={tmp_path / 'nowhere'}", f"libpython{version}",
                 f"{tmp_path / 'nowhere'}/bin/python{version}", f"set {OVERRIDE} to a Python {version}"):
        assert part in message, (part, message)


def test_missing_recorded_python_is_one_clear_message(importer, unzipped_plant, tmp_path):
    record = unzipped_plant.directory + "/resources/obsfmu_native.txt"
    original = open(record).read()
    try:
        with open(record, "w") as handle:
            handle.write(original.replace("python_library=", "python_library=/moved/away"))
        completed = one_step(unzipped_plant, importer, tmp_path, env={})
    finally:
        with open(record, "w") as handle:
            handle.write(original)
    (message,) = [line for line in completed.stdout.splitlines() if line.startswith("log ")]
    assert "instantiate plant null" in completed.stdout
    assert f"{OVERRIDE} is not set" in message and "/moved/away" in message and "missing" in message, message


@pytest.mark.parametrize("override", ["venv", "executable"])
def test_the_override_points_at_another_python(importer, unzipped_plant, tmp_path, override):
    """The variable as a user would set it after moving the FMU: a venv directory or a python executable."""
    value = sys.prefix if override == "venv" else sys.executable
    record = unzipped_plant.directory + "/resources/obsfmu_native.txt"
    original = open(record).read()
    try:  # the recorded Python is gone: only the override can work
        with open(record, "w") as handle:
            handle.write(original.replace("python_executable=", "python_executable=/moved/away"))
        completed = one_step(unzipped_plant, importer, tmp_path, env={OVERRIDE: value})
    finally:
        with open(record, "w") as handle:
            handle.write(original)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    statuses = [line.split()[3] for line in completed.stdout.splitlines() if line.startswith("call ")]
    assert statuses == ["0"] * 5, completed.stdout


def test_a_python_host_of_another_version_is_told_so(build_dir, tmp_path, capfd):
    """The bridge is compiled for one Python version; a host running another gets NULL and the reason."""
    from fmpy.fmi2 import FMU2Slave

    plant = Unzipped.of("plant", ensure_fmus(get("ship"), build_dir)["ship_plant"], tmp_path)
    record = Path(plant.directory) / "resources" / "obsfmu_native.txt"
    version = f"{sys.version_info.major}.{sys.version_info.minor}"
    record.write_text(record.read_text().replace(f"python_version={version}", "python_version=3.99"))
    slave = FMU2Slave(guid=plant.description.guid, unzipDirectory=plant.directory, modelIdentifier="ship_plant",
                      instanceName="plant")
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate()
    message = capfd.readouterr().out
    assert f"this process runs Python {version}" in message and "built for Python 3.99" in message, message
