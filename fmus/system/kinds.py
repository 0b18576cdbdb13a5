"""Every component type of a system file, registered, and the field reference generated from them."""

from __future__ import annotations

from . import (gpebo_types, linear_types, ltv_types, signal_types, state_affine_types,  # noqa: F401  (register on import)
               uio_types, waveform_types)
from .schema import FIELD_TYPES, TYPES, ComponentType, Field

__all__ = ["component_type", "reference"]


def component_type(kind: str) -> ComponentType | None:
    """The registered type ``kind`` (None if unknown)."""
    return TYPES.get(kind)


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|")


def _default(f: Field) -> str:
    if f.required:
        return "**required**"
    if f.default is None or f.default == "":
        return "optional"
    return f"`{str(f.default).lower() if isinstance(f.default, bool) else f.default}`"


def _table(fields) -> list[str]:
    lines = ["| field | type | default | unit | meaning | example |", "|---|---|---|---|---|---|"]
    for f in fields:
        kind = f.type if not f.choices else "choice: " + ", ".join(f"`{c}`" for c in f.choices)
        example = f"`{f.example}`" if f.example else ""
        lines.append(f"| `{f.name}` | {_cell(kind)} | {_default(f)} | {_cell(f.unit)} | {_cell(f.doc)} | "
                     f"{_cell(example)} |")
    return lines


def reference(sections: dict[str, tuple[str, tuple[Field, ...]]]) -> str:
    """The field reference (markdown): the file's ``sections`` (title -> (doc, fields)), then every type."""
    lines = ["# System file: field reference", "",
             "Generated from the registry of component types (`fmus/system/schema.py`, `linear_types.py`, "
             "`signal_types.py`) by `obsfmu show --fields`; do not edit "
             "by hand (`tests/fmus/system/test_system_file.py` checks that this file is the generated one).", "",
             "Units: *(signal)* is the unit the component's `unit` field gives, *(time unit)* the file's "
             "`time_unit`.", "", "## Value types", ""]
    lines += [f"- **{name}**: {text}" for name, text in FIELD_TYPES.items()]
    for title, (doc, fields) in sections.items():
        lines += ["", f"## {title}", "", doc] + (["", *_table(fields)] if fields else [])
    lines += ["", "## Component types", "",
              "Every component is a table `[components.NAME]` with a `kind`; NAME is an identifier and "
              "its FMU is called `<name>_<NAME>`. Components step in the order of the file (Gauss-Seidel)."]
    for kind in sorted(TYPES):
        entry = TYPES[kind]
        lines += ["", f"### `{kind}`", "", entry.doc, ""] + _table(entry.fields)
    return "\n".join(lines) + "\n"
