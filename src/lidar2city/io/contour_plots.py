"""Figures of the active contours and the genetic algorithm (matplotlib, Agg canvas)."""

from __future__ import annotations

import numpy as np

from ._atomic import atomic_path
from .figures import figure_class

__all__ = ["plot_contour_evolution", "plot_ga_history"]


def plot_contour_evolution(path, image, snapshots, *, reference=None, title=None, dpi=120) -> None:
    """PNG of one building's contour at several iterations over the DSM.

    Parameters
    ----------
    image : ndarray, shape (h, w)
        Background (the DSM window around the building).
    snapshots : list of (int, ndarray (M, 2))
        ``(iteration, (row, col) contour)`` in the window's pixel coordinates.
    reference : list of ndarray (K, 2), optional
        Reference outlines in the same coordinates.
    """
    fig = figure_class()(figsize=(6, 6))
    from matplotlib import colormaps

    ax = fig.add_subplot(1, 1, 1)
    ax.imshow(image, cmap="gray", interpolation="nearest")
    colors = colormaps["viridis"](np.linspace(0, 1, max(len(snapshots), 2)))
    for (it, c), col in zip(snapshots, colors, strict=False):
        c = np.vstack([c, c[:1]])
        ax.plot(c[:, 1], c[:, 0], "-", color=col, lw=1.2, label=f"iteration {it}")
    for k, r in enumerate(reference or []):
        r = np.vstack([r, r[:1]])
        ax.plot(r[:, 1], r[:, 0], "--", color="red", lw=1.5, label="reference" if k == 0 else None)
    ax.set_title(title or "active contour evolution")
    ax.legend(fontsize=7, loc="upper right")
    ax.set_axis_off()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")


def plot_ga_history(path, history, *, title=None, dpi=120) -> None:
    """PNG of the GA's best-so-far, population minimum and mean cost per generation."""
    gen = [r["generation"] for r in history]
    fig = figure_class()(figsize=(6, 4))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(gen, [r["best_cost"] for r in history], "o-", label="best so far")
    ax.plot(gen, [r["min"] for r in history], ".--", label="population min")
    ax.plot(gen, [r["mean"] for r in history], ".:", label="population mean")
    ax.set_xlabel("generation")
    ax.set_ylabel("cost (FP + FN) / N")
    ax.set_title(title or "genetic algorithm")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
