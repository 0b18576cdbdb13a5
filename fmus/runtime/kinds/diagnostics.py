"""The diagnostics contract of every adaptive observer FMU (docs/estimation.md, "Diagnostics").

Every adaptive observer kind appends, after its own outputs, the same two outputs:

* ``excitation`` (real, >= 0): the family's own measure of how exciting the data have been;
* ``converged`` (0/1): 1 only when the estimator's own criterion guarantees, under the family's
  assumptions, that the parameter error is at most the FMU parameter ``converged_tolerance``.

A :class:`Contract` names, per family, what ``excitation`` is and the parameters its criterion
needs (``converged_tolerance`` first, with the family's default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..definition import Parameter, Port

__all__ = ["Contract", "LS_CONTRACT", "FT_DREM_CONTRACT", "UIO_CONTRACT", "GPEBO_CONTRACT",
           "contract_parameters", "contract_ports", "contract_values"]

_TOLERANCE = "converged = 1 once the guaranteed bound on the parameter error is at most this"
_THETA_BOUND = "a-priori bound on every unknown parameter, |theta_i| <= theta_bound (the criterion's assumption)"


@dataclass(frozen=True)
class Contract:
    """What ``excitation`` means for a family and the parameters of its ``converged`` criterion."""

    excitation: str                                 #: description of the excitation output
    converged: str                                  #: description of the converged output
    parameters: tuple[tuple[str, str], ...]         #: (name, description), converged_tolerance first


LS_CONTRACT = Contract(
    "lambda_min(P) / gamma, P = F^-1: smallest eigenvalue of the forgotten information matrix",
    "1 once f0 e^(-beta t) |Theta_tilde(0)| / lambda_min(P) + eps sqrt(gamma / (beta lambda_min(P))) "
    "<= converged_tolerance (guaranteed |Theta_hat - Theta|_2 bound), else 0",
    (("converged_tolerance", _TOLERANCE), ("theta_bound", _THETA_BOUND),
     ("regression_error_bound", "a-priori bound eps on the regression error |z - Psi Theta| (0: exact)")))

FT_DREM_CONTRACT = Contract(
    "|Delta| of the row-normalised extended regressor (0 <= Delta <= 1)",
    "1 once nu < mu (finite-time identification) and nu (|theta_hat(0)| + theta_bound) <= "
    "converged_tolerance (the DREM error bound), else 0",
    (("converged_tolerance", _TOLERANCE), ("theta_bound", _THETA_BOUND)))

UIO_CONTRACT = Contract(
    "smallest |Delta| of the FT-DREMs of the stages adapting now (started and not yet identified; "
    "once all are identified, of all)",
    "1 once every stage is identified and the bound on its error (stage 1: exact after the "
    "finite-time switch; stages 2-4: settle_tol (1 + |estimate|) / expm1(sigma settle_window)) "
    "is at most converged_tolerance, else 0",
    (("converged_tolerance", _TOLERANCE),
     ("decay_rate", "sigma: a lower bound on the exponential rate at which the errors of stages 2-4 "
                    "decay (the criterion's assumption; default: the slowest filter pole)")))

GPEBO_CONTRACT = Contract(
    "min(|Delta_sigma|, |Delta_eta|): the smaller |Delta| of the two normalised delay-extended regressors "
    "at the last sample (0 until the eta regression starts)",
    "1 once the Statement 2 bounds nu_gamma, nu_eta times (|initial estimate| + theta_bound) give "
    "|gamma_hat - gamma| and |eta_hat - eta| <= converged_tolerance, else 0",
    (("converged_tolerance", _TOLERANCE), ("theta_bound", _THETA_BOUND)))


def contract_parameters(contract: Contract, **values) -> list[Parameter]:
    """The contract's FMU parameters with the values given (every one of them)."""
    return [Parameter.of(name, np.array(values[name], dtype=float), text) for name, text in contract.parameters]


def contract_values(params, contract: Contract) -> list[float]:
    """The contract's parameter values from a block factory's ``params``, in the contract's order."""
    return [float(params[name]) for name, _ in contract.parameters]


def contract_ports(contract: Contract) -> list[Port]:
    """The two outputs, appended after the family's own."""
    return [Port("excitation", 1, contract.excitation, scalar=True),
            Port("converged", 1, contract.converged, scalar=True)]
