"""FMI 3.0 FMUs in the non-Python host: ``importer.c`` (no libpython in the process, ``env -i``).

One importer process co-simulates the ship loop from FMI 3.0 FMUs, the bounded LTV system from
FMI 3.0 FMUs and a mixed ship loop (FMI 2.0 plant and controller, FMI 3.0 observer), with the
Jacobi rounds of ``obsfmu run --master jacobi`` and its linear coupling -- FMI 2.0 input
derivatives, FMI 3.0 inputs at t + h in the intermediate update -- and must reproduce our master
to 1e-9.
"""

import re
import subprocess

import numpy as np
import pytest

from obsfmu.fmus.scenarios import ensure_fmus, get, run
from native_harness import KERNEL_NOTE, Unzipped, read_csv, run as run_importer, scenario_script

#: (name, scenario, FMI 3.0 models, stop time, step): short runs at the scenario's coupling (linear)
RUNS = [("ship3", "ship", {"ship_plant", "ship_observer", "ship_controller"}, 0.2, 1e-4),
        ("ltv3", "ltv-ls-bounded", {"ltv_ls_bounded_source", "ltv_ls_bounded_plant",
                                     "ltv_ls_bounded_observer"}, 2.0, 1e-3),
        ("mixed", "ship", {"ship_observer"}, 0.2, 1e-4)]


def lines_of(name, scenario_name, fmi3_models, stop, step, build_dir, work):
    scenario = get(scenario_name)
    fmus2, fmus3 = ensure_fmus(scenario, build_dir), ensure_fmus(scenario, build_dir, fmi_version=3)
    fmus = {model: (fmus3 if model in fmi3_models else fmus2)[model] for model in fmus2}
    return scenario_script(scenario, fmus, work / name, work / f"{name}.csv", stop, step)


@pytest.fixture(scope="module")
def c_host(importer, build_dir, tmp_path_factory):
    work = tmp_path_factory.mktemp("c_host3")
    lines = [line for run_ in RUNS for line in lines_of(*run_, build_dir, work)]
    completed = run_importer(importer, lines, work)  # env -i: no PYTHONHOME, PYTHONPATH, LD_LIBRARY_PATH
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr
    completed.declared = [line.split()[0] for line in lines if line.startswith("fmu")]
    return completed, {name: read_csv(work / f"{name}.csv") for name, *_ in RUNS}


@pytest.mark.parametrize("name, scenario_name, fmi3_models, stop, step", RUNS, ids=[r[0] for r in RUNS])
def test_c_importer_runs_fmi3_fmus_like_the_jacobi_master(c_host, build_dir, name, scenario_name, fmi3_models,
                                                          stop, step):
    _, results = c_host
    ours, _ = run(scenario_name, build_dir, stop_time=stop, step=step, order="jacobi", ramp=0,   # the importer's plain grid
                  fmi_version=3 if name != "mixed" else 2)
    theirs = results[name]
    assert theirs.shape == (len(ours.time), 1 + len(ours.columns))
    np.testing.assert_array_equal(theirs[:, 0], ours.time)
    deviation = np.max(np.abs(theirs[:, 1:] - ours.values))
    assert deviation <= 1e-9, deviation  # measured: 0 (ship3, ltv3) and 1e-16 (mixed)


def test_one_c_process_runs_fmi2_and_fmi3_instances_without_a_message(c_host):
    completed, _ = c_host
    instantiations = [line.split()[1:3] for line in completed.stdout.splitlines() if line.startswith("instantiate ")]
    ship = [["plant", "ok"], ["observer", "ok"], ["controller", "ok"]]
    assert instantiations == ship + [["source", "ok"], ["plant", "ok"], ["observer", "ok"]] + ship
    assert completed.declared == ["fmu3"] * 6 + ["fmu", "fmu3", "fmu"]
    assert not [line for line in completed.stdout.splitlines() if line.startswith("log ") and
                KERNEL_NOTE not in line], completed.stdout[-2000:]      # (logging on: the kernel's info line)


def symbols(*command):
    return subprocess.run(list(map(str, command)), capture_output=True, text=True, check=True).stdout


def test_the_fmi3_loader_has_no_python_symbols_and_exports_fmi3_and_the_guard_only(build_dir, tmp_path):
    fmu = ensure_fmus(get("ship"), build_dir, fmi_version=3)["ship_plant"]
    unzipped = Unzipped.of("plant", fmu, tmp_path)
    loader = f"{unzipped.directory}/binaries/x86_64-linux/ship_plant.so"
    undefined = symbols("nm", "-D", "--undefined-only", loader)
    assert "dlopen" in undefined and not re.search(r"\b_?Py", undefined), undefined
    assert "python" not in symbols("readelf", "-d", loader).lower()
    exported = {line.split()[-1] for line in symbols("nm", "-D", "--defined-only", loader).splitlines()}
    # the FMI 3.0 API and the process-wide guard of the first Python start (docs/portability.md)
    assert all(name.startswith("fmi3") for name in exported - {"obsfmu_python_start_guard_1"}), exported
    assert {"fmi3InstantiateCoSimulation", "fmi3DoStep", "fmi3GetFloat64", "fmi3UpdateDiscreteStates"} <= exported
