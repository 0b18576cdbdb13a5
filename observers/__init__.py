"""Observer algorithms in plain numpy -- no FMI.

Modules (one concept each):

* :mod:`observers.checks` -- validation and the two error types
* :mod:`observers.standard_forms` -- binomial / Butterworth characteristic polynomials
* :mod:`observers.modal` -- pole placement for ``K`` and ``N`` (paper 002)
* :mod:`observers.integrators` -- exact LTI steps for linear inputs, RK4
* :mod:`observers.block` -- the block interface the FMU adapter wraps
* :mod:`observers.luenberger` -- full-order observer (paper 002)
* :mod:`observers.feedback` -- state feedback ``u = -K x_hat + r``
* :mod:`observers.estimation` -- parameter estimators (gradient, LS, DREM, FT-DREM)
* :mod:`observers.ltv` -- adaptive observer of an LTV plant, LS with forgetting (paper 001)
* :mod:`observers.uio` -- unknown-input observer with FT-DREM stages (paper 003)
* :mod:`observers.gpebo` -- discrete GPEBO + DREM observer (paper 000)
* :mod:`observers.state_affine` -- DREM observer through a state-affine form (paper 004)
"""
