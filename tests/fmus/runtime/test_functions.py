"""Expression functions (fmus/runtime/functions.py): the user's A(t), f(y), Psi(y, u) as text in an FMU."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from obsfmu.fmus.runtime.callables import resolve
from obsfmu.fmus.runtime.functions import compiled, expression_function
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.expressions import ExpressionError


def test_a_matrix_of_time_equals_the_hand_written_function_bit_for_bit():
    from obsfmu.plants.ltv import A_paper
    A = resolve(expression_function([["2 - sin(t)", 1], ["-8 + cos(t)", 0]], [("t", 0)], (2, 2)), "A")
    for t in np.linspace(0.0, 20.0, 41):
        assert np.array_equal(A(t), A_paper(t))
        assert A(t).shape == (2, 2)


def test_arguments_take_their_own_names_scalars_bare_and_vectors_indexed():
    Psi = compiled(expression_function([["-y", 0], [0, "-sin(y[1]) * u[2]"]], [("y", 1), ("u", 2)], (2, 2)))
    value = Psi(np.array([0.3]), np.array([5.0, 2.0]))
    assert np.array_equal(value, [[-0.3, 0.0], [0.0, -math.sin(0.3) * 2.0]])
    f = compiled(expression_function("sin(y) + t", [("t", 0), ("y", 0)]))
    assert f(2.0, 0.5) == math.sin(0.5) + 2.0 and isinstance(f(2.0, 0.5), float)


def test_named_constants_are_read_as_given():
    mu = compiled(expression_function(["mu_max * y / (K_S + y)"], [("y", 0)], (1,),
                                      constants={"mu_max": 0.5, "K_S": 1.0}))
    assert mu(3.0)[0] == 0.5 * 3.0 / (1.0 + 3.0)


def test_the_option_is_plain_json_and_survives_a_round_trip():
    option = expression_function(["chi[1] - theta[1] * chi[2]", "chi[2]"],
                                 [("chi", 2), ("theta", 1)], (2,))
    again = compiled(json.loads(json.dumps(option)))
    assert np.array_equal(again([1.0, 2.0], [0.5]), [0.0, 2.0])


@pytest.mark.parametrize("texts, arguments, shape, message", [
    (["sin(z)"], [("y", 0)], (1,), "components.o.f[1] (line 1, column 5 of the expression): unknown name"),
    ([["1", "2"]], [("t", 0)], (2, 2), "components.o.f: expected 2 x 2 expressions (rows), got 1 x 2"),
    (["y[2]"], [("y", 1)], (1,), "index out of range: y has 1 entries"),
    (["x[1]"], [("y", 2)], (1,), "only y can be indexed"),
    (["__import__('os')"], [("y", 1)], (1,), "unknown function"),
    ([True], [("y", 1)], (1,), "expected expressions (texts) or numbers"),
    (["1"], [("y", 1), ("u", 1), ("w", 1)], (1,), "at most two vectors"),
])
def test_mistakes_are_refused_naming_the_field(texts, arguments, shape, message):
    with pytest.raises(ParameterError) as error:
        expression_function(texts, arguments, shape, field="components.o.f")
    assert message in str(error.value)


def test_a_constant_cannot_shadow_an_argument():
    with pytest.raises(ParameterError, match="the constant 'y' has the name of an argument"):
        expression_function(["y"], [("y", 0)], (1,), constants={"y": 1.0})


def test_a_malformed_option_is_an_error_not_a_crash():
    with pytest.raises(ParameterError, match="malformed expression function"):
        compiled({"expressions": ["1"], "arguments": "nonsense"}, "A")
    with pytest.raises(ParameterError, match="2 expressions for the shape"):
        compiled({"expressions": ["1", "2"], "shape": [3], "arguments": [], "constants": {}}, "A")
    with pytest.raises(ExpressionError):
        compiled({"expressions": ["eval('1')"], "shape": [1], "arguments": [], "constants": {}}, "A")
