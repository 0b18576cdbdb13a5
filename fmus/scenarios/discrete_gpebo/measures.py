"""What a run of ``discrete-gpebo`` must reach, and what ``obsfmu sweep`` measures of one."""

from __future__ import annotations

from ...campaign.measures import Measure

TOLERANCE = 1e-6  #: acceptance: gamma and x to 1e-6

MEASURE = Measure(("gamma_samples_to_tolerance", "state_samples_to_tolerance"), ("final_state_error",),
                  f"samples until |gamma_hat - gamma| and |x - x_hat| stay below {TOLERANCE:g}",
                  "final max |x - x_hat|", time_unit="samples")
