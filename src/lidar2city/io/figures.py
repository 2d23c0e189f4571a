"""Check images (PNG): a fitted model's wire frame superimposed on its points.

matplotlib is optional (``pip install lidar2city[plot]``); it is imported
only when an image is written, with the non-interactive Agg backend.
:func:`figure_class` is the one entry to matplotlib for every PNG writer of
:mod:`lidar2city.io`.
"""

from __future__ import annotations

import numpy as np

from ..errors import DependencyError
from ._atomic import atomic_path

__all__ = ["write_check_image", "solid_edges", "figure_class"]


def solid_edges(solid) -> np.ndarray:
    """Unique undirected edges of a solid's faces, shape (E, 2) of vertex indices."""
    pairs = []
    for s in solid.surfaces:
        for ring in s.rings:
            r = np.asarray(ring, dtype=np.int64)
            pairs.append(np.column_stack([r, np.roll(r, -1)]))
    if not pairs:
        return np.empty((0, 2), dtype=np.int64)
    e = np.sort(np.vstack(pairs), axis=1)
    return np.unique(e, axis=0)


def figure_class():
    """matplotlib's ``Figure`` class, or :class:`~lidar2city.errors.DependencyError`.

    A bare Figure renders with the Agg canvas when saved as PNG: no pyplot, no
    GUI backend and no global state.
    """
    try:
        import matplotlib
    except ImportError:
        raise DependencyError("check images need matplotlib: install lidar2city[plot]") from None
    del matplotlib
    from matplotlib.figure import Figure

    return Figure


def write_check_image(path, points, solid, *, footprint=None, title: str = "", ortho=None,
                      dpi: int = 100) -> None:
    """Write a PNG with the plan view (points coloured by height) and a side view.

    Parameters
    ----------
    path : str or Path
        Output PNG.
    points : ndarray, shape (N, 3)
        Points around the building (local metres).
    solid : Solid
        The fitted model; its edges are drawn in both views.
    footprint : shapely Polygon, optional
        Drawn dashed in the plan view.
    title : str
    ortho : (ndarray (H, W[, C]), extent), optional
        An orthoimage cut-out and its (xmin, xmax, ymin, ymax) in local
        metres, drawn under the plan view.
    """
    Figure = figure_class()
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    v = solid.vertices
    edges = solid_edges(solid)
    fig = Figure(figsize=(15, 5), dpi=dpi)
    ax1 = fig.add_subplot(1, 3, 1)
    if ortho is not None:
        img, extent = ortho
        img = np.asarray(img)
        if img.dtype.kind == "f" or img.max() > 255:
            mx = np.nanmax(img) or 1.0
            img = np.clip(img / mx, 0, 1)
        ax1.imshow(img, extent=extent, origin="upper", zorder=0)
    if len(points):
        sc = ax1.scatter(points[:, 0], points[:, 1], c=points[:, 2], s=2, cmap="viridis",
                         zorder=1, alpha=0.4 if ortho is not None else 1.0)
        fig.colorbar(sc, ax=ax1, label="height (m)", shrink=0.8)
    for a, b in edges:
        ax1.plot(v[[a, b], 0], v[[a, b], 1], color="red", lw=1.2, zorder=3)
    if footprint is not None and not footprint.is_empty:
        for g in getattr(footprint, "geoms", [footprint]):
            xy = np.asarray(g.exterior.coords)
            ax1.plot(xy[:, 0], xy[:, 1], "k--", lw=0.8, zorder=2)
    ax1.set_aspect("equal")
    ax1.set_xlabel("x (m)")
    ax1.set_ylabel("y (m)")
    ax1.set_title("plan (model red, footprint dashed)")
    # side views along and across the main horizontal axis of the model; only the
    # points over the model (1 m margin), coloured by their depth in the view
    c = v[:, :2].mean(axis=0)
    cov = np.cov((v[:, :2] - c).T) if len(v) > 2 else np.eye(2)
    w, vec = np.linalg.eigh(cov)
    d = vec[:, np.argmax(w)]
    n = np.array([-d[1], d[0]])
    vu, vv = (v[:, :2] - c) @ d, (v[:, :2] - c) @ n
    rel = points[:, :2] - c if len(points) else np.empty((0, 2))
    pu, pv = rel @ d, rel @ n
    over = ((pu >= vu.min() - 1) & (pu <= vu.max() + 1) & (pv >= vv.min() - 1) & (pv <= vv.max() + 1))
    for k, (ax_h, ax_depth, vh, name) in enumerate(((pu, pv, vu, "along"), (pv, pu, vv, "across"))):
        ax = fig.add_subplot(1, 3, 2 + k)
        if over.any():
            ax.scatter(ax_h[over], points[over, 2], c=ax_depth[over], s=2, cmap="coolwarm")
        for a, b in edges:
            ax.plot(vh[[a, b]], v[[a, b], 2], color="red", lw=1.2)
        ax.set_aspect("equal")
        ax.set_xlabel(f"{name} the main axis (m)")
        ax.set_ylabel("z (m)")
        ax.set_title(f"view {name} the main axis")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
