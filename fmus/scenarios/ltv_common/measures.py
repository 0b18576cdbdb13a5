"""What a run of a paper-001 scenario must reach, and what ``obsfmu sweep`` measures of one."""

from __future__ import annotations

from ...campaign.measures import Measure

TOLERANCE = 1e-3  #: the acceptance level of the parameter and relative state errors

MEASURE = Measure(("parameter_convergence_time",), ("final_parameter_error",),
                  f"time until all 8 |theta_hat - theta| stay below {TOLERANCE:g}",
                  "final max |theta_hat - theta|")
