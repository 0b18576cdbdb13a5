"""Shared fixtures: FMUs are built once per test session into a temporary directory."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def build_dir(tmp_path_factory):
    """A session-wide build directory (FMUs are rebuilt only when their sources change)."""
    return tmp_path_factory.mktemp("build")


@pytest.fixture(scope="session")
def ship_fmus(build_dir):
    from obsfmu.fmus.scenarios import ensure_fmus, get
    return ensure_fmus(get("ship"), build_dir)


@pytest.fixture(scope="session")
def every_fmu(build_dir):
    """model -> (scenario step, fmu path) for every distinct FMU used by a scenario."""
    from obsfmu.fmus.scenarios import SCENARIOS, ensure_fmus
    found = {}
    for scenario in SCENARIOS.values():
        for model, path in ensure_fmus(scenario, build_dir).items():
            found.setdefault(model, (scenario.step, path))
    return found


@pytest.fixture(scope="session")
def every_fmu3(build_dir):
    """model -> (scenario step, FMI 3.0 fmu path) for every distinct FMU used by a scenario (build_dir/fmi3)."""
    from obsfmu.fmus.scenarios import SCENARIOS, ensure_fmus
    found = {}
    for scenario in SCENARIOS.values():
        for model, path in ensure_fmus(scenario, build_dir, fmi_version=3).items():
            found.setdefault(model, (scenario.step, path))
    return found


@pytest.fixture(scope="session")
def faulty_fmus(build_dir):
    """``{2: path, 3: path}``: paper 000's generator plant (``Ts = 1e-3``) as FMI 2.0 and 3.0 FMUs whose
    user function ``f`` has a deliberate bug at ``y = 0`` (``tests/faulty_user_function.py``): a step
    with ``x0[1] = 0`` fails inside the slave -- the FMI error state, which no refused call reaches."""
    from pathlib import Path

    from obsfmu.fmus.builder import build_fmu
    from obsfmu.fmus.runtime.kinds.gpebo import generator_plant_definition

    module = Path(__file__).with_name("faulty_user_function.py")
    definition = generator_plant_definition("faulty_plant", Ts=1e-3, f="faulty_user_function:f")
    return {version: build_fmu(definition, build_dir / "faulty" / f"fmi{version}", [module], version)
            for version in (2, 3)}


@pytest.fixture(scope="session")
def kind_fmus(build_dir):
    """``kind -> (scenario step, path)``: one FMU of every block kind of the scenarios, built once."""
    from faults_support import one_per_kind
    return one_per_kind(build_dir)
