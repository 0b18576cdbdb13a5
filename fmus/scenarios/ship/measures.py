"""What ``obsfmu sweep`` measures of a ``ship`` sample."""

from __future__ import annotations

from ...campaign.measures import Measure

MEASURE = Measure(("observer_convergence_time",), ("final_error_x1", "final_error_x2"),
                  "time until |x - x_hat| stays below 5 % of its peak", "final max |x - x_hat|")
