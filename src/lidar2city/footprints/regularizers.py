"""Footprint outline regularisers: a name -> function dict (``REGULARIZERS``).

Every regulariser takes a simplified polygon (local metres) and keyword
options and returns ``(polygon, info)`` where ``info`` holds ``direction``
(degrees, the building's dominant direction modulo 90), ``n_vertices``,
``reductions`` (dict of the snake's type "I".."IV" operation counts; zeros
when no snake ran) and ``mean_deviation`` (m, mean distance of the output
vertices from the input outline).
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import DependencyError

logger = logging.getLogger(__name__)

__all__ = ["REGULARIZERS", "regularize_none", "regularize_snake", "outline_direction",
           "vertex_count", "mean_deviation", "require"]


def outline_direction(polygon) -> float:
    """Dominant direction (degrees in [0, 90)) of a polygon's edges, modulo 90 degrees.

    The length-weighted circular mean of the edge angles taken four times
    (angles modulo 90 degrees map to one direction), as a light estimate for
    outlines that are not regularised.
    """
    import shapely

    total = np.zeros(2)
    for ring in shapely.get_rings(polygon):
        c = np.asarray(ring.coords)[:, :2]
        d = np.diff(c, axis=0)
        length = np.hypot(d[:, 0], d[:, 1])
        ang = 4.0 * np.arctan2(d[:, 1], d[:, 0])
        total += np.array([(length * np.cos(ang)).sum(), (length * np.sin(ang)).sum()])
    if not total.any():
        return 0.0
    return float(np.mod(np.degrees(np.arctan2(total[1], total[0])) / 4.0, 90.0))


def vertex_count(polygon) -> int:
    """Number of distinct vertices over all rings (closing vertices not counted)."""
    import shapely

    return int(sum(len(r.coords) - 1 for r in shapely.get_rings(polygon)))


def mean_deviation(polygon, reference) -> float:
    """Mean distance (m) from the vertices of ``polygon`` to the boundary of ``reference``."""
    import shapely

    pts = shapely.points(shapely.get_coordinates(polygon))
    if not len(pts):
        return 0.0
    return float(np.mean(shapely.distance(pts, reference.boundary)))


def regularize_none(polygon, **_ignored):
    """No regularisation: the polygon as it is, with its descriptive ``info``."""
    return polygon, {
        "direction": outline_direction(polygon),
        "n_vertices": vertex_count(polygon),
        "reductions": {"I": 0, "II": 0, "III": 0, "IV": 0},
        "mean_deviation": 0.0,
    }


def _snake():
    try:
        from ..regularize.snake import regularize_polygon
    except ImportError as exc:
        raise DependencyError(
            "the snake regulariser (lidar2city.regularize.snake) is not available in this "
            f"installation ({exc}); use --regularize none") from None
    return regularize_polygon


def require(name: str) -> None:
    """Raise :class:`~lidar2city.errors.DependencyError` if regulariser ``name`` cannot run."""
    if name == "snake":
        _snake()


def regularize_snake(polygon, *, cell: float, window: int, **kwargs):
    """The exact 2-D snake (graph reduction) with direction and deviation energies.

    Calls :func:`lidar2city.regularize.snake.regularize_polygon`, imported here
    so that the footprint package works without it.

    Raises
    ------
    DependencyError
        When the snake regulariser is not part of this installation.
    """
    regularize_polygon = _snake()
    out, info = regularize_polygon(polygon, cell=cell, window=window, **kwargs)
    info = dict(info)
    info.setdefault("direction", outline_direction(out))
    info.setdefault("n_vertices", vertex_count(out))
    info.setdefault("reductions", {"I": 0, "II": 0, "III": 0, "IV": 0})
    if "mean_deviation" not in info:
        info["mean_deviation"] = mean_deviation(out, polygon)
    return out, info


#: Regularisers by name (the CLI choice and the ``footprints.regularize`` config value).
REGULARIZERS = {
    "none": regularize_none,
    "snake": regularize_snake,
}
