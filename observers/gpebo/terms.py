"""The terms of paper 000's input-output form (8), shared by the determinant regressions."""

from __future__ import annotations

import numpy as np

from obsfmu.observers.checks import ParameterError

from .model import GeneratorModel

__all__ = ["GENERATORS", "MAPS", "io_terms"]

GENERATORS = ("gamma_beta", "gamma_theta", "gamma_delta")
MAPS = ("h_beta", "H_theta", "H_delta")     #: the fields that give each generator's size and output map


def io_terms(model: GeneratorModel, max_terms: int) -> list[tuple[int, object, int]]:
    r"""The terms of the input-output form (8), ``y(k+n) = sum_t s_t(k + o_t) w_t(k + o_t)``.

    Each is ``(generator index, signal: "u" | i of f_i | "1", offset o_t)``: ``beta u`` at 0, each
    nonzero row ``i`` of ``H_theta`` at ``n - 1 - i``, all of ``delta`` merged into one term ``1``.
    Refused (naming the field) if a generator reaches no term or there are more than ``max_terms``.
    """
    n = model.n
    terms = [(0, "u", 0)] if np.any(model.h_beta) else []
    terms += [(1, i, n - 1 - i) for i in range(n) if np.any(model.H_theta[i])]
    if np.any(model.H_delta):
        terms.append((2, "1", 0))
    reached = {generator for generator, _, _ in terms}
    for v, size in enumerate(model.sizes):
        if size and v not in reached:
            raise ParameterError(f"{MAPS[v]}: is zero, so the {GENERATORS[v][6:]} generator does not "
                                 f"reach the output: {GENERATORS[v]} is not identifiable")
    if len(terms) > max_terms:
        raise ParameterError(f"H_theta: the input-output form has {len(terms)} terms (beta, each nonzero row of "
                             f"H_theta, delta); the determinant regression takes at most {max_terms}")
    return terms
