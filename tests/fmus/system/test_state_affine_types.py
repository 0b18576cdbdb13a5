"""The ``state-affine-observer`` component type (paper 004): every refusal names the field and the assumption.

Each case changes one line of a valid observer (the Van der Pol example's Statement-2 form, or a Statement-1
form) and checks the one-line message of :func:`fmus.system.load.parse_system`; nothing is built.  The CLI
refuses such a file with exit code 2.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from obsfmu.fmus.cli import main as cli
from obsfmu.fmus.system.load import parse_system
from obsfmu.observers.checks import ParameterError

STATEMENT2 = {
    "Lambda": "[[0, 1], [0, 0]]",
    "C": "[[1, 0]]",
    "poles": "[[0, 2], [0, -2]]",
    "Psi": '[["y - y**3/3", 0], [0, "-y"]]',
    "w": '[0, "u"]',
    "phi": "[1, 0]",
    "c": '"y"',
    "phi_L": '["chi[1]", "chi[2] + theta[1] * (chi[1] - chi[1]**3/3)"]',
    "rates": "[0.5, 2.0, 8.0, 32.0]",
    "gamma": "1e10",
    "gamma_x": "1e10",
}
STATEMENT1 = {     # the chemostat's form
    "constants": "{ mu_max = 0.5, K_S = 1.0, k = 2.0 }",
    "Lambda": '[["mu_max * y / (K_S + y) - u", 0], ["-k * mu_max * y / (K_S + y)", "-u"]]',
    "Psi": '[[0], ["u"]]',
    "phi": "[0, 1]",
    "c": '"y"',
    "rates": "[0.2, 1.0, 5.0]",
    "gamma": "1e7",
    "gamma_x": "1e7",
}


def _text(fields: dict) -> str:
    lines = [f"{key} = {value}" for key, value in fields.items() if value is not None]
    return "\n".join(['name = "t"', "[experiment]", "stop_time = 1.0", "step = 1e-3",
                      "[components.observer]", 'kind = "state-affine-observer"', *lines,
                      "[values]", '"observer.y" = 0.0', '"observer.u" = 0.0', ""])


def _refusal(base: dict, **changes) -> str:
    with pytest.raises(ParameterError) as caught:
        parse_system(_text({**base, **changes}), "t.toml")
    message = str(caught.value)
    assert "\n" not in message
    return message


@pytest.mark.parametrize("base", [STATEMENT2, STATEMENT1], ids=["statement2", "statement1"])
def test_the_valid_forms_are_accepted(base):
    spec = parse_system(_text(base), "t.toml")
    definition = spec.components["observer"].definitions[0]
    assert definition.kind == "state-affine-observer"
    assert {"Psi", "phi", "c", "phi_L"} <= set(definition.options)


def test_the_poles_give_the_injection_gain():
    definition = parse_system(_text(STATEMENT2), "t.toml").components["observer"].definitions[0]
    L = next(p for p in definition.parameters if p.name == "L")
    np.testing.assert_allclose(L.value, [0.0, 4.0], atol=1e-12)


SHAPES = [
    (STATEMENT2, {"Lambda": "[[0, 1, 0], [0, 0, 0]]"}, r"components\.observer\.Lambda: expected 2 x 2 \(q x q: square"),
    (STATEMENT2, {"Psi": '[["-y", 0]]'}, r"components\.observer\.Psi: expected 2 x 2 \(q x p: q = 2 rows"),
    (STATEMENT2, {"w": '[0, "u", 1]'}, r"components\.observer\.w: expected 2 \(q = 2 entries"),
    (STATEMENT2, {"phi": "[1]"}, r"components\.observer\.phi: expected l \+ q >= q = 2 entries"),
    (STATEMENT2, {"rates": "[0.5, 2.0]"}, r"components\.observer\.rates: expected 4 entries \(k = l \+ q \+ p"),
    (STATEMENT2, {"rates": "[0.5, 2.0, 2.0, 32.0]"}, r"components\.observer\.rates: expected distinct a_i > 0"),
    (STATEMENT2, {"chi_hat0": "[0, 0, 0]"}, r"components\.observer\.chi_hat0: expected 2 entries"),
    (STATEMENT2, {"theta_hat0": "[0]"}, r"components\.observer\.theta_hat0: expected 2 entries \(l \+ p"),
    (STATEMENT2, {"C": "[[1, 0, 0]]"}, r"components\.observer\.C: expected 1 x 2 \(ny x q"),
    (STATEMENT2, {"poles": None, "L": "[[0, 4]]"}, r"components\.observer\.L: expected 2 x 1 \(q x ny\)"),
    (STATEMENT2, {"poles": "[[0, 2]]"}, r"components\.observer\.poles: expected q = 2 eigenvalues"),
    (STATEMENT2, {"mu": "1.5"}, r"components\.observer\.mu: must lie in \(0, 1\)"),
]


@pytest.mark.parametrize("base, changes, pattern", SHAPES, ids=[next(iter(c)) + str(i) for i, (_, c, _) in
                                                                 enumerate(SHAPES)])
def test_dimensions_are_refused_naming_the_field(base, changes, pattern):
    assert re.search(pattern, _refusal(base, **changes))


ASSUMPTIONS = [
    # Statement 2
    ({"C": "[[0, 1]]"}, r"observer\.C: the pair \(Lambda, C\) is not observable; Statement 2 \(Assumption 6\)"),
    ({"poles": "[1, -2]"}, r"observer\.poles: Lambda - L C: eigenvalue 1 has a positive real part.*Assumption 4"),
    ({"poles": None, "L": "[[0], [0]]"}, r"observer\.L: Lambda - L C: eigenvalue 0 on the imaginary axis is repeated "
                                         r"with a Jordan block"),
    ({"poles": None}, r"observer\.L: give exactly one of L \(q x ny\) and poles"),
    ({"Lambda": '[[0, 1], [0, "-y"]]'}, r"observer\.Lambda: with C \(Statement 2\) Lambda must be a constant matrix"),
    # evaluation at the sample point
    ({"c": '"1 / (y - 0.5)"'}, r"observer\.c: (cannot be evaluated|not finite) at the sample point y = \[0\.5\]"),
    # identifiability
    ({"Psi": '[["y - y**3/3", 0], [0, 0]]'}, r"observer\.Psi: column 2 is zero at every sample point: theta_p\[2\] "
                                              r"never enters \(2\)"),
    ({"phi": "[0, 0]"}, r"observer\.phi: phi_chi .* is zero at every sample point: relation \(3\) says nothing about "
                        r"chi \(Assumption 2\)"),
    ({"Psi": '[["-y", "-2 * y"], [0, 0]]'}, r"observer\.Psi: the extended regressor \(6\) is singular along a generic "
                                            r"exciting \(y, u\) \(rank 5 < N = 6.*theta_p\[[12]\], theta_p\[[12]\] "
                                            r"cannot be identified"),
]


@pytest.mark.parametrize("changes, pattern", ASSUMPTIONS, ids=[f"{next(iter(c))}{i}" for i, (c, _) in
                                                               enumerate(ASSUMPTIONS)])
def test_statement2_assumptions_are_refused(changes, pattern):
    assert re.search(pattern, _refusal(STATEMENT2, **changes))


def test_statement1_unobservable_chi_is_refused():
    """chi_2 never reaches chi_1 = y (Lambda diagonal): chi[2](t) and chi[2](0) cannot be identified."""
    message = _refusal(STATEMENT1, Lambda='[[-1, 0], [0, "-u"]]', phi="[1, 0]")
    assert re.search(r"observer\.Lambda: the extended regressor \(6\) is singular .*chi\[2\]\(.\).*cannot be "
                     r"identified .*does not observe them", message), message


def test_statement1_takes_no_C():
    assert re.search(r"observer\.poles: only with C \(Statement 2", _refusal(STATEMENT1, poles="[-1, -2]"))


def test_theta_l_that_never_enters_is_refused():
    message = _refusal(STATEMENT1, phi="[0, 0, 1]", rates="[0.2, 1.0, 5.0, 9.0]")
    assert re.search(r"observer\.phi: entry 1 \(phi_l\[1\]\) is zero at every sample point: theta_l\[1\]", message)


@pytest.mark.parametrize("changes, pattern", [
    ({"Psi": '[["-y", "foo"], [0, "-y"]]'}, r"Psi.*foo"),
    ({"phi_L": '["chi[1]", "chi[3]"]'}, r"phi_L.*chi\[3\]"),
    ({"w": '[0, "x[1]"]'}, r"w.*x"),
])
def test_expressions_outside_the_arguments_are_refused(changes, pattern):
    message = _refusal(STATEMENT2, **changes)
    assert message.startswith("t.toml") and re.search(pattern, message), message


def test_the_cli_refuses_with_exit_2(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(_text({**STATEMENT2, "C": "[[0, 1]]"}))
    assert cli.main(["build", "--config", str(path), "--out", str(tmp_path / "build")]) == 2
    error = capsys.readouterr().err
    assert "the pair (Lambda, C) is not observable" in error and len(error.strip().splitlines()) == 1


@pytest.mark.parametrize("example", ["pendulum", "chemostat"])
def test_the_paper_files_write_the_papers_functions_bit_for_bit(example):
    """The scenarios' expressions give exactly the floats of plants.state_affine's functions (so the scenario
    CSVs stay bit for bit): 500 random points per function."""
    from pathlib import Path

    import obsfmu.plants.state_affine as paper
    from obsfmu.fmus.runtime.callables import resolve
    from obsfmu.fmus.system.load import load_system

    path = Path(__file__).resolve().parents[3] / "fmus" / "scenarios" / f"state_affine_{example}" / "system.toml"
    options = load_system(path).components["observer"].definitions[0].options
    rng = np.random.default_rng(4)
    names = [name for name in ("Lambda", "Psi", "w", "phi", "c", "phi_L") if name in options]
    assert len(names) == (6 if example == "chemostat" else 5)
    for name in names:
        mine, theirs = resolve(options[name], name), getattr(paper, f"{example}_{name}")
        for _ in range(500):
            size = 2 if name == "phi_L" else 1
            a, b = rng.normal(size=size) * 3, np.abs(rng.normal(size=size))
            assert np.array_equal(np.asarray(mine(a, b)), np.asarray(theirs(a, b))), (name, a, b)


def test_a_constant_named_as_an_argument_is_refused():
    assert re.search(r"observer\.constants: 'y' is the name of an argument", _refusal(STATEMENT2, constants="{ y = 1 }"))
