"""The monolithic references live in the scenario folders and stay independent of the code they check."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from obsfmu.fmus import scenarios as bundled_scenarios

FOLDER = Path(bundled_scenarios.__file__).parent
REFERENCES = sorted(FOLDER.glob("*/reference.py"))
PROJECT = {"observers", "plants", "fmus", "benchmarks", "tests"}


def test_every_paper_has_its_reference_generator_in_a_scenario_folder():
    assert [path.parent.name for path in REFERENCES] == [
        "discrete_gpebo", "ltv_common", "ship", "state_affine_common", "uio_ftdrem"]


def test_a_shared_folder_is_no_scenario():
    names = {scenario.name for scenario in bundled_scenarios.SCENARIOS.values()}
    assert not any(name.endswith("common") for name in names)
    assert {"ltv-ls", "ltv-ls-bounded", "state-affine-pendulum", "state-affine-chemostat"} <= names


@pytest.mark.parametrize("path", REFERENCES, ids=lambda path: path.parent.name)
def test_a_reference_imports_nothing_of_the_project(path):
    imported = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            imported |= {alias.name.partition(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add("(relative)" if node.level else node.module.partition(".")[0])
    assert not imported & (PROJECT | {"(relative)"}), f"{path} imports {sorted(imported & (PROJECT | {'(relative)'}))}"
