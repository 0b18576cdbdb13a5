"""The benchmarks' yardstick is honest: the direct loop computes exactly what the FMU path computes.

``benchmarks/direct_loop.py`` steps the same blocks in one process (issue 14, target 1 compares
the FMU master's cost with it).  Same blocks, segments, coupling, order and outputs read: the
trajectories must agree to the last bit on the FMUs' Python path (``OBSFMU_KERNELS=python``), start-up ramp
included; with the compiled step kernels (issue 39: the linear blocks in C, their sums in another order) to 1e-12
of each column's largest value.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.direct_loop import for_scenario
from obsfmu.fmus.master import Session, communication_points
from obsfmu.fmus.scenarios import ensure_fmus, get, system


@pytest.mark.parametrize("kernels", ["python", "c"])
@pytest.mark.parametrize("name, stop_time, ramp", [("ship", 0.01, 0), ("ltv-ls-bounded", 0.2, 6),
                                                    ("uio-ftdrem", 0.05, 2)])
def test_the_direct_loop_is_the_fmu_path_without_fmi(build_dir, monkeypatch, name, stop_time, ramp, kernels):
    monkeypatch.setenv("OBSFMU_KERNELS", kernels)
    scenario = get(name)
    with Session(system(scenario, ensure_fmus(scenario, build_dir)), echo_log=False) as session:
        result = session.run(stop_time, scenario.step, ramp=ramp)
    loop = for_scenario(scenario)
    times, rows = loop.run(stop_time, scenario.step, ramp=ramp)
    names = [f"{node.name}.{output}" for node in loop.nodes for output in node.output_names]
    np.testing.assert_array_equal(times, result.time)
    direct = rows[:, [names.index(c) for c in result.columns]]
    if kernels == "python":
        np.testing.assert_array_equal(direct, result.values)
    else:
        scale = np.maximum(np.max(np.abs(direct), axis=0), 1e-300)
        assert np.all(np.max(np.abs(direct - result.values), axis=0) <= 1e-12 * scale)


def test_the_start_up_ramp_splits_only_the_first_step():
    steps = list(communication_points(0.0, 1.0, 0.25, ramp=3))
    assert [h for _, h, _ in steps] == [0.03125, 0.03125, 0.0625, 0.125, 0.25, 0.25, 0.25]
    assert [t for t, _, _ in steps] + [steps[-1][2]] == [0.0, 0.03125, 0.0625, 0.125, 0.25, 0.5, 0.75, 1.0]
    assert all(t + h == t_next for t, h, t_next in steps[:4])          # the ramp lands on the grid exactly
    steps = list(communication_points(0.0, 0.6, 0.25))
    assert [t_next for _, _, t_next in steps] == [0.25, 0.5, 0.6] and steps[-1][1] == pytest.approx(0.1)
