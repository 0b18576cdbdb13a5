"""Parameter estimation for linear regressions ``y = phi^T theta`` and ``Y = Phi theta``.

Estimators (each with ``update(y, phi, dt) -> theta_hat``, ``theta_hat``,
``reset(theta0)``):

* :class:`Gradient` -- continuous gradient;
* :class:`LeastSquaresForgetting` -- least squares with forgetting and a
  gain bound (paper 001);
* :class:`DREM` -- dynamic regressor extension and mixing;
* :class:`FiniteTimeDREM` -- DREM with finite-time convergence (papers 003, 004);
* :class:`DiscreteDREM` -- discrete DREM with delays (paper 000).

Reusable pieces for observers that build their own regressions:
extensions (:class:`KreisselmeierExtension`, :class:`FilterBankExtension`,
:class:`DelayExtension`), :func:`mix`, :func:`normalize_rows`, the scalar
laws :func:`scalar_gradient_step`, :func:`discrete_scalar_gradient_step`,
:func:`finite_time_estimate`, the matrix law :func:`gradient_flow_step`,
and the exact-step helpers :func:`phi1`, :func:`phi1_symmetric`,
:func:`held_input_lowpass`.  See ``docs/estimation.md``.
"""

from .discrete_drem import DiscreteDREM
from .drem import DREM, FiniteTimeDREM
from .exponential import held_input_lowpass, phi1, phi1_symmetric
from .extension import DelayExtension, FilterBankExtension, KreisselmeierExtension
from .gradient import Gradient, gradient_flow_step
from .least_squares import LeastSquaresForgetting
from .mixing import mix, normalize_rows
from .scalar_gradient import discrete_scalar_gradient_step, finite_time_estimate, scalar_gradient_step

__all__ = [
    "Gradient",
    "LeastSquaresForgetting",
    "DREM",
    "FiniteTimeDREM",
    "DiscreteDREM",
    "KreisselmeierExtension",
    "FilterBankExtension",
    "DelayExtension",
    "mix",
    "normalize_rows",
    "scalar_gradient_step",
    "discrete_scalar_gradient_step",
    "finite_time_estimate",
    "gradient_flow_step",
    "phi1",
    "phi1_symmetric",
    "held_input_lowpass",
]
