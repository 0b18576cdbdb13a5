"""Shared fixtures: FMUs are built once per test session into a temporary directory."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def build_dir(tmp_path_factory):
    """A session-wide build directory (FMUs are rebuilt only when their sources change)."""
    return tmp_path_factory.mktemp("build")


@pytest.fixture(scope="session")
def ship_fmus(build_dir):
    from fmus.scenarios import ensure_fmus, get
    return ensure_fmus(get("ship"), build_dir)


@pytest.fixture(scope="session")
def every_fmu(build_dir):
    """model -> (scenario step, fmu path) for every distinct FMU used by a scenario."""
    from fmus.scenarios import SCENARIOS, ensure_fmus
    found = {}
    for scenario in SCENARIOS.values():
        for model, path in ensure_fmus(scenario, build_dir).items():
            found.setdefault(model, (scenario.step, path))
    return found


@pytest.fixture(scope="session")
def every_fmu3(build_dir):
    """model -> (scenario step, FMI 3.0 fmu path) for every distinct FMU used by a scenario (build_dir/fmi3)."""
    from fmus.scenarios import SCENARIOS, ensure_fmus
    found = {}
    for scenario in SCENARIOS.values():
        for model, path in ensure_fmus(scenario, build_dir, fmi_version=3).items():
            found.setdefault(model, (scenario.step, path))
    return found


@pytest.fixture(scope="session")
def kind_fmus(build_dir):
    """``kind -> (scenario step, path)``: one FMU of every block kind of the scenarios, built once."""
    from faults_support import one_per_kind
    return one_per_kind(build_dir)


def pytest_collection_modifyitems(config, items):
    """Tests marked ``full_reference`` re-derive a whole stored reference (minutes): opt-in."""
    import os

    if os.environ.get("OBSFMU_FULL_REFERENCES"):
        return
    skip = pytest.mark.skip(reason="re-derives a whole stored reference (minutes); set OBSFMU_FULL_REFERENCES=1")
    for item in items:
        if "full_reference" in item.keywords:
            item.add_marker(skip)
