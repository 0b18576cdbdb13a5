"""What is simulated: FMU instances (:class:`Component`) and the connections between them."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Component", "Connection", "System"]


@dataclass
class Component:
    """One FMU instance: ``name`` (e.g. ``"plant"``), the ``.fmu`` file and start values."""

    name: str
    fmu: Path
    start: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Connection:
    """``source`` output -> ``target`` input, each ``"instance.variable"``."""

    source: str
    target: str


@dataclass
class System:
    components: list[Component]
    connections: list[Connection]
