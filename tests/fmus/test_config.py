"""TOML designs: the ship design of paper 002, a user's own plant, and every way a config can be wrong."""

import textwrap

import numpy as np
import pytest

from obsfmu.fmus.config import design_from_config, load_config
from obsfmu.observers.checks import ParameterError

SHIP = {
    "name": "ship",
    "plant": {"A": [[0, 1], [-2, 3]], "B": [[0], [1]], "C": [[1, 0]], "x0": [0.05, 0.2]},
    "observer": {"t_settle": 0.15},
    "controller": {"t_settle": 0.3},
}


def with_changes(section, **fields):
    config = {key: (dict(value) if isinstance(value, dict) else value) for key, value in SHIP.items()}
    target = config if section is None else config[section]
    for key, value in fields.items():
        if value is None:
            target.pop(key, None)
        else:
            target[key] = value
    return config


def test_the_ship_design_gives_the_paper_gains():
    design = design_from_config(SHIP)
    assert np.max(np.abs(design.K - [[398, 43]])) < 1e-9
    assert np.max(np.abs(design.N - [[83], [1847]])) < 1e-9
    assert [d.model_name for d in design.definitions()] == ["ship_observer", "ship_plant", "ship_controller"]


@pytest.mark.parametrize("section, fields, message", [
    ("plant", {"A": [[0, 1, 2], [3, 4, 5]]}, r"plant\.A: expected a square matrix"),
    ("plant", {"B": [[0], [1], [2]]}, r"plant\.B: expected 2 rows"),
    ("plant", {"C": [[1, 0, 0]]}, r"plant\.C: expected 2 columns"),
    ("plant", {"D": [[1, 2]]}, r"plant\.D: expected 1 columns"),
    ("plant", {"C": [[0, 0]]}, r"plant\.C: the pair \(plant\.A, plant\.C\) is not observable"),
    ("plant", {"A": [[0, 1], [float("nan"), 3]]}, r"plant\.A: entry \(2, 1\) is not finite"),
    ("plant", {"B": [[0], [float("inf")]]}, r"plant\.B: entry \(2, 1\) is not finite"),
    ("plant", {"x0": [1, 2, 3]}, r"plant\.x0: expected 2 entries"),
    ("plant", {"A": None}, r"plant\.A: missing"),
    ("plant", {"colour": "red"}, r"plant\.colour: unknown field"),
    ("plant", {"state_units": ["rad"]}, r"plant\.state_units: expected 2 unit strings"),
    ("observer", {"poles": [-1, -2], "t_settle": None}, None),
    ("observer", {"poles": [-1, 2], "t_settle": None}, r"observer\.N \(A - N C\): not Hurwitz"),
    ("observer", {"poles": [-1], "t_settle": None}, r"observer\.poles: expected 2 poles"),
    ("observer", {"poles": [-1, -2]}, r"observer: give exactly one of"),
    ("observer", {"form": "bessel"}, r"observer\.form: unknown standard form"),
    ("observer", {"t_settle": -1.0}, r"observer\.t_settle: must be > 0"),
    ("observer", {"N": [[1], [2]], "t_settle": None}, r"observer\.N \(A - N C\): not Hurwitz"),
    ("controller", {"K": [[1, 2, 3]], "t_settle": None}, r"controller\.K: expected 2 columns"),
    ("plant", {"B": [[1], [0]], "A": [[1, 0], [0, 2]], "C": [[1, 1]]}, r"plant\.B: the pair \(plant\.A, plant\.B\) is not controllable"),
    (None, {"name": "3ship"}, r"name: expected an identifier"),
    (None, {"observer": None}, r"observer: missing section"),
])
def test_bad_config_fails_naming_the_field(section, fields, message):
    config = with_changes(section, **fields)
    if message is None:
        design_from_config(config)  # the valid variant of the same edit
        return
    with pytest.raises(ParameterError, match=message):
        design_from_config(config)


def test_toml_syntax_error_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("name = 'x'\n[plant\nA = 1\n")
    with pytest.raises(ParameterError, match="broken.toml"):
        load_config(path)


def test_toml_nan_literal_is_refused(tmp_path):
    path = tmp_path / "nan.toml"
    path.write_text(textwrap.dedent("""
        name = "p"
        [plant]
        A = [[0, 1], [-2, nan]]
        C = [[1, 0]]
        [observer]
        t_settle = 1.0
    """))
    with pytest.raises(ParameterError, match=r"plant\.A: entry \(2, 2\) is not finite"):
        design_from_config(load_config(path))


@pytest.mark.parametrize("plant_entry, observer_entry, key", [
    ("A = [[0, 1], [-2, {big}]]", "t_settle = 0.15", "plant.A[2][2]"),
    ("A = [[0, 1], [-2, 3]]", "t_settle = {big}", "observer.t_settle"),
    ("A = [[0, 1], [-2, 3]]", "poles = [-1, -{big}]", "observer.poles[2]"),
])
def test_a_401_digit_integer_in_a_design_file_is_one_line_naming_its_key(tmp_path, plant_entry, observer_entry, key):
    """Issue 37.6: an integer beyond a float in a design file ended in an OverflowError traceback."""
    big = "1" * 401
    path = tmp_path / "design.toml"
    path.write_text(f'name = "inj"\n[plant]\n{plant_entry.format(big=big)}\nB = [[0], [1]]\nC = [[1, 0]]\n'
                    f'[observer]\n{observer_entry.format(big=big)}\n')
    with pytest.raises(ParameterError) as refused:
        load_config(path)
    assert str(refused.value) == (f"config {path}: {key}: an integer of 401 digits is beyond the range of a float "
                                  f"(about 1.8e308)")
