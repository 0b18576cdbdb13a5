"""Handles are checked, not trusted; sizes are bounded (issues 28.3, 28.2, 28.6, 29.7), from the C importer.

Every case runs in its own ``importer.c`` process (empty environment), FMI 2.0 and FMI 3.0: a fresh
instance in step mode, the abusive calls real importers commit -- a foreign pointer as instance or FMU
state, a state used after it was freed, ``fmi2FreeFMUstate`` given the state itself instead of its
address (fmusim 0.0.39 does it), ``fmi2GetFMUstate`` with an uninitialised ``*state``, an instance freed
twice or used after it was freed, ``nvr`` of 2^40 or SIZE_MAX -- each of which crashed the host or left
the instance in the error state before; now each is fmi2Error/fmi3Error (logged where a logger is
known), and a step afterwards works.
"""

from pathlib import Path

import pytest

from obsfmu.fmus.scenarios import ensure_fmus, get
from native_harness import KERNEL_NOTE, Unzipped, run as run_importer

OK, ERROR = 0, 3

#: case -> the calls it prints, with their statuses, before the last step (which must be OK)
CASES = {
    "foreign-instance": [("doStep", ERROR), ("getReal", ERROR), ("getFMUstate", ERROR)],
    "free-twice": [],
    "use-after-free": [("doStep", ERROR), ("getReal", ERROR), ("getFMUstate", ERROR)],
    "state-after-free": [("getFMUstate", OK), ("freeFMUstate", OK), ("setFMUstate", ERROR),
                         ("serializedFMUstateSize", ERROR), ("freeFMUstate-again", ERROR)],
    "free-state-itself": [("getFMUstate", OK), ("freeFMUstate-itself", ERROR), ("setFMUstate", OK),
                          ("freeFMUstate", OK)],
    "uninitialised-state": [("getFMUstate", ERROR), ("unchanged", OK)],
    "foreign-state": [("setFMUstate", ERROR), ("serializedFMUstateSize", ERROR), ("freeFMUstate", ERROR)],
    "leaked-states": [("getFMUstate", OK)] * 3,
}
HUGE2 = ["getReal-2^40", "getReal-SIZE_MAX", "setReal-2^40", "getInteger-SIZE_MAX", "setInteger-2^40",
         "getBoolean-2^40", "setRealInputDerivatives-2^40"]
HUGE3 = ["getReal-2^40", "getReal-SIZE_MAX", "setFloat64-2^40", "getInt32-SIZE_MAX", "setInt32-2^40"]
#: what the log says for the refusals of a case with an instance known (FMI 2.0 wording; FMI 3.0: fmi3...State)
SAYS = {"state-after-free": "is not a state of this FMU (another FMU's, a foreign pointer, or freed already)",
        "free-state-itself": "given the FMU state itself instead of its address",
        "uninitialised-state": "neither NULL (a new state) nor a state of this FMU",
        "foreign-state": "is not a state of this FMU"}


@pytest.fixture(scope="module")
def plants(build_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("handles")
    scenario = get("ship")
    return {version: Unzipped.of(f"plant{version}", ensure_fmus(scenario, build_dir, fmi_version=version)["ship_plant"],
                                 root / f"fmi{version}")
            for version in (2, 3)}


def abuse(importer, unzipped, case, work, *arguments):
    completed = run_importer(importer, [unzipped.declaration(), f"abuse {case} {unzipped.instance} {case} "
                                        + " ".join(map(str, arguments))], work, timeout=120)
    assert completed.returncode == 0, (case, completed.returncode, completed.stdout[-2000:], completed.stderr[-2000:])
    calls = [tuple(line.split()[2:]) for line in completed.stdout.splitlines() if line.startswith("abuse ")]
    logs = [line.split(" ", 3)[3] for line in completed.stdout.splitlines() if line.startswith("log ")
            and KERNEL_NOTE not in line]        # the compiled kernel's info line (logging on): not about the abuse
    return [(name, int(status)) for name, status in calls], logs


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", sorted(CASES))
def test_an_abusive_call_is_an_error_never_a_crash(importer, plants, tmp_path, case, version):
    calls, logs = abuse(importer, plants[version], case, tmp_path)
    assert calls == CASES[case] + [("last-step", OK)], calls
    if case in SAYS:
        assert any(SAYS[case] in line for line in logs), logs
    if case == "free-state-itself":
        call = "fmi2FreeFMUstate" if version == 2 else "fmi3FreeFMUState"
        assert any(f"call {call}(instance, &state)): nothing freed" in line for line in logs), logs


@pytest.mark.parametrize("version", [2, 3])
def test_a_huge_nvr_is_refused_and_the_instance_steps_on(importer, plants, tmp_path, version):
    calls, logs = abuse(importer, plants[version], "huge-nvr", tmp_path)
    assert calls == [(name, ERROR) for name in (HUGE2 if version == 2 else HUGE3)] + [("last-step", OK)], calls
    assert len(logs) == len(calls) - 1 and all("larger than the FMU's variables" in line for line in logs), logs
    assert not any("not allowed in state" in line for line in logs), logs


def float64_variables(unzipped):
    """The FMI 3.0 loader's table: every Float64 variable (``time`` first) and the number of their values."""
    lines = (Path(unzipped.directory) / "resources" / "obsfmu_fmi3.txt").read_text().splitlines()
    rows = [line.split() for line in lines if line and not line.startswith("#")]
    floats = [(int(vr), max(1, int(count))) for vr, kind, _, _, count, *_ in rows if kind == "F"]
    return [vr for vr, _ in floats], sum(count for _, count in floats)


@pytest.mark.parametrize("model", ["ship_controller", "uio_ftdrem_plant", "gpebo_source"])
def test_fmi3_get_float64_of_every_variable_with_time(importer, build_dir, tmp_path, model):
    """fmusim asks fmi3GetFloat64 for every Float64, ``time`` included (it failed: "16 values requested, more
    than the FMU's 15")."""
    from obsfmu.fmus.scenarios import SCENARIOS
    scenario = next(s for s in SCENARIOS.values() if model in {m for _, m, _ in s.components})
    unzipped = Unzipped.of("fmu", ensure_fmus(scenario, build_dir, fmi_version=3)[model], tmp_path)
    vrs, values = float64_variables(unzipped)
    assert vrs[0] == 0
    calls, logs = abuse(importer, unzipped, "every-variable", tmp_path, values, *vrs)
    assert calls == [("getFloat64-every", OK), ("time", OK), ("last-step", OK)], (calls, logs)


@pytest.fixture(scope="module")
def pair(build_dir, tmp_path_factory):
    root = tmp_path_factory.mktemp("pair")
    scenario = get("ship")
    fmus2, fmus3 = ensure_fmus(scenario, build_dir), ensure_fmus(scenario, build_dir, fmi_version=3)
    return [Unzipped.of("plant", fmus2["ship_plant"], root), Unzipped.of("observer", fmus2["ship_observer"], root),
            Unzipped.of("controller3", fmus3["ship_controller"], root)]


@pytest.mark.parametrize("second", ["observer", "controller3"])
def test_two_fmus_start_python_at_once_from_two_threads(importer, pair, tmp_path, second):
    """Two different FMUs (two loader libraries) instantiated at once, before Python runs: each loader had
    its own lock, so both started Python (SIGSEGV in most runs).  Repeated: each run is a new process."""
    plant, *others = pair
    other = next(u for u in others if u.instance == second)
    for attempt in range(4):
        completed = run_importer(importer, [plant.declaration(), other.declaration(), f"parallel plant {second}"],
                                 tmp_path, timeout=120)
        assert completed.returncode == 0, (attempt, completed.returncode, completed.stdout[-2000:],
                                           completed.stderr[-2000:])
        assert sorted(line for line in completed.stdout.splitlines() if line.startswith("parallel ")) == sorted(
            ["parallel plant ok", f"parallel {second} ok"]), completed.stdout
