"""Closed solids over a polygon whose roof is the lower envelope of planes.

A gable roof is the minimum of two planes, a hip roof of four, a shed or flat
roof a single plane. Over any footprint polygon (holes allowed) the roof
faces are the polygon cut by the regions where each plane is the lowest;
the walls are vertical, from the ground to the roof along the outline
(split where the outline crosses a region boundary, so every roof edge on
the outline is a wall's top edge). Coordinates are snapped to a fine grid so
faces share vertices exactly.
"""

from __future__ import annotations

import numpy as np

from ..datamodel import Solid, Surface
from ..errors import FitError

__all__ = ["envelope_solid", "envelope_z", "unpaired_edges"]

_GRID = 1e-6


def envelope_z(planes, xy) -> np.ndarray:
    """Height of the lower envelope ``min_i(a_i + b_i x + c_i y)`` at xy (N, 2)."""
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 3)
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return (planes[:, 0][None] + xy[:, :1] * planes[:, 1][None] + xy[:, 1:] * planes[:, 2][None]).min(axis=1)


def _regions(planes, box):
    """Convex plan regions where each plane is the lowest (within ``box``)."""
    import shapely

    x0, y0, x1, y1 = box
    big = shapely.box(x0, y0, x1, y1)
    span = 4.0 * max(x1 - x0, y1 - y0) + 1.0
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    out = []
    for i, (a, b, c) in enumerate(planes):
        reg = big
        for j, (a2, b2, c2) in enumerate(planes):
            if i == j or reg.is_empty:
                continue
            # keep  (a - a2) + (b - b2) x + (c - c2) y <= 0
            da, db, dc = a - a2, b - b2, c - c2
            nrm = np.hypot(db, dc)
            if nrm < 1e-12:
                if da > 0 or (da == 0 and j < i):
                    reg = shapely.Polygon()
                continue
            n = np.array([db, dc]) / nrm
            off = -da / nrm  # half-plane n . p <= off
            t = np.array([-n[1], n[0]])
            p0 = np.array([cx, cy]) + (off - n @ np.array([cx, cy])) * n
            half = shapely.Polygon([p0 + t * span, p0 - t * span, p0 - t * span - n * span,
                                    p0 + t * span - n * span])
            reg = reg.intersection(half)
        out.append(reg)
    return out


def _polys(g):
    if g.is_empty:
        return []
    if g.geom_type == "Polygon":
        return [g]
    return [p for p in getattr(g, "geoms", []) if p.geom_type == "Polygon" and p.area > 0]


def envelope_solid(polygon, planes, z0: float) -> Solid:
    """A closed solid: ``polygon`` at ground height ``z0`` up to the envelope of ``planes``.

    Parameters
    ----------
    polygon : shapely Polygon
        Footprint (local metres); holes allowed.
    planes : array_like, shape (P, 3)
        Roof planes ``z = a + b x + c y``.
    z0 : float
        Ground height.

    Returns
    -------
    Solid
        Ground (one face with holes), walls (one per footprint edge, its top
        following the roof), roof faces (one per connected piece of each
        plane's region).

    Raises
    ------
    FitError
        The roof reaches down to the ground inside the polygon.
    """
    import shapely
    from shapely.geometry.polygon import orient

    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 3)
    with np.errstate(all="ignore"):  # subnormal coordinates warn inside GEOS snapping
        poly = orient(shapely.set_precision(polygon, _GRID), 1.0)
    if poly.is_empty or poly.geom_type != "Polygon":
        raise FitError("footprint polygon degenerates when snapped")
    minx, miny, maxx, maxy = poly.bounds
    pad = 1.0 + max(maxx - minx, maxy - miny)
    regions = _regions(planes, (minx - pad, miny - pad, maxx + pad, maxy + pad))
    faces = []
    for reg in regions:
        if reg.is_empty:
            continue
        with np.errstate(all="ignore"):
            piece = shapely.set_precision(poly.intersection(reg), _GRID)
        faces.extend(orient(p, 1.0) for p in _polys(piece))
    if not faces:
        raise FitError("no roof face over the footprint")
    # every face vertex on the outline is inserted into the outline rings
    face_pts = np.unique(np.vstack([np.asarray(r.coords)[:-1] for f in faces
                                    for r in [f.exterior, *f.interiors]]), axis=0)
    rings = [np.asarray(poly.exterior.coords)[:-1]] + [np.asarray(r.coords)[:-1] for r in poly.interiors]
    # per original edge: its top polyline (start vertex + outline crossings of the roof faces)
    edge_tops = []
    for ring in rings:
        per_edge = []
        for a, b in zip(ring, np.roll(ring, -1, axis=0), strict=True):
            pts = [a]
            ab = b - a
            L2 = ab @ ab
            if L2 > 0:
                t = ((face_pts - a) @ ab) / L2
                d = np.abs((face_pts[:, 0] - a[0]) * ab[1] - (face_pts[:, 1] - a[1]) * ab[0]) / np.sqrt(L2)
                on = (t > 1e-9) & (t < 1 - 1e-9) & (d < 2 * _GRID)
                pts.extend(face_pts[on][np.argsort(t[on])])
            per_edge.append(pts)
        edge_tops.append(per_edge)
    key = {}
    top_xy = []

    def top(p):
        k = (round(p[0] / _GRID), round(p[1] / _GRID))
        if k not in key:
            key[k] = len(top_xy)
            top_xy.append(p)
        return key[k]

    tops = [[[top(p) for p in pts] for pts in per_edge] for per_edge in edge_tops]
    face_idx = [[[top(p) for p in np.asarray(r.coords)[:-1]] for r in [f.exterior, *f.interiors]]
                for f in faces]
    top_xy = np.asarray(top_xy)
    top_z = envelope_z(planes, top_xy)
    outline_tops = [i for per_edge in tops for pts in per_edge for i in pts]
    if np.any(top_z[outline_tops] <= z0 + 1e-6):
        raise FitError("the roof reaches the ground on the outline")
    nt = len(top_xy)
    base_xy = np.vstack(rings)
    verts = np.vstack([np.column_stack([top_xy, top_z]),
                       np.column_stack([base_xy, np.full(len(base_xy), z0)])])
    surfaces = []
    offs = np.concatenate([[0], np.cumsum([len(r) for r in rings])]) + nt
    surfaces.append(Surface([np.arange(o0, o1)[::-1].copy() for o0, o1 in zip(offs[:-1], offs[1:], strict=True)],
                            "GroundSurface"))
    for (o0, o1), per_edge in zip(zip(offs[:-1], offs[1:], strict=True), tops, strict=True):
        base = np.arange(o0, o1)
        n = len(base)
        for i in range(n):
            j = (i + 1) % n
            # one vertical wall per footprint edge: up the end, back along the roof line
            up = per_edge[j][0]
            along = per_edge[i][::-1]
            surfaces.append(Surface([np.array([base[i], base[j], up, *along], dtype=np.int64)],
                                    "WallSurface"))
    for rings_f in face_idx:
        surfaces.append(Surface([np.asarray(r, dtype=np.int64) for r in rings_f], "RoofSurface"))
    solid = Solid(verts, surfaces)
    bad = unpaired_edges(solid)
    if bad:
        raise FitError(f"roof over the footprint is not closed ({bad} unpaired edges)")
    return solid


def unpaired_edges(solid) -> int:
    """Number of directed edges not used exactly once, with their reverse used exactly once."""
    e = np.vstack([np.column_stack([r, np.roll(r, -1)]) for s in solid.surfaces
                   for r in (np.asarray(x, dtype=np.int64) for x in s.rings)])
    n = int(e.max()) + 1
    code = e[:, 0] * n + e[:, 1]
    rev = e[:, 1] * n + e[:, 0]
    uniq, counts = np.unique(code, return_counts=True)
    cnt = dict(zip(uniq.tolist(), counts.tolist(), strict=True))
    bad = sum(1 for c, r in zip(code.tolist(), rev.tolist(), strict=True)
              if cnt.get(c, 0) != 1 or cnt.get(r, 0) != 1)
    return bad
