"""What a run of a paper-004 scenario must reach, and what ``obsfmu sweep`` measures of one."""

from __future__ import annotations

from ...campaign.measures import Measure

TOLERANCE = 1e-4   #: acceptance: theta_hat and x_hat to 1e-4

MEASURE = Measure(("theta_time_to_1e-4", "x_time_to_1e-4"), ("final_theta_error", "final_x_error"),
                  f"time until |theta_hat - theta| and |x_hat - x| stay below {TOLERANCE:g}",
                  "final max(|theta_hat - theta|, |x_hat - x|)")
