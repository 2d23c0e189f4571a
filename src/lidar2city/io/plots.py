"""Figures written as PNG files (matplotlib, Agg canvas, imported lazily)."""

from __future__ import annotations

import numpy as np

from ._atomic import atomic_path
from .figures import figure_class

__all__ = ["SHAPE_COLOURS", "plot_outlines"]

#: colour per outline shape type
SHAPE_COLOURS = {
    "rectangle": "#e41a1c",
    "right_trapezoid": "#ff7f00",
    "trapezoid": "#ffff33",
    "composite": "#4daf4a",
    "polygon": "#377eb8",
    "pixels": "#984ea3",
}


def plot_outlines(path, ndsm, extent, polygons, shape_types, *, title="", vmax=None, dpi=120):
    """Outlines over a normalised DSM, coloured by shape type, saved as PNG.

    Parameters
    ----------
    ndsm : ndarray, shape (H, W)
        Background heights (m); NaN drawn blank.
    extent : (left, right, bottom, top)
        World coordinates of the raster's edges.
    polygons : sequence of shapely Polygon / MultiPolygon
        In the same world coordinates.
    shape_types : sequence of str
        One per polygon (keys of :data:`SHAPE_COLOURS`).
    """
    import shapely

    Figure = figure_class()
    from matplotlib.lines import Line2D

    h, w = np.asarray(ndsm).shape
    fig = Figure(figsize=(7.0, max(3.0, 7.0 * h / max(w, 1))))
    ax = fig.add_subplot(1, 1, 1)
    finite = np.asarray(ndsm)[np.isfinite(ndsm)]
    top = vmax if vmax is not None else (float(np.percentile(finite, 99)) if finite.size else 1.0)
    im = ax.imshow(ndsm, extent=extent, cmap="gray", vmin=0.0, vmax=max(top, 1e-6),
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, label="nDSM (m)", shrink=0.6)
    used = set()
    for g, kind in zip(polygons, shape_types, strict=True):
        if g is None or g.is_empty:
            continue
        colour = SHAPE_COLOURS.get(kind, "#ffffff")
        used.add(kind)
        for ring in shapely.get_rings(shapely.get_parts(g)):
            c = np.asarray(ring.coords)
            ax.plot(c[:, 0], c[:, 1], "-", color=colour, lw=1.2)
    handles = [Line2D([], [], color=SHAPE_COLOURS.get(k, "#ffffff"), lw=2, label=k.replace("_", " "))
               for k in SHAPE_COLOURS if k in used]
    if handles:
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    ax.set_title(title or "building outlines by shape type")
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.tick_params(labelsize=6)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
