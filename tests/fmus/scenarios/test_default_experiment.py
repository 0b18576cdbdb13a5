"""Every FMU declares a ``DefaultExperiment`` (issue 28.6): the start, stop and step of its scenario or design,
in its FMI 2.0 and FMI 3.0 modelDescription, so that importers run it without options.

``ltv-ls`` and ``ltv-ls-bounded`` are system files, each with its own FMUs declaring its own run.
"""

import pytest
from fmpy import read_model_description

from obsfmu.fmus.scenarios import SCENARIOS

PAPER_001 = {"ltv_ls_source", "ltv_ls_plant", "ltv_ls_observer"}


def declared(path) -> tuple[float, float, float, object]:
    experiment = read_model_description(str(path)).defaultExperiment
    assert experiment is not None, path
    return (*(float(value) for value in (experiment.startTime, experiment.stopTime, experiment.stepSize)),
            experiment.tolerance)


@pytest.mark.parametrize("fixture", ["every_fmu", "every_fmu3"])
def test_every_fmu_declares_the_run_of_its_scenario(request, fixture):
    fmus = request.getfixturevalue(fixture)
    by_model = {model: scenario for scenario in SCENARIOS.values() for _, model, _ in scenario.components}
    assert set(by_model) == set(fmus) and len(fmus) >= 17
    for model, (_, path) in fmus.items():
        scenario = by_model[model]
        assert declared(path) == (0.0, scenario.stop_time, scenario.step, None), model
    assert {m for m, s in by_model.items() if s.name == "ltv-ls"} == PAPER_001


def test_the_bounded_case_declares_its_own_run_not_the_paper_case(every_fmu):
    bounded = SCENARIOS["ltv-ls-bounded"]
    for model in PAPER_001:
        _, stop, step, _ = declared(every_fmu[model][1])
        _, bounded_stop, bounded_step, _ = declared(every_fmu[model.replace("ltv_ls", "ltv_ls_bounded")][1])
        assert (stop, step) == (15.0, 1e-3) and (bounded_stop, bounded_step) == (20.0, 1e-2)


def test_a_design_built_alone_declares_its_own_run(tmp_path):
    """``obsfmu build --config``: 10 time constants of the slowest designed pole, a hundredth of the fastest."""
    from obsfmu.fmus.cli.main import main

    design = tmp_path / "ship.toml"          # paper 002's design: t_settle 0.15 s (observer), 0.3 s (loop)
    design.write_text('name = "ship"\n[plant]\nA = [[0, 1], [-2, 3]]\nB = [[0], [1]]\nC = [[1, 0]]\n'
                      "[observer]\nt_settle = 0.15\n[controller]\nt_settle = 0.3\n")
    assert main(["build", "--config", str(design), "--out", str(tmp_path)]) == 0
    built = sorted(tmp_path.glob("ship_*.fmu"))
    assert len(built) == 3
    for path in built:  # poles -40 (observer), -20 (controller): 10 / 20 s, 0.01 / 40 s to one digit
        assert declared(path) == (0.0, 0.5, 3e-4, None), path.name
