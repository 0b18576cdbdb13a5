"""What a subcommand of ``obsfmu`` is: its name, help, arguments and handler."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Subcommand"]


@dataclass
class Subcommand:
    """``obsfmu NAME``: ``configure(parser)`` adds its arguments, ``handler(args)`` runs it (exit code)."""

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    handler: Callable[[argparse.Namespace], int]
    epilog: str | Callable[[], str] | None = None
