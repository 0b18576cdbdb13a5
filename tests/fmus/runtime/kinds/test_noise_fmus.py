"""The noise kinds (fmus/runtime/kinds/noise.py) as FMUs: the documented white sequence computed here,
reproducible by seed whatever the step, band-limited as the block, noise added on a connection of a
co-simulation.  (The statistics of the sequences: tests/plants/test_noise.py.)"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import read_model_description

from obsfmu.fmus.master import Component, Connection, System, cosimulate
from obsfmu.fmus.runtime.kinds.noise import added_noise_definition, noise_source_definition
from obsfmu.fmus.runtime.kinds.sources import sine_source_definition
from kinds_support import build_all, simulate, started
from obsfmu.observers.checks import ParameterError
from obsfmu.plants.noise import Noise

DT, STD, SEED = 0.01, 0.3, 11


def white(t, std=STD, seed=SEED, size=1, dt=DT, uniform=False):
    """The module docstring of plants/noise.py: w_k from default_rng((seed, k)), k = floor(t / dt)."""
    k = int(math.floor(t / dt + 1e-9))
    rng = np.random.default_rng((seed, k))
    return std * (rng.uniform(-math.sqrt(3), math.sqrt(3), size) if uniform else rng.standard_normal(size))


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    return build_all([
        noise_source_definition("gauss", STD, DT, SEED, size=2, unit="V"),
        noise_source_definition("uniform", STD, DT, SEED, distribution="uniform"),
        noise_source_definition("band", STD, DT, SEED, cutoff_hz=4.0, filter_order=2),
        added_noise_definition("sensor", STD, DT, SEED, unit="m"),
        sine_source_definition("wave", 1.0, 0.5, unit="m"),
    ], tmp_path_factory.mktemp("noise"))


def test_white_noise_is_the_documented_sequence_whatever_the_communication_step(fmus):
    for step in (DT, DT / 4, 3 * DT):
        result = simulate(fmus["gauss"], 1.0, step)
        got = np.column_stack([result["y[1]"], result["y[2]"]])
        expected = np.array([white(t, size=2) for t in result["time"]])
        np.testing.assert_array_equal(got, expected)
    result = simulate(fmus["uniform"], 0.5, DT)
    np.testing.assert_array_equal(result["y"], [white(t, uniform=True)[0] for t in result["time"]])
    assert np.max(np.abs(result["y"])) <= STD * math.sqrt(3)


def test_the_seed_and_std_are_parameters(fmus):
    result = simulate(fmus["gauss"], 0.3, DT, seed=4.0, std=2.0)
    np.testing.assert_array_equal(result["y[2]"], [white(t, 2.0, 4, 2)[1] for t in result["time"]])
    assert not np.array_equal(result["y[1]"], simulate(fmus["gauss"], 0.3, DT, seed=5.0, std=2.0)["y[1]"])


def test_band_limited_noise_is_reproducible_and_the_block_stream(fmus):
    first, second = simulate(fmus["band"], 2.0, DT), simulate(fmus["band"], 2.0, DT / 2)
    noise = Noise(STD, DT, SEED, cutoff_hz=4.0, filter_order=2)
    np.testing.assert_array_equal(first["y"], [noise(t)[0] for t in first["time"]])
    np.testing.assert_array_equal(second["y"][::2], first["y"])
    assert np.corrcoef(first["y"][:-1], first["y"][1:])[0, 1] > 0.5       # low-passed: correlated neighbours


def test_noise_added_on_a_connection_of_a_cosimulation(fmus):
    system = System([Component("wave", fmus["wave"]), Component("sensor", fmus["sensor"])],
                    [Connection("wave.y", "sensor.u")])
    result = cosimulate(system, 1.0, DT / 2)
    t = result.time
    expected = np.sin(np.pi * t) + np.array([white(s)[0] for s in t])
    np.testing.assert_allclose(result["sensor.y"], expected, rtol=0, atol=1e-12)
    description = read_model_description(str(fmus["sensor"]))
    assert description.outputs[0].dependencies and description.coSimulation.maxOutputDerivativeOrder == 0
    assert {v.name: v.unit for v in description.modelVariables}["u"] == "m"


@pytest.mark.parametrize("settings, field", [
    ({"std": -1.0}, "std"), ({"sample_interval": 0.0}, "sample_interval"), ({"seed": 1.5}, "seed"),
    ({"distribution": "cauchy"}, "distribution"), ({"cutoff_hz": -2.0}, "cutoff_hz"),
    ({"cutoff_hz": 2.0, "filter_order": 3}, "filter_order"),
])
def test_a_bad_setting_is_refused_at_build_time_naming_it(settings, field):
    with pytest.raises(ParameterError, match=f"^{field}"):
        added_noise_definition("bad", **settings)


def test_band_limited_noise_after_a_restored_fmu_state_is_the_same_stream(fmus):
    slave, refs = started(fmus["band"], "band")
    try:
        for k in range(300):                           # past a checkpoint of the filter
            slave.doStep(k * DT, DT)
        saved = slave.serializeFMUstate(slave.getFMUstate())
        first = []
        for k in range(300, 340):
            slave.doStep(k * DT, DT)
            first += slave.getReal([refs["y"]])
        slave.setFMUstate(slave.deSerializeFMUstate(saved))
        again = []
        for k in range(300, 340):
            slave.doStep(k * DT, DT)
            again += slave.getReal([refs["y"]])
        assert again == first
        assert slave.getRealOutputDerivatives([refs["y"]], [1]) == [0.0]          # held: derivative 0
    finally:
        slave.terminate()
        slave.freeInstance()
