"""Observers for plants of order 20 and 50 from a config (issue 14, target 6).

A sound design or a refusal that says why: the eigenvector placement reaches what Ackermann's
formula cannot (a 50-state modal plant), the closed loop is checked against the request, and the
n = 20 and n = 50 observers are built as FMUs and converge in a short co-simulation.
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.high_order import chain_config, input_system, modes_config
from obsfmu.fmus.builder import build_fmu
from obsfmu.fmus.config import design_from_config
from obsfmu.fmus.master import Component, System, cosimulate
from obsfmu.observers.checks import ParameterError
from obsfmu.observers.modal import POLE_ACCURACY, ackermann, controllable_dimension, pole_deviation, transient_growth


@pytest.mark.parametrize("n", [20, 50])
def test_the_binomial_form_of_high_order_is_refused_with_the_reason(n):
    """The issue's case: accepted before, then the observer diverged (8.6e11 after 2 s at n = 20)."""
    with pytest.raises(ParameterError, match=r"observer\.poles: the requested poles cannot be placed reliably "
                                             r"in double precision: .* off by [0-9.]+ \(relative; accepted: 0\.01\).*"
                                             rf"multiplicity {n}"):
        design_from_config(chain_config(n, {"t_settle": 2.0}))


def test_fast_distinct_poles_on_a_chain_are_refused_for_their_transient_growth():
    """Butterworth poles of radius 14 on a 20-chain: placed to 2e-8, but the gains are 8e22 and an
    initial error grows 8e20 times before it decays -- the estimate would be rounding noise."""
    with pytest.raises(ParameterError, match=r"observer\.poles: the designed closed loop amplifies an initial "
                                             r"error up to [0-9.e+]+ times"):
        design_from_config(chain_config(20, {"t_settle": 2.0, "form": "butterworth"}))


def test_the_eigenvector_placement_reaches_what_ackermann_cannot():
    design = design_from_config(modes_config(50))
    A, C, N = design.model.A, design.model.C, design.N
    poles = np.linalg.eigvals(A) - 3.0
    assert pole_deviation(A - N @ C, poles) < 1e-9                    # measured 1.5e-12
    assert transient_growth(A - N @ C) < 1e3                           # measured 1.3e2
    # the controllability matrix of (A^T, C^T) has condition ~1e30: the staircase is not fooled by it
    assert controllable_dimension(A.T, C.T) == 50
    with pytest.raises(ParameterError, match="not controllable"):      # Ackermann needs W_c^-1
        ackermann(A.T, C.T, poles)


def test_complex_poles_are_given_as_pairs_and_checked():
    config = modes_config(20, {"poles": [[-3.0 + lam.real, lam.imag] for lam in
                                         np.linalg.eigvals(np.array(modes_config(20)["plant"]["A"]))]})
    design = design_from_config(config)
    assert pole_deviation(design.model.A - design.N @ design.model.C, design.observer_poles) < POLE_ACCURACY
    with pytest.raises(ParameterError, match=r"observer\.poles\[2\]: expected a number or an \[re, im\] pair"):
        design_from_config(modes_config(20, {"poles": [-1.0, [1.0, 2.0, 3.0]] + [-1.0] * 18}))
    with pytest.raises(ParameterError, match=r"observer\.poles: complex poles must come in conjugate pairs"):
        design_from_config(modes_config(20, {"poles": [[-1.0, 2.0]] + [-1.0] * 19}))


@pytest.mark.parametrize("n", [20, 50])
def test_observers_of_order_20_and_50_converge_through_fmus(n, tmp_path_factory):
    """Plant, observer and input FMUs built from the config; 5 s at h = 1e-3 (exact LTI steps).

    The error first grows (up to 9x at n = 20, 37x at n = 50: the transient growth of the
    closed loop bounds it), then decays like e^(-3 t) to the coupling floor (y interpolated linearly across each step).
    """
    design = design_from_config(modes_config(n))
    definitions, components, connections = input_system(design)
    build = tmp_path_factory.mktemp(f"modes{n}")
    paths = {d.model_name: build_fmu(d, build) for d in definitions}
    result = cosimulate(System([Component(i, paths[m], s) for i, m, s in components], connections), 5.0, 1e-3)
    error = np.abs(result.vector("plant.x") - result.vector("observer.x_hat")).max(axis=1)
    assert np.all(np.isfinite(result.values))
    assert error[0] == pytest.approx(np.abs(design.x0).max())          # x_hat(0) = 0
    bound = transient_growth(design.model.A - design.N @ design.model.C) * np.linalg.norm(design.x0)
    assert error.max() <= bound                                          # |e(t)| <= max|exp(H t)| |e(0)|
    late = result.time >= 4.0
    assert error[late].max() < 1e-3 * error[0]                          # measured 1.7e-4 and 1.6e-4
