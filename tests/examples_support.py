"""What the worked-example tests (tests/examples/) share: running an example file through the CLI as a user
would, reading the CSV it writes, and when an error stays below a tolerance.

Nothing here imports the project: the tests compare the CLI's output with references of their own.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

__all__ = ["ROOT", "obsfmu", "run_config", "read_csv", "columns", "stays_below", "first_from_which", "flag_lag"]

ROOT = Path(__file__).resolve().parents[1]


def obsfmu(*args, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m obsfmu ARGS`` in ``cwd`` with this checkout first on the path."""
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "obsfmu", *map(str, args)], cwd=cwd, env=environment,
                          capture_output=True, text=True, timeout=900)


def run_config(example: Path, csv: Path, *options, cwd: Path = ROOT) -> tuple[dict[str, np.ndarray], str]:
    """``obsfmu run --config EXAMPLE --csv CSV OPTIONS``: the CSV's columns by name, and the printed summary."""
    done = obsfmu("run", "--config", example, "--csv", csv, *options, cwd=cwd)
    assert done.returncode == 0, done.stdout + done.stderr
    return read_csv(Path(cwd) / csv), done.stdout


def read_csv(path: Path) -> dict[str, np.ndarray]:
    """The columns of an ``obsfmu`` CSV by their names (``time``, ``plant.x[1]``, ...)."""
    header = path.read_text().split("\n", 1)[0].split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return {name: data[:, j] for j, name in enumerate(header)}


def columns(data: dict, name: str, size: int) -> np.ndarray:
    """The columns ``name[1] .. name[size]`` side by side."""
    return np.column_stack([data[f"{name}[{i}]"] for i in range(1, size + 1)])


def first_from_which(condition: np.ndarray) -> int:
    """First index from which ``condition`` holds to the end (len if never)."""
    bad = np.nonzero(~condition)[0]
    return 0 if bad.size == 0 else int(bad[-1]) + 1


def stays_below(time: np.ndarray, error: np.ndarray, tolerance: float) -> float:
    """The first time from which ``|error|`` (every column of it) stays below ``tolerance`` (inf: never)."""
    below = np.abs(error).reshape(time.size, -1).max(axis=1) < tolerance
    index = first_from_which(below)
    return float(time[index]) if index < time.size else float("inf")


def flag_lag(flag: np.ndarray, within: np.ndarray) -> int:
    """The ``converged`` contract per row: the flag comes, stays, and is never set where ``within`` (the true
    error within the tolerance) is false.  Returns the rows from the true convergence (``within`` for good) to
    the flag's first row."""
    assert flag.any() and flag[first_from_which(flag):].all()
    early = np.nonzero(flag & ~within)[0]
    assert early.size == 0, f"converged while the true error exceeds the tolerance at rows {early[:5].tolist()}"
    return int(np.argmax(flag)) - first_from_which(within)
