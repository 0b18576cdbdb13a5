"""Component types generator-plant and gpebo-observer: every refusal names its field, before a build."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError

ROOT = Path(__file__).resolve().parents[3]

SOURCE = """
[components.source]
kind = "waveform"
amplitude = [1.0, 1.0]
omega = [1.0, 2.0]
"""
PLANT = """
[components.plant]
kind = "generator-plant"
f = ["sin(y)", "sin(y)"]
h_beta = [1, 0]
H_theta = [[1, 0], [0, 0]]
gamma_beta = [0, -1]
gamma_theta = [0, 1]
xi_beta0 = [1.0, 0.5]
xi_theta0 = [0.5, -0.4]
x0 = [0.3, -0.2]
"""
OBSERVER = """
[components.observer]
kind = "gpebo-observer"
plant = "plant"
input = "source"
gamma_hat0 = [-0.5, 0.5]
"""
HEAD = """name = "g"
connections = ["source.y -> plant.u", "source.y -> observer.u", "plant.y -> observer.y"]
[experiment]
stop_time = 40.0
step = 1.0
master = "jacobi"
"""


def system(source=SOURCE, plant=PLANT, observer=OBSERVER, replace=()):
    text = HEAD + source + plant + observer
    for old, new in replace:
        assert old in text, old
        text = text.replace(old, new, 1)
    return parse_system(text)


def refused(match: str, **keywords):
    with pytest.raises(ParameterError, match=match):
        system(**keywords)


def test_the_paper_example_builds_and_its_input_is_checked():
    spec = system()
    observer = [d for d in spec.definitions() if d.kind == "gpebo-observer"][0]
    assert [p.name for p in observer.parameters][-2:] == ["h_beta", "H_theta"]


def test_structure_may_be_the_observers_own():
    own = OBSERVER.replace('plant = "plant"\ninput = "source"\n', "") + (
        'f = ["sin(y)", 0]\nh_beta = [1, 0]\nH_theta = [[1, 0], [0, 0]]\n')
    system(observer=own)
    refused(r"components.observer.f: required \(or name a generator-plant",
            observer=OBSERVER.replace('plant = "plant"\ninput = "source"\n', ""))


@pytest.mark.parametrize("replace, match", [
    (('f = ["sin(y)", "sin(y)"]', 'f = ["sin(y)"]'), r"components.plant.f: expected 2 expressions"),
    (('x0 = [0.3, -0.2]', 'x0 = [0.3, -0.2]\ngamma_delta = [0, 1]'),
     r"components.plant.H_delta: the delta generator needs gamma_delta, xi_delta0 and H_delta together"),
    (('gamma_theta = [0, 1]', 'gamma_theta = [0, 1, 2]'), r"components.plant.gamma_theta: expected 2"),
    (('f = ["sin(y)", "sin(y)"]', 'f = ["sin(y)", "spin(y)"]'), r"components.plant.f\[2\]"),
    # issue 36: an unbounded generator was refused only by the excitation check, pointing at k_gamma
    (('gamma_theta = [0, 1]', 'gamma_theta = [2.5, -1]'), r"components.plant.gamma_theta: \[2.5, -1.0\] gives the "
     r"generator .* an eigenvalue of magnitude 2 > 1 .* grow without bound"),
    (('gamma_theta = [0, 1]', 'gamma_theta = [2, -1]'), r"components.plant.gamma_theta: .* a repeated eigenvalue "
     r"on the unit circle"),
])
def test_plant_refusals(replace, match):
    refused(match, replace=[replace])


@pytest.mark.parametrize("replace, match", [
    (('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [0, 0.5]'),
     r"components.observer.gamma_hat0: gamma_beta \(entry 1\) must be nonzero"),
    (('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [-0.5]'), r"components.observer.gamma_hat0: expected 2"),
    (('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [-0.5, 0.5]\nx_hat0 = [0, 0, 0]'),
     r"components.observer.x_hat0: expected 2"),
    (('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [-0.5, 0.5]\nh_beta = [1, 1]'),
     r"components.observer.h_beta: \[1.0, 1.0\] differs from the h_beta of the plant"),
    (('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [-0.5, 0.5]\nTs = 2.0'),
     r"components.observer.Ts: 2 differs from the plant's Ts = 1"),
    (('plant = "plant"', 'plant = "nope"'), r"components.observer.plant: 'nope' is not a component defined before"),
    (('plant = "plant"', 'plant = "source"'), r"components.observer.plant: 'source' is a component of kind "
                                              r"'waveform'"),
    (('input = "source"', 'input = "plant"'), r"components.observer.input: 'plant' is a generator-plant, not a "
                                              r"source"),
])
def test_observer_refusals(replace, match):
    refused(match, replace=[replace])


def test_the_plants_generators_must_have_the_observers_form():
    refused(r"components.observer.plant: gamma_theta of 'plant' is \[0.3, 0.5\], not \[0, ..., 0, g\]",
            replace=[("gamma_theta = [0, 1]", "gamma_theta = [0.3, 0.5]")])
    refused(r"components.observer.plant: gamma_beta of 'plant' ends in 0; the regression is divided by it",
            replace=[("gamma_beta = [0, -1]", "gamma_beta = [0, 0]")])


def test_structures_the_regression_cannot_take():
    refused(r"components.observer.h_beta: is zero, so the beta generator does not reach the output",
            replace=[("h_beta = [1, 0]", "h_beta = [0, 0]")])
    refused(r"components.observer.h_beta: the regression shifts by D = lcm of the generator sizes \[3, 2\] = 6",
            replace=[("h_beta = [1, 0]", "h_beta = [1, 0, 0]"), ("gamma_beta = [0, -1]", "gamma_beta = [0, 0, -1]"),
                     ("xi_beta0 = [1.0, 0.5]", "xi_beta0 = [1.0, 0.5, 0.2]")])


@pytest.mark.parametrize("source, measured", [
    ('[components.source]\nkind = "constant"\nvalue = 5.0\n', "constant u = 5"),
    ('[components.source]\nkind = "waveform"\namplitude = [0.0]\nomega = [1.0]\nexp_amplitude = 1.0\n'
     'exp_rate = 0.5\n', "u = exp(-0.5 t)"),
])
def test_an_input_that_does_not_excite_is_refused_with_the_measured_values(source, measured):
    with pytest.raises(ParameterError) as info:
        system(source=source)
    text = str(info.value)
    assert ("components.observer.input: 'source' does not excite the regressions over 40 samples of 'plant': "
            "nu_gamma = ") in text, (measured, text)
    nu_gamma = float(text.split("nu_gamma = ")[1].split(",")[0])
    assert nu_gamma > 1e-9, measured


def test_check_false_builds_an_unexcited_file_with_the_finding_for_the_fmus_log():
    spec = system(source='[components.source]\nkind = "constant"\nvalue = 5.0\n',
                  observer=OBSERVER.replace('input = "source"', 'input = "source"\ncheck = false'))
    observer = next(d for d in spec.definitions() if d.model_name.endswith("observer"))
    assert len(observer.warnings) == 1 and observer.warnings[0].startswith(
        "components.observer.input: 'source' does not excite the regressions over 40 samples")
    assert any("WARNING, built anyway (check = false): input:" in note for note in spec.notes)


def test_the_check_runs_the_planned_number_of_samples():
    # 12 samples are too few for the eta regression (it starts after the gamma one, ~ sample 14)
    refused(r"does not excite the regressions over 12 samples", replace=[
        ('input = "source"', 'input = "source"\nexcitation_samples = 12')])


def test_the_cli_refuses_with_exit_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(HEAD + SOURCE + PLANT + OBSERVER.replace("[-0.5, 0.5]", "[0, 0.5]"))
    done = subprocess.run([sys.executable, "-m", "obsfmu", "run", "--config", str(path)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert "components.observer.gamma_hat0: gamma_beta (entry 1) must be nonzero" in done.stderr
    assert np.char.count(done.stderr.strip(), "\n") <= 1


def test_a_sampling_period_in_phase_with_a_generator_is_refused():
    # Ts = pi/2: u(k) = sin(k pi/2) + sin(k pi) vanishes every other sample, in phase with beta (docs/paper000.md)
    ts = "Ts = 1.5707963267948966\n"
    refused(r"components.observer.input: 'source' does not excite the regressions over 40 samples of 'plant'",
            replace=[('input = "source"\n', 'input = "source"\n' + ts),
                     ('kind = "generator-plant"\n', 'kind = "generator-plant"\n' + ts)])


def test_a_check_run_that_fails_is_a_refusal_naming_the_input():
    refused(r"components.observer.input: the excitation check of 'source' driving 'plant' failed: .*not finite",
            replace=[('f = ["sin(y)", "sin(y)"]', 'f = ["1 / (y - 0.3)", "sin(y)"]')])


def test_a_structure_with_dependent_terms_is_refused_whatever_the_input():
    # theta1 * 1 and theta2 * 1 of one generator: two proportional columns, det M = 0 for every gamma
    refused(r"components.observer.f: with this f and H_theta the regression \(16\) has \d+ unknowns but rank 0",
            replace=[('f = ["sin(y)", "sin(y)"]', 'f = ["1", "1"]'), ("H_theta = [[1, 0], [0, 0]]",
                                                                      "H_theta = [[1, 0], [0, 1]]")])


def test_the_structural_rank_of_the_examples_is_full():
    from obsfmu.fmus.system.gpebo_types import block_of, structural_rank
    from obsfmu.fmus.system.load import load_system
    for path in (ROOT / "fmus/scenarios/discrete_gpebo/system.toml", ROOT / "examples/gpebo_shift3.toml"):
        observer = [d for d in load_system(path).definitions() if d.kind == "gpebo-observer"][0]
        assert structural_rank(block_of(observer)) == (5, 5)


# ------------------------------------------------------------------ whole gamma vectors unknown (gamma_*_unknown)
FULL_PLANT = [("gamma_beta = [0, -1]", "gamma_beta = [1.2, -1.0]"), ("gamma_theta = [0, 1]", "gamma_theta = [1.0, -0.96]")]
FULL_OBSERVER = ('gamma_hat0 = [-0.5, 0.5]', 'gamma_hat0 = [0.5, 0.5, 0.5, 0.5]\ngamma_beta_unknown = "all"\n'
                 'gamma_theta_unknown = "all"\nk_gamma = 1e-30\nexcitation_samples = 80')


def full(*more):
    return FULL_PLANT + [FULL_OBSERVER] + list(more)


def test_whole_gammas_build_and_their_input_is_checked():
    spec = system(replace=full())
    observer = [d for d in spec.definitions() if d.kind == "gpebo-observer"][0]
    assert observer.options["gamma_unknown"] == ["all", "all", "last"]
    assert [p for p in observer.outputs if p.name == "gamma_hat"][0].size == 4
    ordinary = [d for d in system().definitions() if d.kind == "gpebo-observer"][0]
    assert "gamma_unknown" not in ordinary.options          # today's files: the same FMU options


@pytest.mark.parametrize("more, match", [
    (('k_gamma = 1e-30', 'k_gamma = 1e-30\ngamma_delta_unknown = "all"'),
     r'components.observer.gamma_delta_unknown: "all" but there is no delta generator'),
    (('gamma_beta_unknown = "all"', 'gamma_beta_unknown = "some"'),
     r"components.observer.gamma_beta_unknown: 'some' is not one of last, all"),
    (('gamma_hat0 = [0.5, 0.5, 0.5, 0.5]', 'gamma_hat0 = [0.5, 0.5]'), r"components.observer.gamma_hat0: expected 4"),
    (('gamma_hat0 = [0.5, 0.5, 0.5, 0.5]', 'gamma_hat0 = [0.5, 0.5, 0.5, 0]'),
     r"components.observer.gamma_hat0: gamma_theta\[2\] \(entry 4\) must be nonzero"),
    (("gamma_beta = [1.2, -1.0]", "gamma_beta = [0.5, 0]"),
     r"components.observer.plant: gamma_beta of 'plant' has gamma_beta\[2\] = 0; the regression is divided by it"),
    (('k_gamma = 1e-30', 'k_gamma = 1e-8'),
     r"components.observer.input: 'source' does not excite the regressions over 80 samples of 'plant': .*; with a "
     r"whole gamma unknown the regression has p = 29 unknowns .* k_gamma = 1e-08 must be below Delta\^2"),
])
def test_whole_gamma_refusals(more, match):
    refused(match, replace=full(more))


def test_too_many_unknowns_are_refused_naming_the_field():
    # generator sizes 3 and 2, both whole: 1 + 3 + 2 = 6 rows but 59 unknowns (measured: DREM cannot take them)
    refused(r"components.observer.gamma_beta_unknown: the full-gamma regression has 59 unknowns; at most 50",
            replace=full(("h_beta = [1, 0]", "h_beta = [1, 0, 0]"), ("xi_beta0 = [1.0, 0.5]", "xi_beta0 = [1, 0.5, 0.2]"),
                         ("gamma_beta = [1.2, -1.0]", "gamma_beta = [0.3, -0.5, 0.8]"),
                         ("gamma_hat0 = [0.5, 0.5, 0.5, 0.5]", "gamma_hat0 = [0.5, 0.5, 0.5, 0.5, 0.5]")))


def test_a_plant_outside_the_last_form_names_the_field_that_admits_it():
    refused(r'components.observer.plant: gamma_theta of .* not \[0, ..., 0, g\].*set gamma_theta_unknown = "all"',
            replace=[("gamma_theta = [0, 1]", "gamma_theta = [0.3, 0.5]")])


def test_a_whole_gamma_regression_of_rank_0_is_refused_whatever_the_input():
    # f = 0: the theta term vanishes, every row of the regression is 0 on generic data
    refused(r"components.observer.f: with this f and H_theta the regression \(16\) has 29 unknowns but rank 0",
            replace=full(('f = ["sin(y)", "sin(y)"]', 'f = ["0", "0"]')))
