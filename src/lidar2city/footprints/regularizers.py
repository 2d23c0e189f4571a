"""Footprint outline regularisers: a name -> function dict (``REGULARIZERS``).

Every regulariser is called as ``f(traced, cell=..., window=..., tolerance=...)``
with the traced outline (a polygon, local metres) and the Douglas–Peucker
tolerance (m) of its simplification (``simplified=`` may give the simplified
outline instead; a regulariser that does not use it never makes it), and
returns ``(polygon, info)``. ``info``
holds ``direction`` (degrees, the building's dominant direction modulo 90),
``n_vertices``, ``reductions`` (dict of the snake's type "I".."IV" operation
counts; zeros when no snake ran), ``mean_deviation`` (m, mean distance from the
output outline to the traced one), ``status`` ("ok" or "unregularised") and
``reason``.
"""

from __future__ import annotations

import logging

import numpy as np

from .trace import simplify_polygon

logger = logging.getLogger(__name__)

__all__ = ["REGULARIZERS", "regularize_none", "regularize_snake", "regularize_fit",
           "outline_direction", "vertex_count", "mean_deviation"]


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


def mean_deviation(polygon, reference, *, step: float = 0.25) -> float:
    """Mean distance (m) from the boundary of ``polygon`` to the boundary of ``reference``.

    The boundary is sampled every ``step`` metres (vertices included).
    """
    import shapely

    dense = shapely.segmentize(polygon.boundary, step)
    pts = shapely.points(shapely.get_coordinates(dense))
    if not len(pts):
        return 0.0
    return float(np.mean(shapely.distance(pts, reference.boundary)))


def _plain_info(poly, traced, **extra) -> dict:
    """The descriptive ``info`` of an outline made without the snake."""
    return {
        "direction": outline_direction(poly),
        "n_vertices": vertex_count(poly),
        "reductions": {"I": 0, "II": 0, "III": 0, "IV": 0},
        "mean_deviation": mean_deviation(poly, traced),
        "status": "ok",
        "reason": "",
        **extra,
    }


def regularize_none(traced, *, simplified=None, tolerance: float | None = None, **_ignored):
    """No regularisation: the simplified outline with its descriptive ``info``.

    ``simplified`` when given, else ``traced`` simplified with ``tolerance``
    (:func:`..trace.simplify_polygon`), else ``traced``.
    """
    if simplified is None and tolerance is not None:
        simplified = simplify_polygon(traced, tolerance)
    poly = simplified if simplified is not None else traced
    return poly, _plain_info(poly, traced)


def _snake():
    """The snake solver (a function so tests can stand in for it)."""
    from ..regularize.snake import regularize_polygon

    return regularize_polygon


def regularize_snake(traced, *, cell: float, window: int, tolerance: float | None = None,
                     simplified=None, **kwargs):
    """The exact 2-D snake (graph reduction) with direction and deviation energies.

    Calls :func:`lidar2city.regularize.snake.regularize_polygon` on the *traced*
    outline, which simplifies it with ``tolerance`` and measures the deviation
    energy against it; ``kwargs`` are its keywords (``t_adjust``...). When the
    snake falls back (no valid result) the status is "unregularised" and the
    simplified outline is kept (``simplified``, else made from ``traced`` with
    ``tolerance`` then).

    References
    ----------
    Kass, Witkin, Terzopoulos (1988) for snakes; the graph-reduction solver and
    energies (eqs. 4-6) of :mod:`lidar2city.regularize.snake`.
    """
    regularize_polygon = _snake()
    if tolerance is not None:
        kwargs["simplify_tolerance"] = tolerance
    out, raw = regularize_polygon(traced, cell=cell, window=window, **kwargs)
    raw = dict(raw)
    if raw.get("status") != "regularized" or out is None:
        # the simplified outline is made here only: the snake simplifies on its own
        fallback, info = regularize_none(traced, simplified=simplified, tolerance=tolerance)
        info["status"] = "unregularised"
        info["reason"] = str(raw.get("reason", "the snake fell back"))
        info["reductions"] = dict(raw.get("reductions", info["reductions"]))
        return fallback, info
    direction = raw.get("direction_deg")
    deviation = raw.get("mean_deviation_m")
    return out, {
        "direction": float(np.mod(direction, 90.0)) if direction is not None
        else outline_direction(out),
        "n_vertices": vertex_count(out),
        "reductions": {t: int(raw.get("reductions", {}).get(t, 0)) for t in ("I", "II", "III", "IV")},
        "mean_deviation": float(deviation) if deviation is not None else mean_deviation(out, traced),
        "status": "ok",
        "reason": "",
    }


def regularize_fit(traced, *, cell: float, simplified=None, **_ignored):
    """Polygon fitting with complexity-penalised selection on the rasterised outline.

    The traced outline is rasterised at ``cell`` metres (pixel centres inside)
    and described by :func:`lidar2city.fit.polygon.fit_building_outline` with
    its default :class:`~lidar2city.fit.polygon.PolygonFitConfig`: the simplest
    of rectangle / right trapezoid / trapezoid / union of rectangles / general
    polygon whose overlap error plus complexity penalty is lowest. The same
    fitter describes the buildings segmented from a DSM
    (``lidar2city footprints --dsm``). ``info`` also holds ``shape_type``.

    Raises
    ------
    FitError
        When the outline covers no pixel centre or no shape fits (the caller
        keeps the simplified outline, status "unregularised").
    """
    import shapely
    from affine import Affine
    from rasterio import features

    from ..errors import EmptyInputError, FitError
    from ..fit.polygon import fit_building_outline

    cell = float(cell)
    if not cell > 0:
        raise FitError(f"cell must be positive, got {cell}")
    x0, y0, x1, y1 = traced.bounds
    x0, y1 = np.floor(x0 / cell) * cell - cell, np.ceil(y1 / cell) * cell + cell
    w = int(np.ceil((x1 - x0) / cell)) + 2
    h = int(np.ceil((y1 - y0) / cell)) + 2
    mask = features.rasterize([(traced, 1)], out_shape=(h, w),
                              transform=Affine(cell, 0.0, x0, 0.0, -cell, y1),
                              fill=0, dtype="uint8").astype(bool)
    if not mask.any():
        raise FitError("the outline covers no pixel centre at this cell size")
    try:
        # one traced outline, no neighbours; the size-scaled weight is tuned for DSM regions
        poly, kind, info = fit_building_outline(mask, cell=cell, offset=(x0, y1),
                                                regular_cells=0.0)
    except EmptyInputError as exc:
        raise FitError(str(exc)) from None
    if poly.geom_type != "Polygon" or not poly.is_valid or poly.is_empty:
        raise FitError("the fitted outline is not a valid polygon")
    poly = shapely.set_precision(poly, 1e-6)
    return poly, _plain_info(poly, traced, shape_type=kind)


#: Regularisers by name (the CLI choice and the ``footprints.regularize`` config value).
REGULARIZERS = {
    "none": regularize_none,
    "snake": regularize_snake,
    "fit": regularize_fit,
}
