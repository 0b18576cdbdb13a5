"""Paper 003's component types (ltv-disturbed-plant, uio-ftdrem-observer): the observer designed from the
plant's matrices, every checkable assumption of the paper refused before anything is built, one line naming
the field and the assumption."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError

ROOT = Path(__file__).resolve().parents[3]
PAPER = (ROOT / "fmus" / "scenarios" / "uio_ftdrem" / "system.toml").read_text()


def changed(*pairs: str, text: str = PAPER) -> str:
    """``text`` with each (old, new) pair replaced; every old text must be there."""
    for old, new in zip(pairs[::2], pairs[1::2]):
        assert old in text, old
        text = text.replace(old, new)
    return text


REFUSED = {
    "relative degree too low": (changed("r = 2\n", "r = 1\n"),
                                "components.observer.r: rank(C A^0 B) = 0 != rank B = 1 (C A^0 B = 0): (3) has no "
                                "solution"),
    "relative degree beyond n": (changed("r = 2\n", "r = 3\n"), "components.observer.r: the relative degree must be"),
    "unstable pole": (changed("poles = [-0.5, -0.3]", "poles = [0.5, -0.3]"),
                      "components.observer.poles: 0.5 not in the open left half-plane; F = M - L C must be Hurwitz"),
    "gain not Hurwitz": (changed("poles = [-0.5, -0.3]", "L = [0.0, 0.0]"),
                         "components.observer.L: eig(M - L C) = [0, 0] not all in the open left half-plane"),
    "poles and gain": (changed("poles = [-0.5, -0.3]", "poles = [-0.5, -0.3]\nL = [0.4, 0.075]"),
                       "components.observer.poles: give exactly one of 'poles'"),
    "wrong number of harmonics": (changed("harmonics = 1", "harmonics = 2"),
                                  "components.observer.harmonics: 2, but the disturbance of 'plant' has 1 sinusoids"),
    "zero frequency": (changed("omega = [1.0]", "omega = [0.0]"),
                       "components.plant.omega: frequencies must be > 0"),
    "equal frequencies": (changed("omega = [1.0]\nphase = [0.0]", "omega = [1.0, 1.0]\nphase = [0.0, 0.0]",
                                  "amplitude = [5.0]", "amplitude = [5.0, 1.0]", "harmonics = 1\n", ""),
                          "components.observer.harmonics: the frequencies of 'plant' [1.0, 1.0] are not distinct"),
    "no sinusoid": (changed("omega = [1.0]\nphase = [0.0]", "omega = []\nphase = []", "amplitude = [5.0]",
                            "amplitude = []"), "components.plant.amplitude: no sinusoid; f is a sum of N >= 1"),
    "growing generator": (changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", "Gamma = [[0.1, 0.0], [0.0, 0.0]]"),
                          "components.plant.Gamma: eigenvalue 0.1 has Re > 0, e^(components.plant.Gamma t) and "
                          "theta grow without bound; the observer needs a bounded generator"),
    "growing rotation": (changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", "Gamma = [[0.01, 1.0], [-1.0, 0.0]]"),
                         "components.plant.Gamma: eigenvalue 0.005+0.999987j has Re > 0"),
    "Jordan block on the imaginary axis": (
        changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", "Gamma = [[0.0, 1.0], [0.0, 0.0]]"),
        "components.plant.Gamma: eigenvalue 0 on the imaginary axis is not semisimple (multiplicity 2, 1 "
        "eigenvector(s)): e^(components.plant.Gamma t) grows like t^1"),
    "generator decaying faster than the filters": (
        changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", "Gamma = [[-20.0, 0.0], [0.0, 0.0]]"),
        "components.observer.lambda2: 10 <= -min Re eig(Gamma) = 20; the filters of (14)/(17) modulated by "
        "e^(Gamma t) need Re eig(Gamma) > -lambda2"),
    "generator of the wrong size": (changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", "Gamma = [[0.0]]"),
                                    "components.plant.Gamma: expected 2 rows"),
    "B_bar B != 1": (changed("B_bar = [1.0, 1.0]", "B_bar = [1.0, 2.0]"),
                     "components.observer.B_bar: B_bar B must be 1, got 2"),
    "input vector of the wrong size": (changed("B = [0.0, 1.0]", "B = [0.0, 1.0, 0.0]"),
                                       "components.plant.B: expected 2 entries, got 3"),
    "H of the wrong shape": (changed("H = [[1.0, 0.0], [0.0, 1.0]]", "H = [[1.0, 0.0, 0.0]]"),
                             "components.plant.H: expected 2 rows"),
    "output blind to the input": (changed("B = [0.0, 1.0]", "B = [0.0, 0.0]"),
                                  "components.observer.plant: 'plant': B: C A^k B = 0 for every k < n"),
    "switching level": (changed("mu = 0.98", "mu = 1.5"), "components.observer.mu: entries must lie in (0, 1)"),
    "three gains": (changed("gamma = [1e6, 1e6, 1e6, 1e6]", "gamma = [1e6, 1e6, 1e6]"),
                    "components.observer.gamma: expected 4 entries, got 3"),
    "zero gain": (changed("gamma = [1e6, 1e6, 1e6, 1e6]", "gamma = [1e6, 0, 1e6, 1e6]"),
                  "components.observer.gamma: entry 2 (stage 2) is 0; every FT-DREM gain must be > 0"),
    "xi0_free not 0/1": (changed("xi0_free = [0.0, 1.0]", "xi0_free = [0.0, 2.0]"),
                         "components.observer.xi0_free: entries must be 0 (known) or 1 (estimated)"),
    "extension rates": (changed("mu = 0.98", "mu = 0.98\nrates2 = [10.0]"),
                        "components.observer.rates2: expected 2 entries, got 1"),
    "filter rate": (changed("lambda2 = 10.0", "lambda2 = -1.0"), "components.observer.lambda2: must be > 0"),
    "filter order below r": (changed("mu = 0.98", "mu = 0.98\nfilter_order = 1"),
                             "components.observer.filter_order: the filter of (14) needs order >= r = 2"),
}

#: a third-order plant with relative degree 2 and its zero at +1 (C (sI - A)^-1 B = (1 - s) / ...)
NON_MINIMUM_PHASE = changed("A = [[0.0, 1.0], [-2.0, 0.0]]",
                            "A = [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-2.0, -3.0, -1.0]]",
                            "B = [0.0, 1.0]", "B = [0.0, 0.0, 1.0]", "C = [2.0, 0.0]", "C = [1.0, -1.0, 0.0]",
                            "H = [[1.0, 0.0], [0.0, 1.0]]\n", "", "Gamma = [[0.0, 0.0], [0.0, 0.0]]", "",
                            "xi0 = [0.0, -1.0]", "xi0 = [0.0, 0.0, -1.0]", "x0 = [-1.0, 1.0]", "x0 = [1.0, 0.0, 0.0]",
                            "B_bar = [1.0, 1.0]", "", "z0 = [-3.0, 3.0]", "",
                            "xi0_free = [0.0, 1.0]", "xi0_free = [0.0, 0.0, 1.0]", "xi0_known = [0.0, 0.0]",
                            "xi0_known = [0.0, 0.0, 0.0]")
REFUSED["unstable zero"] = (NON_MINIMUM_PHASE, "components.observer.poles: the plant is not minimum phase: its "
                                               "invariant zeros [1.0]")
REFUSED["n poles for a plant with a zero"] = (
    changed("poles = [-0.5, -0.3]", "poles = [-0.5, -0.3, -1]", "C = [1.0, -1.0, 0.0]", "C = [1.0, 1.0, 0.0]",
            text=NON_MINIMUM_PHASE),
    "components.observer.poles: (M, C) has 1 unobservable eigenvalues [-1.0] (the plant's zeros, kept in F); give "
    "the 2 poles")


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_each_assumption_is_refused_naming_the_field(case):
    text, expected = REFUSED[case]
    with pytest.raises(ParameterError) as refused:
        parse_system(text, "uio.toml")
    message = str(refused.value)
    assert expected in message, message
    assert message.startswith("uio.toml:") and "\n" not in message


def test_the_cli_refuses_in_one_line_with_exit_2_and_builds_nothing(tmp_path):
    (tmp_path / "bad.toml").write_text(REFUSED["unstable zero"][0])
    done = subprocess.run([sys.executable, "-m", "obsfmu", "build", "--config", "bad.toml", "--out", "fmus"],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert len(done.stderr.strip().splitlines()) == 1 and "Traceback" not in done.stderr
    assert "components.observer.poles: the plant is not minimum phase" in done.stderr
    assert not list(tmp_path.glob("fmus/**/*.fmu"))


def _observer_parameters(spec) -> dict:
    definition = spec.components["observer"].definitions[0]
    return {p.name: np.asarray(p.value, dtype=float) for p in definition.parameters}


def test_the_observer_is_designed_from_the_plant_and_the_build_notes_say_so():
    spec = parse_system(PAPER, "uio.toml")
    assert spec.notes == ["components.observer: r = 2, G = [0, 0.5], L = [0.4, 0.075]; eig(F) = [-0.5, -0.3]"]
    parameters = _observer_parameters(spec)
    np.testing.assert_allclose(parameters["L"], [0.4, 0.075], rtol=1e-12)
    np.testing.assert_array_equal(parameters["A"].ravel(), [0.0, 1.0, -2.0, 0.0])   # the plant's, not given again


def test_the_paper_file_makes_the_definitions_the_python_scenario_made():
    """The FMU parameters of the file equal those of the kinds' definition functions with the paper's values
    (what made the scenario's CSV bit for bit the same as before it was a file)."""
    from obsfmu.fmus.runtime.kinds.uio import ltv_plant_definition, uio_observer_definition
    from obsfmu.observers.uio import uio_gain
    A, B, C = [[0.0, 1.0], [-2.0, 0.0]], [0.0, 1.0], [2.0, 0.0]
    expected = {"plant": ltv_plant_definition("p", A, B, C, np.eye(2), np.zeros((2, 2)), [0.0, -1.0], [-1.0, 1.0],
                                              [5.0], [1.0], [0.0]),
                "observer": uio_observer_definition("o", A, B, C, 2, uio_gain(A, B, C, 2, [-0.5, -0.3]), np.eye(2),
                                                    [1.0, 1.0], [-3.0, 3.0], [0.0, 1.0], [0.0, 0.0])}
    spec = parse_system(PAPER, "uio.toml")
    for instance, definition in expected.items():
        ours = spec.components[instance].definitions[0]
        # the file adds step_rate to its adaptive observer: the fastest rate, for the converged flag (load.py)
        own = [p for p in ours.parameters if p.name != "step_rate"]
        assert (instance == "observer") == (len(own) < len(ours.parameters))
        assert [p.name for p in own] == [p.name for p in definition.parameters]
        for mine, theirs in zip(own, definition.parameters):
            np.testing.assert_array_equal(np.asarray(mine.value, float), np.asarray(theirs.value, float), mine.name)
        assert [(p.name, p.size) for p in ours.outputs] == [(p.name, p.size) for p in definition.outputs]


def test_defaults_relative_degree_B_bar_and_the_rates_not_given():
    text = changed("r = 2\n", "", "B_bar = [1.0, 1.0]", "", "harmonics = 1", "", "mu = 0.98",
                   "mu = 0.98\nrates2 = [8.0, 4.0]")
    parameters = _observer_parameters(parse_system(text, "uio.toml"))
    assert parameters["r"].ravel().tolist() == [2.0]                                 # C B = 0, C A B = 2
    np.testing.assert_array_equal(parameters["B_bar"], [0.0, 1.0])       # B / |B|^2
    np.testing.assert_array_equal(parameters["rates2"], [8.0, 4.0])
    np.testing.assert_array_equal(parameters["rates1"], [10.0])          # lambda1 / 1: the default of the others


def test_a_plant_with_a_stable_zero_places_only_the_observable_poles():
    text = changed("C = [1.0, -1.0, 0.0]", "C = [1.0, 1.0, 0.0]", text=NON_MINIMUM_PHASE)
    spec = parse_system(text, "uio.toml")
    eigenvalues = spec.notes[0].rpartition("eig(F) = [")[2]
    assert sorted(float(v) for v in eigenvalues.rstrip("]").split(", ")) == pytest.approx([-1.0, -0.5, -0.3])


def test_a_bounded_generator_is_accepted_and_handed_to_the_observer():
    """theta = H e^{Gamma t} xi(0) with a rotation (eigenvalues +-0.5j, semisimple) and a decaying mode: both
    accepted; the observer FMU gets the plant's Gamma (it builds the modulated filters from it)."""
    for Gamma in ([[0.0, 0.5], [-0.5, 0.0]], [[-0.5, 1.0], [0.0, -0.5]]):    # the second: a stable Jordan block
        text = changed("Gamma = [[0.0, 0.0], [0.0, 0.0]]", f"Gamma = {Gamma}")
        parameters = _observer_parameters(parse_system(text, "uio.toml"))
        np.testing.assert_array_equal(parameters["Gamma"], np.ravel(Gamma))
    np.testing.assert_array_equal(_observer_parameters(parse_system(PAPER, "uio.toml"))["Gamma"], np.zeros(4))
