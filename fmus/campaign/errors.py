"""The campaign's error type: a bad study description, reported before anything runs."""

from __future__ import annotations

from ..master import SimulationError

__all__ = ["CampaignError"]


class CampaignError(SimulationError):
    """A campaign cannot run as described (the message names the option or variable)."""
