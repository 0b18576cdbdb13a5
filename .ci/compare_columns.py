"""Bit-for-bit check of `obsfmu all` against a baseline, column by column.

    python .ci/compare_columns.py BASELINE_DIR NEW_DIR

For every ``*.csv`` of ``BASELINE_DIR``: the file of the same name in ``NEW_DIR`` must have every
baseline column, in the same order relative to each other, with the same text in every row (the
values as written, so bit for bit); columns the new run adds are reported, not compared.  Every
``*.txt`` (the summaries) must be identical.  Exit status 0 when all agree, 1 otherwise.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path


def compare_csv(baseline: Path, new: Path) -> list[str]:
    """Differences of ``new`` from ``baseline`` on the baseline's columns (empty: identical)."""
    with baseline.open(newline="") as a, new.open(newline="") as b:
        old_rows, new_rows = list(csv.reader(a)), list(csv.reader(b))
    old_header, new_header = old_rows[0], new_rows[0]
    missing = [name for name in old_header if name not in new_header]
    if missing:
        return [f"{baseline.name}: columns missing: {missing}"]
    positions = [new_header.index(name) for name in old_header]
    if positions != sorted(positions):
        return [f"{baseline.name}: the baseline columns are not in their order"]
    if len(old_rows) != len(new_rows):
        return [f"{baseline.name}: {len(old_rows) - 1} rows in the baseline, {len(new_rows) - 1} now"]
    for number, (old, row) in enumerate(zip(old_rows[1:], new_rows[1:]), start=2):
        changed = [name for name, value, at in zip(old_header, old, positions) if row[at] != value]
        if changed:
            return [f"{baseline.name}: line {number} differs in {changed[:5]}"]
    added = [name for name in new_header if name not in old_header]
    if added:
        print(f"{baseline.name}: identical on the baseline's {len(old_header)} columns; added {added}")
    return []


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    baseline, new = (Path(a) for a in argv)
    problems = []
    for old in sorted(baseline.glob("*.csv")):
        current = new / old.name
        problems += compare_csv(old, current) if current.exists() else [f"{old.name}: not in {new}"]
    for old in sorted(baseline.glob("*.txt")):
        current = new / old.name
        if not current.exists() or current.read_bytes() != old.read_bytes():
            problems.append(f"{old.name}: differs or missing")
    for problem in problems:
        print(problem)
    if not problems:
        print("ALL BASELINE CSV COLUMNS AND TXT FILES BIT FOR BIT IDENTICAL")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
