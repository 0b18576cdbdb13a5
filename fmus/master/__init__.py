"""The co-simulation master (being split by concern)."""

from .session import *  # noqa: F401,F403
from .session import __all__  # noqa: F401
