"""Figures of scenario results (matplotlib, no display needed): one convention for every scenario.

* Every y axis is labelled ``quantity [unit]`` with the unit the FMU declares for the plotted
  variable (``[-]``: none declared -- the academic examples are dimensionless); a panel whose
  curves have different units says so and puts each unit in the legend.  The x axis is time in
  the scenario's unit and ends where the data ends.
* Colour is the quantity (``Curve.key``: a state, its estimate and its error share it), the line
  style is the role: the true value is a wide pale line, the estimate a dashed line on top of it
  (both stay visible once they agree), a reference (e.g. a paper's table) black open circles, a
  tolerance a black dotted line.
* Legends sit outside the axes, right of the data.
* :func:`figure` writes the figure twice: as the file asked for and as vector graphics (SVG)
  beside a PNG, or a PNG beside an SVG/PDF.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Curve", "Panel", "figure", "draw", "unit_label", "companion_paths", "FORMATS"]

FORMATS = (".png", ".svg", ".pdf")
FLOOR = 1e-16  #: smallest magnitude drawn on a log axis

_STYLES = {
    "true": dict(linestyle="-", linewidth=3.2, alpha=0.35),
    "estimate": dict(linestyle="--", linewidth=1.4),
    "reference": dict(linestyle="none", marker="o", markersize=3.5, markerfacecolor="none", color="k",
                      markeredgewidth=0.8),
    "error": dict(linestyle="-", linewidth=1.2),
    "limit": dict(linestyle=":", linewidth=1.1, color="k"),
    "signal": dict(linestyle="-", linewidth=1.2),
}


@dataclass
class Curve:
    """One line of a panel.

    ``role``: ``"true"``, ``"estimate"``, ``"reference"``, ``"error"``, ``"limit"`` (a tolerance
    line; takes the panel's unit) or ``"signal"``.  ``key`` picks the colour of the quantity;
    ``marker`` draws the samples (discrete-time signals).
    """

    label: str
    time: np.ndarray
    values: np.ndarray
    unit: str = ""
    role: str = "signal"
    key: int = 0
    marker: str | None = None

    def __post_init__(self):
        if self.role not in _STYLES:
            raise ValueError(f"role: {self.role!r} is not one of {sorted(_STYLES)}")


@dataclass
class Panel:
    """One axes: ``quantity`` (the y label without its unit), its curves, linear or log scale."""

    quantity: str
    curves: list[Curve]
    log: bool = False
    note: str = ""  #: a short remark above the panel (e.g. "clipped to +-4")


def unit_label(unit: str) -> str:
    """How a unit is written in brackets: ``rad/s``; ``-`` for a dimensionless quantity."""
    return unit or "-"


def companion_paths(path: Path | str) -> list[Path]:
    """``F.png`` -> ``[F.png, F.svg]``; ``F.svg`` / ``F.pdf`` -> ``[F.svg, F.png]`` / ``[F.pdf, F.png]``."""
    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise ValueError(f"{path}: expected a file name ending in {', '.join(FORMATS)}")
    other = ".svg" if path.suffix.lower() == ".png" else ".png"
    return [path, path.with_suffix(other)]


def _draw(ax, panel: Panel) -> None:
    units = sorted({c.unit for c in panel.curves if c.role != "limit"})
    mixed = len(units) > 1
    for curve in panel.curves:
        style = dict(_STYLES[curve.role])
        style.setdefault("color", f"C{curve.key % 10}")
        if curve.marker:
            style.update(marker=curve.marker, markersize=4)
        values = np.asarray(curve.values, dtype=float)
        if panel.log:
            values = np.maximum(np.abs(values), FLOOR)
        label = f"{curve.label} [{unit_label(curve.unit)}]" if mixed and curve.role != "limit" else curve.label
        ax.plot(curve.time, values, label=label, **style)
    if panel.log:
        ax.set_yscale("log")
    ax.set_ylabel(f"{panel.quantity}\n(units in legend)" if mixed else
                  f"{panel.quantity} [{unit_label(units[0] if units else '')}]", fontsize=9)
    if panel.note:
        ax.set_title(panel.note, fontsize=8, loc="left")
    ax.grid(True, alpha=0.4)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, frameon=False)


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt
    return plt


def draw(title: str, panels: list[Panel], time_unit: str = "s"):
    """The matplotlib figure of ``panels``, one above the other over a shared time axis."""
    plt = _pyplot()
    spans = [(np.min(c.time), np.max(c.time)) for p in panels for c in p.curves
             if c.role not in ("reference", "limit") and len(c.time)]
    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.2 * len(panels) + 0.7), sharex=True, squeeze=False)
    for ax, panel in zip(axes[:, 0], panels):
        _draw(ax, panel)
    if spans:
        start, end = min(s for s, _ in spans), max(e for _, e in spans)
        axes[-1, 0].set_xlim(start, end if end > start else start + 1.0)
    axes[-1, 0].set_xlabel(f"time t [{time_unit}]")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return fig


def _save(fig, targets: list[Path]) -> None:
    from .output import replacing
    plt = _pyplot()
    try:
        for target in targets:
            fmt = target.suffix.lstrip(".").lower()
            with replacing(target) as temporary:
                fig.savefig(temporary, format=fmt, dpi=110, bbox_inches="tight",
                            metadata={"Date": None} if fmt == "svg" else None)
    finally:
        plt.close(fig)


def figure(path: Path | str, title: str, panels: list[Panel], time_unit: str = "s") -> list[Path]:
    """Draw ``panels`` (see :func:`draw`) and write ``path`` and its companion (:func:`companion_paths`).

    Returns the files written; each is written under a temporary name and renamed into place.
    """
    targets = companion_paths(path)
    with _pyplot().rc_context({"svg.fonttype": "none"}):
        _save(draw(title, panels, time_unit), targets)
    return targets
