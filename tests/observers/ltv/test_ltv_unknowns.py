"""Paper 001's observer with any subset of k, b, m unknown (issue 27, item 1): no dummy unknowns."""

import math

import numpy as np
import pytest

from obsfmu.observers.block import Segment
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.ltv import LTVAdaptiveObserver
from obsfmu.plants.ltv import A_paper, L_paper, OutputNonlinearLTVPlant, f_sin

C = [1.0, 0.0]
CASE = {"k": [-3.0, 1.0], "b": [0.5, -1.0], "m": [-2.0, 3.0], "x0": [2.0, -1.0]}   # scenario ltv-ls-bounded
STEPPING = {"input_degree": 4, "max_substep": 5e-3}


def run(unknowns, T=20.0, h=1e-2):
    """Plant then observer, u = sin t; the known parameters given their true values."""
    known = {name: CASE[name] for name in ("k", "b", "m") if name not in unknowns}
    p = OutputNonlinearLTVPlant(A_paper, C, f_sin, CASE["k"], CASE["b"], CASE["m"], CASE["x0"])
    o = LTVAdaptiveObserver(A_paper, C, L_paper, f_sin, unknowns=unknowns, theta_bound=5.0, **known, **STEPPING)
    truth = np.concatenate([-np.array(CASE["x0"])] + [CASE[name] for name in ("k", "b", "m") if name in unknowns])
    errors, flags = [], []
    for i in range(int(round(T / h))):
        t = i * h
        y0 = p.outputs(t, {})["y"]
        u = Segment.between([math.sin(t)], [math.sin(t + h)], h)
        p.advance(t, h, {"u": u})
        o.advance(t, h, {"u": u, "y": Segment.between(y0, p.outputs(t + h, {})["y"], h)})
        out = o.outputs(t + h, {})
        errors.append(np.max(np.abs(out["theta_hat"] - truth)))
        flags.append(out["converged"][0])
    return o, out, np.array(errors), np.array(flags)


@pytest.mark.parametrize("unknowns", [("k", "m"), ("b",), ()])
def test_a_subset_of_unknowns_is_estimated_without_dummies(unknowns):
    o, out, errors, flags = run(unknowns)
    n = 2
    assert out["theta_hat"].size == n * (1 + len(unknowns)) == o.estimator.p
    assert errors[-1] < 1e-4                                       # measured 1.8e-5 (k, m), 1.3e-6
    for name in ("k", "b", "m"):
        if name not in unknowns:
            assert out[f"{name}_hat"].tolist() == CASE[name]          # the known values, exactly
    assert flags[-1] == 1.0 and np.all(errors[flags > 0.5] <= 1e-3)   # the contract holds here too


def test_fewer_unknowns_converge_sooner():
    times = {}
    for unknowns in [("k", "b", "m"), ("k", "m"), ()]:
        _, _, errors, _ = run(unknowns)
        below = np.nonzero(errors >= 1e-3)[0]
        times[unknowns] = 0 if below.size == 0 else below[-1] + 1
    assert times[()] < times[("k", "m")] < times[("k", "b", "m")]


@pytest.mark.parametrize("options, field", [
    ({"unknowns": ("k", "q")}, "unknowns"),
    ({"unknowns": ("k", "k")}, "unknowns"),
    ({"unknowns": ("k", "m")}, "b"),                                   # b known but no value
    ({"unknowns": ("k", "b", "m"), "b": [1.0, 0.0]}, "b"),            # b unknown but given
    ({"unknowns": ("k", "b"), "m": [1.0]}, "m"),                      # wrong length
    ({"unknowns": ("k", "b"), "m": [1.0, 0.0], "m_hat0": [0.0, 0.0]}, "m_hat0"),
])
def test_mistakes_name_the_field(options, field):
    with pytest.raises(ParameterError, match=f"^{field}"):
        LTVAdaptiveObserver(A_paper, C, L_paper, f_sin, **options)


def test_an_unobservable_pair_is_refused_naming_C():
    with pytest.raises(ParameterError, match="^C: .*not observable"):
        LTVAdaptiveObserver(lambda t: np.array([[-1.0, 0.0], [0.0, -2.0]]), C, lambda t: np.zeros(2), f_sin)


def test_the_kind_takes_the_unknowns_as_an_option_and_the_known_values_as_parameters():
    from obsfmu.fmus.runtime.kinds.ltv import ltv_observer_definition
    definition = ltv_observer_definition("o", A_paper, C, L_paper, f_sin, unknowns=("k", "m"),
                                         known={"b": CASE["b"]})
    names = [p.name for p in definition.parameters]
    assert definition.options["unknowns"] == "k,m" and "b" in names and "b_hat0" not in names
    assert {o.name: o.size for o in definition.outputs}["theta_hat"] == 6
    with pytest.raises(ParameterError, match="^b: "):
        ltv_observer_definition("o", A_paper, C, L_paper, f_sin, unknowns=("k", "m"))
    with pytest.raises(ParameterError, match="^b_hat0: "):
        ltv_observer_definition("o", A_paper, C, L_paper, f_sin, unknowns=("k", "m"), known={"b": CASE["b"]},
                                b_hat0=[0.0, 0.0])
