"""Sub-cell boundary tracing of building regions and Douglas–Peucker simplification."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from .grid import Grid

logger = logging.getLogger(__name__)

__all__ = ["trace_regions", "simplify_polygon"]


def _ring_polygon(rc, grid: Grid):
    import shapely

    xy = grid.to_xy(rc)
    if len(xy) < 4:
        return None
    poly = shapely.Polygon(xy)
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
        parts = [g for g in getattr(poly, "geoms", [poly]) if g.geom_type == "Polygon"]
        if not parts:
            return None
        poly = max(parts, key=lambda g: g.area)
    return poly if poly.area > 0 else None


def trace_regions(field, labels, grid: Grid, *, level: float = 0.5, min_hole_area: float = 4.0):
    """One polygon (with holes) per labelled region, traced on the iso-line ``field = level``.

    The contour of each region is found by marching squares
    (:func:`skimage.measure.find_contours`) on the field itself, with the cells
    of every other region set to 0 so that neighbouring regions do not leak in.
    Linear interpolation between cell centres places the outline between
    cells, to a fraction of a cell.

    Parameters
    ----------
    field : ndarray, shape (R, C)
        Smooth building field (:func:`lidar2city.footprints.grid.building_fraction`).
    labels : ndarray of int, shape (R, C)
        Regions 1..K of ``field >= level`` (8-connected).
    grid : Grid
        Geometry of the cells.
    level : float
        Iso-value traced.
    min_hole_area : float
        Inner rings smaller than this (m2) are dropped.

    Returns
    -------
    list of (int, shapely.Polygon)
        Region label and its polygon in local metres; regions whose outline
        degenerates are skipped.
    """
    import shapely
    from scipy import ndimage as ndi
    from skimage.measure import find_contours

    field = np.asarray(field, dtype=np.float64)
    labels = np.asarray(labels)
    if field.shape != labels.shape or field.shape != tuple(grid.shape):
        raise InputError(f"field {field.shape}, labels {labels.shape} and grid {grid.shape} differ")
    out = []
    objects = ndi.find_objects(labels)
    low = np.nextafter(level, -np.inf)
    for k, sl in enumerate(objects, start=1):
        if sl is None:
            continue
        r0 = max(sl[0].start - 2, 0)
        c0 = max(sl[1].start - 2, 0)
        r1 = min(sl[0].stop + 2, field.shape[0])
        c1 = min(sl[1].stop + 2, field.shape[1])
        sub_l = labels[r0:r1, c0:c1]
        sub = np.where(sub_l == k, field[r0:r1, c0:c1],
                       np.where(sub_l > 0, 0.0, np.minimum(field[r0:r1, c0:c1], low)))
        sub = np.pad(sub, 1, constant_values=0.0)
        contours = find_contours(sub, level, fully_connected="high")
        sub_grid = Grid(grid.x0 + (c0 - 1) * grid.cell, grid.y0 + (r0 - 1) * grid.cell,
                        grid.cell, sub.shape)
        rings = [p for p in (_ring_polygon(c, sub_grid) for c in contours) if p is not None]
        if not rings:
            continue
        rings.sort(key=lambda p: p.area, reverse=True)
        outer = rings[0]
        holes = [p for p in rings[1:] if p.area >= min_hole_area and outer.contains(p.representative_point())]
        poly = outer
        if holes:
            poly = shapely.difference(outer, shapely.union_all(holes))
            if poly.geom_type != "Polygon":
                parts = [g for g in getattr(poly, "geoms", [poly]) if g.geom_type == "Polygon"]
                poly = max(parts, key=lambda g: g.area) if parts else outer
        out.append((k, shapely.Polygon(poly.exterior, list(poly.interiors))))
    return out


def _fit_line(pts):
    """Total least squares line through ``pts`` (K, 2): (centroid, unit direction)."""
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    return c, vt[0]


def _refine_ring(kept, dense, tolerance):
    """Move the vertices of a Douglas-Peucker ring to the intersections of lines fitted
    to the dense outline between them (the vertices DP keeps lie on rounded corners)."""
    n = len(kept)
    index = {tuple(p): i for i, p in enumerate(dense)}
    idx = [index.get(tuple(p)) for p in kept]
    if n < 3 or any(i is None for i in idx):
        return kept
    m = len(dense)
    lines = []
    for k in range(n):
        i0, i1 = idx[k], idx[(k + 1) % n]
        span = (i1 - i0) % m
        seg = dense[(i0 + np.arange(span + 1)) % m]
        # leave out the rounded ends: points within ``tolerance`` of either end vertex
        d = np.minimum(np.hypot(*(seg - seg[0]).T), np.hypot(*(seg - seg[-1]).T))
        core = seg[d > tolerance]
        lines.append(_fit_line(core) if len(core) >= 2 else _fit_line(seg[[0, -1]]))
    out = kept.copy()
    for k in range(n):
        (c0, u0), (c1, u1) = lines[k - 1], lines[k]
        cross = u0[0] * u1[1] - u0[1] * u1[0]
        if abs(cross) < np.sin(np.radians(20.0)):
            continue  # nearly collinear edges: keep the vertex
        t = ((c1[0] - c0[0]) * u1[1] - (c1[1] - c0[1]) * u1[0]) / cross
        p = c0 + t * u0
        if np.hypot(*(p - kept[k])) <= 3.0 * tolerance:
            out[k] = p
    return out


def simplify_polygon(polygon, tolerance: float, *, refine: bool = True):
    """Douglas–Peucker simplification keeping the polygon valid, with vertex refinement.

    Douglas–Peucker keeps a subset of the traced vertices; on a traced outline
    those at corners lie on the rounded corner, so the simplified polygon cuts
    every corner (a systematic loss of area). With ``refine`` each edge is
    replaced by the total least squares line through the traced vertices it
    stands for (away from its ends) and each vertex moves to the intersection of
    its two lines, unless they are within 20 degrees of parallel or the
    intersection lies farther than ``3 * tolerance`` away. The refined polygon
    is used only if it is valid.

    Parameters
    ----------
    polygon : shapely.Polygon
    tolerance : float
        Largest distance (m) a removed vertex may lie from the simplified outline.
    refine : bool
        Refit the vertices as described.

    References
    ----------
    Douglas, D. H., Peucker, T. K. (1973). Algorithms for the reduction of the number
    of points required to represent a digitized line or its caricature.
    Cartographica 10(2), 112-122.
    """
    import shapely

    if tolerance < 0:
        raise InputError(f"tolerance must be >= 0, got {tolerance}")
    if tolerance == 0:
        return polygon
    out = shapely.simplify(polygon, tolerance, preserve_topology=True)
    if out.is_empty or out.geom_type != "Polygon" or not out.is_valid:
        return polygon
    if not refine:
        return out
    rings = []
    for kept_ring, dense_ring in zip([out.exterior, *out.interiors],
                                     [polygon.exterior, *polygon.interiors], strict=False):
        kept = np.asarray(kept_ring.coords)[:-1, :2]
        dense = np.asarray(dense_ring.coords)[:-1, :2]
        rings.append(_refine_ring(kept, dense, tolerance))
    if len(out.interiors) != len(polygon.interiors):
        return out
    refined = shapely.Polygon(rings[0], rings[1:])
    return refined if refined.is_valid and refined.area > 0 else out
