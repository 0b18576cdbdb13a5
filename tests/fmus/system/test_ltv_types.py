"""The component types ``ltv-plant`` and ``ltv-adaptive-observer`` (paper 001) of a system file.

Every refusal names the field and the assumption in one line, before anything is built; the good
file builds the definitions the kinds take (expression functions, the estimator's parameters).
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError

ROOT = Path(__file__).resolve().parents[3]

GOOD = '''name = "msd"
connections = ["force.y -> plant.u", "force.y -> observer.u", "plant.y -> observer.y"]

[experiment]
stop_time = 20.0
step = 1e-2

[components.force]
kind = "sine"

[components.plant]
kind = "ltv-plant"
A = [[0, 1], [0, 0]]
C = [1, 0]
f = "y**3"
k = [-0.6, -4]
b = [0, 1]
m = [0, -0.5]
x0 = [0.5, 0.3]

[components.observer]
kind = "ltv-adaptive-observer"
A = [[0, 1], [0, 0]]
C = [1, 0]
L = [0, 9]
f = "y**3"
unknowns = "k"
b = [0, 1]
m = [0, -0.5]
'''


def _bad(old: str, new: str, text: str = GOOD) -> str:
    assert old in text, old
    return text.replace(old, new, 1)


_OBSERVER_F = 'L = [0, 9]\nf = "y**3"\nunknowns = "k"\nb = [0, 1]\nm = [0, -0.5]\n'
BAD = {
    # issue 36: the terms of the unknowns dependent for every y: their columns coincide, nothing ever moves
    "f = y with k and m unknown": (_bad(_OBSERVER_F, 'L = [0, 9]\nf = "y"\nunknowns = "k, m"\nb = [0, 1]\n'),
                                   "components.observer.unknowns: m (its term m f(y)) cannot be separated from k "
                                   "(its term k y)"),
    "two f_i dependent": (_bad(_OBSERVER_F, 'L = [0, 9]\nf = ["y**3", "sin(y)", "2*y**3 - 3*sin(y)"]\nunknowns = '
                                            '"m"\nb = [0, 1]\nk = [-0.6, -4]\n'),
                          "components.observer.unknowns: m_3 (the column of f[3]) cannot be separated from m_1 (the "
                          "column of f[1]) and m_2 (the column of f[2])"),
    "a zero term": (_bad(_OBSERVER_F, 'L = [0, 9]\nf = ["y**3", "0*y"]\nunknowns = "m"\nb = [0, 1]\nk = [-0.6, -4]\n'),
                    "components.observer.unknowns: m_2 (the column of f[2]) multiplies a term that is zero"),
    "C(t) unobservable later": (_bad('C = [1, 0]\nL', 'C = ["where(t > 5, 0, 1)", 0]\nL'),
                                "components.observer.C: (A0(t), C^T) is not observable at t = 5.02513"),
    "C(t) of y": (_bad('C = [1, 0]\nL', 'C = ["y", 0]\nL'), "components.observer.C[1]"),
    "f_correction with C(t)": (_bad('C = [1, 0]\nL', 'C = ["1 + 0.1 * sin(t)", 0]\nf_correction = true\nL'),
                               "components.observer.f_correction: resolves the fast part of y that m f(y) drives "
                               "for one f of y only and a constant C; this plant has C(t)"),
    "m of two nonlinearities": (_bad('f = "y**3"\nunknowns', 'f = ["y**3", "sin(y)"]\nunknowns'),
                                "components.observer.m: expected an n x p = 2 x 2 matrix (one column m_i per "
                                "nonlinearity f_i), got shape (2,)"),
    "m_hat0 of two nonlinearities": (_bad('f = "y**3"\nunknowns = "k"\nb = [0, 1]\nm = [0, -0.5]',
                                          'f = ["y**3", "sin(y)"]\nunknowns = "k, m"\nb = [0, 1]\n'
                                          'm_hat0 = [[0, 1, 2], [0, 0, 0]]'),
                                     "components.observer.m_hat0: expected an n x p = 2 x 2 matrix"),
    "zero C": (_bad('C = [1, 0]\nL', 'C = [0, 0]\nL'), "components.observer.C: the output vector is zero"),
    "A shape": (_bad('A = [[0, 1], [0, 0]]\nC = [1, 0]\nL', 'A = [[0, 1, 2], [0, 0, 1]]\nC = [1, 0]\nL'),
                "components.observer.A: expected 2 x 2 expressions (rows)"),
    "L shape": (_bad('L = [0, 9]', 'L = [0, 9, 1]'), "components.observer.L: expected 2 expressions"),
    "k size": (_bad('k = [-0.6, -4]', 'k = [-0.6, -4, 1]'), "components.plant.k: expected 2 entries"),
    "not observable": (_bad('A = [[0, 1], [0, 0]]\nC = [1, 0]\nL = [0, 9]',
                            'A = [[-1, 0], [0, -2]]\nC = [1, 0]\nL = [0, 0]'),
                       "components.observer.C: (A0(t), C^T) is not observable at t = 0"),
    "unknowns x0": (_bad('unknowns = "k"', 'unknowns = "k, x0"'),
                    "components.observer.unknowns: expected distinct names among k, b, m separated by commas"),
    "unknowns twice": (_bad('unknowns = "k"', 'unknowns = "k, k"'), "components.observer.unknowns: expected distinct"),
    "known without value": (_bad('unknowns = "k"\nb = [0, 1]\n', 'unknowns = "k"\n'),
                            "components.observer.b: b is known (not in unknowns); its value is required"),
    "value of an unknown": (_bad('unknowns = "k"', 'unknowns = "k, b"'),
                            "components.observer.b: b is in unknowns (estimated); give no value"),
    "estimate of a known": (_bad('unknowns = "k"', 'unknowns = "k"\nb_hat0 = [0, 1]'),
                            "components.observer.b_hat0: b is known (not in unknowns); it has no estimate"),
    "estimator": (_bad('unknowns = "k"', 'unknowns = "k"\nestimator = "kalman"'), "components.observer.estimator"),
    "noise bound with DREM": (_bad('unknowns = "k"', 'unknowns = "k"\nestimator = "drem"\n'
                                                     'regression_error_bound = 0.1'),
                              "components.observer.regression_error_bound: the drem estimator's converged bound holds "
                              "for an exact regression only"),
    "f of t with f_correction": (_bad('f = "y**3"\nunknowns', 'f = "t * y"\nf_correction = true\nunknowns'),
                                 "components.observer.f_correction: resolves the fast part of y that m f(y) drives "
                                 "for one f of y only and a constant C; this plant has f depending on t"),
    "f of x": (_bad('f = "y**3"\nunknowns', 'f = "x[1]"\nunknowns'), "components.observer.f[1]"),
}

#: observer gains L for which A0 = A - L C^T breaks Assumptions 3-4, and the message
UNSTABLE = {
    "A0 constant unstable": ("[-1, 9]", "components.observer.L: A0(t) = A(t) - L(t) C^T has the eigenvalue "
                                        "0.5+2.95804j (A0 is constant) (real part > 0)"),
    "A0 Jordan block": ("[0, 0]", "components.observer.L: A0 = A - L C^T is constant with the eigenvalue 0 on the "
                                  "imaginary axis 2 times but a Jordan block"),
    "A0 varying unstable": ('["-sin(t)", 9]', "has the eigenvalue 0.0501667+2.99958j at t = 0.100503 (real part > "
                                              "0); choose L(t) so that A0 is uniformly stable (paper 001, "
                                              "Assumptions 3-4)"),
    "A0 unstable after 10 s": ('["where(t > 12, -1, 1)", 9]', "components.observer.L: A0(t) = A(t) - L(t) C^T has "
                                                              "the eigenvalue 0.5+2.95804j at t = 12.0603"),
}
BAD.update({case: (_bad("L = [0, 9]", f"L = {L}"), message) for case, (L, message) in UNSTABLE.items()})


@pytest.mark.parametrize("case", sorted(BAD))
def test_each_assumption_and_dimension_is_refused_naming_the_field(case):
    text, expected = BAD[case]
    with pytest.raises(ParameterError) as caught:
        parse_system(text, "f.toml")
    assert expected in str(caught.value), str(caught.value)
    assert "\n" not in str(caught.value)


def test_the_grid_covers_the_stop_time_only():
    """An A0 unstable after 12 s is refused for a 20 s run (above), accepted for a 10 s one, over which it is
    constant (the block's own check covers [0, 10] only); a varying one is said to be checked at frozen times."""
    text = BAD["A0 unstable after 10 s"][0]
    system = parse_system(text.replace("stop_time = 20.0", "stop_time = 10.0"), "f.toml")
    assert system.notes[0] == "components.observer: A0(t) = A(t) - L(t) C^T constant, uniformly stable"
    system = parse_system(_bad('L = [0, 9]', 'L = ["1 + 0.5 * sin(t)", 9]'), "f.toml")
    assert system.notes[0] == ("components.observer: A0(t) = A(t) - L(t) C^T stable at 200 frozen times of [0, 20] "
                               "(necessary only)")


def test_a_good_file_builds_expression_functions_and_the_estimators_parameters():
    system = parse_system(GOOD, "f.toml")
    assert system.notes[0] == "components.observer: A0(t) = A(t) - L(t) C^T constant, uniformly stable"
    observer = system.components["observer"].definitions[0]
    assert observer.options["A"]["expressions"] == ["0.0", "1.0", "0.0", "0.0"]
    assert observer.options["unknowns"] == "k" and "estimator" not in observer.options
    names = {p.name for p in observer.parameters}
    assert {"b", "m", "gamma", "beta", "f0", "M", "x_hat0", "k_hat0"} <= names and "b_hat0" not in names
    assert [p.size for p in observer.outputs if p.name == "theta_hat"] == [4]
    drem = parse_system(_bad('unknowns = "k"', 'unknowns = "k"\nestimator = "drem"\nextension_rate = 2'), "f.toml")
    definition = drem.components["observer"].definitions[0]
    parameters = {p.name: p for p in definition.parameters}
    assert definition.options["estimator"] == "drem" and "beta" not in parameters
    assert np.ravel(parameters["extension_rate"].value).tolist() == [2.0]
    assert "F_max" not in {p.name for p in definition.outputs}
    plant = system.components["plant"].definitions[0]
    assert plant.options["f"]["expressions"] == ["y**3"] and plant.options["f"]["arguments"] == [["y", 0]]


def test_the_cli_refuses_a_bad_observer_in_one_line_with_exit_2(tmp_path):
    (tmp_path / "bad.toml").write_text(BAD["A0 Jordan block"][0])
    done = subprocess.run([sys.executable, "-m", "obsfmu", "run", "--config", "bad.toml", "--build-dir", "fmus"],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "Jordan block" in done.stderr, done.stderr
    assert not list(tmp_path.glob("fmus/**/*.fmu"))


def test_a_varying_A_and_an_f_of_y_and_t_from_expressions_converge():
    """Block level (the kinds' factories, no FMU): ``A(t)``, ``L(t)`` varying with a constant ``A0``, ``f(y, t)``,
    least squares; ``x(0)`` and ``k`` to 1e-3 within 15 s, the flag never early."""
    from obsfmu.fmus.runtime.kinds import create_block
    from obsfmu.observers.block import Segment
    text = GOOD.replace("A = [[0, 1], [0, 0]]", 'A = [[0, 1], ["-0.5 * sin(t)", 0]]').replace(
        'f = "y**3"', 'f = "y**3 * (1 + 0.5 * cos(t))"').replace("L = [0, 9]", 'L = [0, "9 - 0.5 * sin(t)"]')
    text = text.replace('kind = "sine"', 'kind = "multisine"\namplitudes = [2, 1]\nfrequencies_hz = [0.1, 0.37]')
    system = parse_system(text, "f.toml")
    assert system.notes[0] == "components.observer: A0(t) = A(t) - L(t) C^T constant, uniformly stable"
    plant, observer = (create_block(d.kind, {p.name: p.array(p.value) for p in d.parameters}, d.options)
                       for d in (system.components[name].definitions[0] for name in ("plant", "observer")))
    assert plant.f_time and observer.f_time
    theta, h = np.array([-0.5, -0.3, -0.6, -4.0]), 1e-2
    force = system.components["force"].definitions[0]
    source = create_block(force.kind, {p.name: p.array(p.value) for p in force.parameters}, force.options)
    errors, flags = [], []
    for i in range(1500):
        t = i * h
        y0 = plant.outputs(t, {})["y"]
        u = Segment.between(source.outputs(t, {})["y"], source.outputs(t + h, {})["y"], h)
        plant.advance(t, h, {"u": u})
        observer.advance(t, h, {"u": u, "y": Segment.between(y0, plant.outputs(t + h, {})["y"], h)})
        out = observer.outputs(t + h, {})
        errors.append(np.linalg.norm(out["theta_hat"] - theta))
        flags.append(out["converged"][0])
    errors, flags = np.array(errors), np.array(flags)
    assert errors[-1] < 1e-3 and flags[-1] == 1 and np.all(errors[flags == 1] <= 1e-3)
