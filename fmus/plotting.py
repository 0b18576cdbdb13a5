"""Figures of scenario results (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["Curve", "plot_panels"]

Curve = tuple  #: (label, time, values, matplotlib style string)


def plot_panels(path: Path | str, title: str, panels: list[tuple[str, list[Curve]]],
                xlabel: str = "time, s", log_panels: tuple[int, ...] = ()) -> None:
    """One figure, one panel per ``(panel title, curves)``, saved as PNG at ``path``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(panels), 1, figsize=(8, 2.6 * len(panels)), sharex=True, squeeze=False)
    for index, (ax, (panel_title, curves)) in enumerate(zip(axes[:, 0], panels)):
        for label, t, values, style in curves:
            if index in log_panels:
                ax.semilogy(t, np.maximum(np.abs(values), 1e-16), style, label=label)
            else:
                ax.plot(t, values, style, label=label)
        ax.set_title(panel_title, fontsize=10)
        ax.grid(True, alpha=0.4)
        ax.legend(fontsize=8, loc="best")
    axes[-1, 0].set_xlabel(xlabel)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
