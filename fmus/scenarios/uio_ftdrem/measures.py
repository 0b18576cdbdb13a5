"""What ``obsfmu sweep`` measures of a ``uio-ftdrem`` sample."""

from __future__ import annotations

from ...campaign.measures import Measure

MEASURE = Measure(("t_omega_1e-4", "t_xi0_1e-4", "t_f_1e-3", "t_x_1e-5"), ("f_error_last20",),
                  "time until omega_hat, xi0_hat stay within 1e-4, f_hat within 1e-3, x_hat within 1e-5 (relative)",
                  "max |f_hat - f| over the last 20 % of the run")
