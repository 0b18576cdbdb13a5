"""A system written as TOML text: the subset a system file uses (tables, arrays of tables, numbers, texts,
booleans, lists), nothing else."""

from __future__ import annotations

import json
import math

import numpy as np

__all__ = ["dumps"]


def _value(value, where: str) -> str:
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{where}: {value} is not a finite number")
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)            # a TOML basic string: JSON's escapes are TOML's
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v, f"{where}[{i}]") for i, v in enumerate(value, start=1)) + "]"
    raise ValueError(f"{where}: {type(value).__name__} cannot be written to a system file")


def _key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() and key.isascii() else json.dumps(key)


def _table(lines: list, name: str, table: dict) -> None:
    scalars = {k: v for k, v in table.items() if not isinstance(v, dict) and not _is_tables(v)}
    if name and (scalars or not table):
        lines.append(f"\n[{name}]")
    lines.extend(f"{_key(k)} = {_value(v, f'{name}.{k}' if name else k)}" for k, v in scalars.items())
    for key, value in table.items():
        sub = f"{name}.{_key(key)}" if name else _key(key)
        if isinstance(value, dict):
            _table(lines, sub, value)
        elif _is_tables(value):
            for entry in value:
                lines.append(f"\n[[{sub}]]")
                lines.extend(f"{_key(k)} = {_value(v, f'{sub}.{k}')}" for k, v in entry.items())


def _is_tables(value) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def dumps(data: dict) -> str:
    """``data`` (nested dicts; a list of dicts is an array of tables) as TOML text."""
    lines: list[str] = []
    _table(lines, "", data)
    return "\n".join(lines) + "\n"
