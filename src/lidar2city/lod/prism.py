"""Extruded footprints: closed prism solids with CityJSON semantics (LoD1.x).

A prism over a polygon (with holes) has one GroundSurface (the footprint,
facing down), one RoofSurface (the footprint lifted to the roof height,
facing up) and one WallSurface per footprint edge, exterior and hole edges
alike. Vertices are shared: ``2 * K`` vertices for a footprint with ``K``
distinct ring vertices, so the shell is closed and 2-manifold by construction
(every edge is used by exactly two faces, in opposite directions).
"""

from __future__ import annotations

import numpy as np

from ..datamodel import Solid, Surface
from ..errors import InputError

__all__ = ["clean_polygon", "prism_solid", "prism_is_valid", "prism_distance", "lod12_solid",
           "lod12_solids"]


def _ring_coords(ring, grid: float) -> np.ndarray:
    c = np.asarray(ring.coords, dtype=np.float64)[:, :2]
    if len(c) and np.array_equal(c[0], c[-1]):
        c = c[:-1]
    if len(c) == 0:
        return c
    # drop consecutive (and closing) vertices closer than 2.5 grid steps, so that a
    # validator snapping vertices at the grid size (val3dity: 1 mm) cannot merge them
    tol = max(2.5 * grid, 1e-9)
    step = np.hypot(*(c - np.roll(c, 1, axis=0)).T)  # distance to the previous vertex
    if len(c) > 1:
        c = c[step >= tol] if np.any(step >= tol) else c[:1]
    return c


def clean_polygon(polygon, *, grid: float = 0.0):
    """Orient (exterior CCW, holes CW), snap to ``grid`` metres and repair a polygon.

    Parameters
    ----------
    polygon : shapely Polygon or MultiPolygon
    grid : float
        Vertices are snapped to multiples of ``grid`` (the output precision,
        e.g. 0.001 m) so that what is written is what was validated; 0 keeps
        them as they are.

    Returns
    -------
    list of shapely Polygon
        Valid, oriented parts with non-zero area (empty list if none remain).
    """
    import shapely
    from shapely.geometry.polygon import orient

    if polygon is None or polygon.is_empty:
        return []
    g = polygon if polygon.is_valid else shapely.make_valid(polygon)
    if grid > 0:
        with np.errstate(all="ignore"):  # denormal coordinates: GEOS copes, numpy warns
            g = shapely.set_precision(g, grid)
    if not g.is_valid:
        g = shapely.make_valid(g)
    parts = [p for p in shapely.get_parts(g) if p.geom_type == "Polygon" and p.area > 0]
    # slivers (a part or a hole a few grid steps wide) give walls closer than the snap
    # tolerance of a validator: they are dropped (mean width = 2 area / perimeter)
    thin = 5.0 * max(grid, 0.001)
    out = []
    for p in parts:
        for q in shapely.get_parts(shapely.make_valid(p)) if not p.is_valid else [p]:
            if q.geom_type != "Polygon" or not q.area > max(grid, 1e-6) ** 2 \
                    or 2.0 * q.area / q.length < thin:
                continue
            holes = [h for h in q.interiors
                     if 2.0 * abs(shapely.Polygon(h).area) / h.length >= thin]
            if len(holes) < len(q.interiors):
                q = shapely.Polygon(q.exterior, holes)
            out.extend(orient(r, 1.0) for r in _separate_rings(q, grid, thin))
    return out


def _separate_rings(polygon, grid: float, thin: float) -> list:
    """``polygon`` with no two rings closer than the validator's snap tolerance.

    A valid polygon may have a hole touching its exterior, or two holes
    touching, at a point; its prism then has a wall edge used by four faces
    (non-manifold, val3dity 303). Each such contact (rings closer than 2.5 grid
    steps, the distance :func:`_ring_coords` keeps vertices apart) is opened:
    a square of ``thin`` metres centred on it is cut out, so that the hole
    becomes a notch of the outline (or the two holes one hole). A part the cuts
    split off is kept as a part of its own.
    """
    import shapely

    tol = 2.5 * max(grid, 0.001)
    half = max(thin, 2.0 * tol)
    todo, out = [polygon], []
    for _ in range(64):  # each cut removes one contact; bounded for pathological inputs
        if not todo:
            break
        q = todo.pop()
        contact = _ring_contact(q, tol)
        if contact is None:
            out.append(q)
            continue
        x, y = contact
        g = q.difference(shapely.box(x - half, y - half, x + half, y + half))
        if grid > 0:
            with np.errstate(all="ignore"):
                g = shapely.set_precision(g, grid)
        if not g.is_valid:
            g = shapely.make_valid(g)
        todo.extend(p for p in shapely.get_parts(g) if p.geom_type == "Polygon"
                    and p.area > max(grid, 1e-6) ** 2 and 2.0 * p.area / p.length >= thin)
    return out + [p for p in todo if _ring_contact(p, tol) is None]


def _ring_contact(polygon, tol: float):
    """``(x, y)`` where two rings of ``polygon`` come closer than ``tol``, or None."""
    from shapely.ops import nearest_points

    rings = [polygon.exterior, *polygon.interiors]
    for i in range(len(rings)):
        for j in range(i + 1, len(rings)):
            if rings[i].distance(rings[j]) < tol:
                a, b = nearest_points(rings[i], rings[j])
                return (a.x + b.x) / 2.0, (a.y + b.y) / 2.0
    return None


def prism_solid(polygon, ground_z: float, roof_z: float, *, grid: float = 0.0) -> Solid:
    """A closed prism over one polygon, from ``ground_z`` to ``roof_z`` (metres).

    Parameters
    ----------
    polygon : shapely Polygon
        Valid polygon in local metric coordinates (holes allowed).
    ground_z, roof_z : float
        Heights of the bottom and the top; ``roof_z > ground_z``.
    grid : float
        Output precision (see :func:`clean_polygon`); consecutive vertices
        closer than 2.5 times this are merged.

    Returns
    -------
    Solid
        Surfaces in the order: GroundSurface, RoofSurface, WallSurfaces (one
        per ring edge, exterior ring edges first, then each hole's).

    Raises
    ------
    InputError
        If the polygon is not a Polygon, is empty, or ``roof_z <= ground_z``.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> s = prism_solid(box(0, 0, 2, 1), 0.0, 3.0)
    >>> len(s.vertices), len(s.surfaces)
    (8, 6)
    """
    return _prism_solid(polygon, ground_z, roof_z, grid)[0]


def _prism_solid(polygon, ground_z: float, roof_z: float, grid: float = 0.0):
    """:func:`prism_solid` and its layout, as :func:`_prism_layout` would find it from the
    solid (what :func:`_layout_distance` and :func:`_layout_is_valid` take)."""
    from shapely.geometry.polygon import orient

    if polygon is None or polygon.geom_type != "Polygon" or polygon.is_empty:
        raise InputError("prism_solid needs a non-empty shapely Polygon")
    if not (np.isfinite(ground_z) and np.isfinite(roof_z)) or roof_z <= ground_z:
        raise InputError(f"roof height {roof_z} must be above ground height {ground_z}")
    polygon = orient(polygon, 1.0)
    rings2d = [_ring_coords(polygon.exterior, grid)] + [
        _ring_coords(r, grid) for r in polygon.interiors]
    rings2d = [rings2d[0]] + [r for r in rings2d[1:] if len(r) >= 3]
    if len(rings2d[0]) < 3:
        raise InputError("footprint ring has fewer than 3 distinct vertices")
    xy = np.concatenate(rings2d)
    k = len(xy)
    vertices = np.empty((2 * k, 3))
    vertices[:k, :2] = xy
    vertices[:k, 2] = ground_z
    vertices[k:, :2] = xy
    vertices[k:, 2] = roof_z
    starts = np.cumsum([0] + [len(r) for r in rings2d])[:-1]
    lens = [len(r) for r in rings2d]
    idx_rings = [np.arange(s, s + len(r)) for s, r in zip(starts, rings2d, strict=True)]
    ground = Surface([r[::-1].copy() for r in idx_rings], "GroundSurface")
    roof = Surface([r + k for r in idx_rings], "RoofSurface")
    walls, quads = [], []
    for r in idx_rings:
        nxt = np.roll(r, -1)
        q = np.column_stack([r, nxt, nxt + k, r + k])
        quads.append(q)
        walls.extend(Surface([w], "WallSurface") for w in q)
    solid = Solid(vertices, [ground, roof, *walls])
    return solid, (solid.vertices, k, starts, lens, quads)


def _prism_layout(solid):
    """``(vertices, k, ring starts, ring lengths, wall quads)`` of a solid laid out exactly
    as :func:`prism_solid` builds it (ground ring vertices ``0..k-1`` at one height, the
    same ``k..2k-1`` above at another, caps and one quad wall per ring edge), else None."""
    v = np.asarray(solid.vertices, dtype=np.float64)
    surfaces = solid.surfaces
    n = len(v)
    k = n // 2
    if v.ndim != 2 or v.shape[1] != 3 or n < 6 or n % 2 or len(surfaces) != 2 + k \
            or not np.isfinite(v).all():
        return None
    ground, roof, walls = surfaces[0], surfaces[1], surfaces[2:]
    if ground.semantic != "GroundSurface" or roof.semantic != "RoofSurface" \
            or len(ground.rings) != len(roof.rings) or not roof.rings:
        return None
    g, r = v[0, 2], v[k, 2]
    if not (r > g and np.all(v[:k, 2] == g) and np.all(v[k:, 2] == r)
            and np.array_equal(v[:k, :2], v[k:, :2])):
        return None
    lens = [len(ring) for ring in roof.rings]
    if min(lens) < 3 or sum(lens) != k:
        return None
    starts = np.cumsum([0] + lens)[:-1]
    quads = []
    for s0, m, top, bottom in zip(starts, lens, roof.rings, ground.rings, strict=True):
        ids = np.arange(s0, s0 + m)
        if not (np.array_equal(np.asarray(top), ids + k)
                and np.array_equal(np.asarray(bottom), ids[::-1])):
            return None
        nxt = np.roll(ids, -1)
        quads.append(np.column_stack([ids, nxt, nxt + k, ids + k]))
    if any(w.semantic != "WallSurface" or len(w.rings) != 1 or len(w.rings[0]) != 4
           for w in walls):
        return None
    if not np.array_equal(np.array([w.rings[0] for w in walls]), np.concatenate(quads)):
        return None
    return v, k, starts, lens, quads


def prism_distance(points, solids, *, chunk_pairs: int = 1 << 16):
    """3-D distance of points to the boundary of prisms, from their footprint rings.

    For a prism over polygon ``A`` from height ``g`` to ``r``, a point whose plan
    position is inside ``A`` is nearest to the roof, the floor, or (between the
    two heights) the wall at its plan distance to ``A``'s rings; a point outside
    is ``sqrt(d_plan^2 + d_z^2)`` away, ``d_z`` its height's distance to
    ``[g, r]``. The minimum over the prisms is the distance to their union of
    faces, as :func:`lidar2city.metrics.model.point_mesh_distance` finds it on
    their triangles (equal up to rounding), without triangulating.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
    solids : list of Solid
        Prisms laid out as :func:`prism_solid` builds them.
    chunk_pairs : int
        Point-edge pairs evaluated at a time (bounds the temporaries).

    Returns
    -------
    ndarray, shape (N,) or None
        None when a solid is not such a prism (measure it on its mesh then).
    """
    layouts = []
    for s in solids:
        layout = _prism_layout(s)
        if layout is None:
            return None
        layouts.append(layout)
    return _layout_distance(points, layouts, chunk_pairs=chunk_pairs)


def _layout_distance(points, layouts, *, chunk_pairs: int = 1 << 16):
    """:func:`prism_distance` of the prisms laid out as ``layouts`` (:func:`_prism_layout`)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rings = []  # per prism: edges from a to b, ground, roof, its rings' vertices
    for v, k, starts, lens, quads in layouts:
        q = quads[0] if len(quads) == 1 else np.concatenate(quads)
        rings.append((v[q[:, 0], :2], v[q[:, 1], :2], v[0, 2], v[k, 2],
                      [v[s0:s0 + m, :2] for s0, m in zip(starts, lens, strict=True)]))
    if not layouts or len(pts) == 0:
        return np.full(len(pts), np.inf) if not layouts else np.zeros(0)
    if len(rings) == 1 or len(pts) * sum(len(q[0]) for q in rings) <= DIRECT_PAIRS:
        # one prism, or few points and edges (a house's parts): every point against every
        # edge at once costs less than sorting them into tiles
        return np.sqrt(_prism_d2(pts, rings, chunk_pairs))
    # many prisms (the parts of a hall, one of them winding through all of it): each
    # point against the prisms that can be its nearest only, and against the edges of
    # those that can decide its distance only (every point against every edge grows with
    # the square of a hall's area). A point inside a prism is at most the height to its
    # nearer cap from it: a bound b (points inside none, valid, are measured against all
    # edges).
    # Tile of points by tile, prisms whose box is farther than b cannot be nearest; of
    # the others, the edges whose box is farther than b cannot give the minimum, and those
    # not crossing the points' rows to their right do not change the ray casting: they are
    # left out. Each value kept is the one computed against all edges (the minimum over
    # edges holding its smallest one, the same parity), the others can only be larger, so
    # the distances are identical. A tolerance of 1 um covers GEOS's and the kernel's
    # rounding (~1e-13 m).
    import shapely

    tol = 1e-6
    g = np.array([q[2] for q in rings])
    r = np.array([q[3] for q in rings])
    emin = [np.minimum(q[0], q[1]) for q in rings]
    emax = [np.maximum(q[0], q[1]) for q in rings]
    blo = np.array([m.min(axis=0) for m in emin])
    bhi = np.array([m.max(axis=0) for m in emax])
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    bound = np.full(len(pts), np.inf)
    for j, q in enumerate(rings):
        sel = np.flatnonzero((x >= blo[j, 0]) & (x <= bhi[j, 0]) & (y >= blo[j, 1])
                             & (y <= bhi[j, 1]))
        poly = shapely.Polygon(q[4][0], q[4][1:])
        if not poly.is_valid:  # its inside per GEOS may not be the ray casting's
            continue
        shapely.prepare(poly)
        sel = sel[shapely.contains_xy(poly, x[sel], y[sel])]
        bound[sel] = np.minimum(bound[sel], np.minimum(np.abs(z[sel] - r[j]),
                                                       np.abs(z[sel] - g[j])) + tol)
    best = np.full(len(pts), np.inf)
    rest = np.flatnonzero(~np.isfinite(bound))
    if len(rest):
        best[rest] = _prism_d2(pts[rest], rings, chunk_pairs)
    held = np.flatnonzero(np.isfinite(bound))
    # tiles of ~256 points
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    side = max(float(np.sqrt((hi - lo).prod() * 256.0 / len(pts))), 1e-3)
    cells = np.floor((pts[held, :2] - lo) / side).astype(np.int64)
    tile = cells[:, 0] * (int(cells[:, 1].max(initial=0)) + 1) + cells[:, 1]
    held = held[np.argsort(tile, kind="stable")]
    tile = np.sort(tile, kind="stable")
    cut = np.flatnonzero(np.r_[True, tile[1:] != tile[:-1], True])
    for s0, s1 in zip(cut[:-1], cut[1:], strict=True):
        sel = held[s0:s1]
        p = pts[sel]
        plo, phi, reach = p[:, :2].min(axis=0), p[:, :2].max(axis=0), bound[sel].max()
        for j in np.flatnonzero(np.all((blo <= phi + reach) & (bhi >= plo - reach), axis=1)):
            keep = np.all((emin[j] <= phi + reach) & (emax[j] >= plo - reach), axis=1)  # near
            keep |= ((emax[j][:, 1] > plo[1]) & (emin[j][:, 1] <= phi[1])
                     & (emax[j][:, 0] + tol >= plo[0]))                       # ray casting
            if keep.any():  # else the points are outside it and farther than their bound
                a, b = rings[j][0][keep], rings[j][1][keep]
                best[sel] = np.minimum(best[sel], _prism_d2(p, [(a, b, g[j], r[j])],
                                                            chunk_pairs))
    return np.sqrt(best)


def _layout_inside_distance(points, layout, *, chunk_pairs: int = 1 << 16):
    """:func:`prism_distance` of points inside the footprint of one prism laid out as
    ``layout``: their plan position known inside (GEOS), the ray casting is left out, and
    the plan distance to the walls is measured only for the points between floor and roof
    (the others are nearest to a cap). Each value is the one :func:`prism_distance` finds
    for a point its ray casting also puts inside; for one it puts outside (within
    rounding of an edge, or of a vertex the prism dropped: :func:`_ring_coords`) the two
    differ by that point's squared plan distance to the outline (under 1e-5 m2)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    v, k, _, _, quads = layout
    q = quads[0] if len(quads) == 1 else np.concatenate(quads)
    a, b = v[q[:, 0], :2], v[q[:, 1], :2]
    g, r = v[0, 2], v[k, 2]
    z = pts[:, 2]
    d2 = np.minimum(np.abs(z - r), np.abs(z - g)) ** 2
    between = np.flatnonzero((z >= g) & (z <= r))
    ab = b - a
    ll = np.einsum("ij,ij->i", ab, ab)
    ll_safe = np.where(ll > 0, ll, 1.0)
    ax, ay, abx, aby = a[:, 0], a[:, 1], ab[:, 0], ab[:, 1]
    step = max(1, chunk_pairs // len(a))
    for s0 in range(0, len(between), step):
        sel = between[s0:s0 + step]
        px, py = pts[sel, :1], pts[sel, 1:2]
        # the plan distance as _prism_d2 computes it, operation by operation
        dx = px - ax
        dy = py - ay
        t = dx * abx
        t += dy * aby
        t /= ll_safe
        np.clip(t, 0.0, 1.0, out=t)
        u = t * abx
        u -= dx
        u *= u
        t *= aby
        t = dy - t
        t *= t
        u += t
        d2[sel] = np.minimum(d2[sel], u.min(axis=1))
    return np.sqrt(d2)


#: point-edge pairs up to which :func:`prism_distance` measures every point against every
#: edge of every prism (a few chunks of ``chunk_pairs``) rather than tile by tile
DIRECT_PAIRS = 1 << 18


def _prism_d2(pts, rings, chunk_pairs):
    """Squared 3-D distance of each point to the nearest of the prisms ``rings`` (as
    :func:`prism_distance` lays them out: ring edges ``a -> b``, ground, roof)."""
    a = np.concatenate([q[0] for q in rings])
    b = np.concatenate([q[1] for q in rings])
    g = np.array([q[2] for q in rings])
    r = np.array([q[3] for q in rings])
    first = np.cumsum([0] + [len(q[0]) for q in rings])[:-1]  # edges grouped by prism
    ab = b - a
    ll = np.einsum("ij,ij->i", ab, ab)
    ll_safe = np.where(ll > 0, ll, 1.0)
    # ray casting along +x: edges crossing the point's row, right of it
    dy = np.where(ab[:, 1] != 0, ab[:, 1], 1.0)
    ax, ay, abx, aby, by = (np.ascontiguousarray(c) for c in (a[:, 0], a[:, 1], ab[:, 0], ab[:, 1],
                                                                b[:, 1]))
    out = np.empty(len(pts))
    # chunks of ~64k point-edge pairs: the scratch arrays stay in the CPU cache (twice as
    # fast as chunks of 1M pairs), written in place; each pair's value is the same IEEE
    # double sequence as the plain expression, so the distances are identical
    step = max(1, chunk_pairs // len(a))
    shape = (min(step, len(pts)), len(a))
    dx, dyp, t, u = (np.empty(shape) for _ in range(4))
    c1, c2 = np.empty(shape, dtype=bool), np.empty(shape, dtype=bool)
    for s0 in range(0, len(pts), step):
        p = pts[s0:s0 + step]
        m = len(p)
        px, py, z = p[:, :1], p[:, 1:2], p[:, 2:]
        DX, DY, T, U, C1, C2 = dx[:m], dyp[:m], t[:m], u[:m], c1[:m], c2[:m]
        np.subtract(px, ax, out=DX)
        np.subtract(py, ay, out=DY)
        np.multiply(DX, abx, out=T)
        np.multiply(DY, aby, out=U)
        T += U
        T /= ll_safe
        np.clip(T, 0.0, 1.0, out=T)                 # t, the nearest point's edge parameter
        np.multiply(T, abx, out=U)
        U -= DX
        U *= U                                      # ex^2 (ex negated: the same square)
        T *= aby
        np.subtract(DY, T, out=T)
        T *= T                                      # ey^2
        U += T
        plan2 = np.minimum.reduceat(U, first, axis=1)      # (n, J)
        np.greater(ay, py, out=C1)
        np.greater(by, py, out=C2)
        np.not_equal(C1, C2, out=C1)
        np.multiply(DY, abx, out=T)
        T /= dy
        T += ax
        np.less(px, T, out=C2)
        C1 &= C2                                    # the edge crosses the row right of the point
        inside = np.add.reduceat(C1, first, axis=1, dtype=np.int64) % 2 == 1
        cap2 = np.minimum(np.abs(z - r), np.abs(z - g)) ** 2
        between = (z >= g) & (z <= r)
        d_in = np.where(between, np.minimum(cap2, plan2), cap2)
        dz = np.maximum(np.maximum(g - z, z - r), 0.0)
        d_out = plan2 + dz * dz
        out[s0:s0 + m] = np.where(inside, d_in, d_out).min(axis=1)
    return out


def prism_is_valid(solid, *, tolerance: float = 0.001) -> bool:
    """Whether ``solid`` is a prism as :func:`prism_solid` builds it, over rings that make it
    valid by construction (so :func:`lidar2city.validate.solid.check_solid` finds nothing).

    A prism's shell is closed, 2-manifold and outward-oriented by its layout, its
    faces are planar (horizontal caps, vertical rectangles), so it is valid exactly
    when its footprint is: the vertex layout and the surfaces are checked to be
    :func:`prism_solid`'s, the footprint rings to form a valid polygon (exterior
    counter-clockwise, holes clockwise), and the polygon's minimum clearance (the
    smallest move of a vertex that would make it invalid) to exceed the
    validator's tolerances with a margin: ``2 * tolerance`` (so no two vertices
    snap together) plus ``1e-4`` times the coordinates' magnitude and the longest
    edge (so no two walls pass the validator's coplanarity test, whose angle
    threshold is ~4.5e-5 rad, and overlap). A prism this cannot vouch for (False)
    may still be valid: check it with ``check_solid``.

    Parameters
    ----------
    solid : Solid
    tolerance : float
        The validator's snap and overlap tolerance (m; val3dity: 0.001).

    Returns
    -------
    bool
        True only when ``check_solid(solid)`` (default tolerances up to
        ``tolerance``) returns no issue.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> prism_is_valid(prism_solid(box(0, 0, 2, 1), 0.0, 3.0))
    True
    """
    layout = _prism_layout(solid)
    return layout is not None and _layout_is_valid(layout, tolerance=tolerance)


def _layout_is_valid(layout, *, tolerance: float = 0.001) -> bool:
    """:func:`prism_is_valid` of a prism laid out as ``layout`` (:func:`_prism_layout`)."""
    import shapely

    v, k, starts, lens, quads = layout
    if not v[k, 2] - v[0, 2] >= 2.0 * tolerance:
        return False
    xy = v[:k, :2]
    o = np.lexsort((xy[:, 1], xy[:, 0]))
    if np.any((xy[o[1:], 0] == xy[o[:-1], 0]) & (xy[o[1:], 1] == xy[o[:-1], 1])):
        # a vertex shared by two rings (holes touching at a point): GEOS's minimum
        # clearance leaves such contacts out, the shell's edge there is non-manifold
        return False
    rings = [shapely.LinearRing(xy[s0:s0 + m]) for s0, m in zip(starts, lens, strict=True)]
    ccw = shapely.is_ccw(rings)
    if not ccw[0] or ccw[1:].any():
        return False
    poly = shapely.Polygon(rings[0], rings[1:])
    if not poly.is_valid:
        return False
    longest = max(float(np.hypot(*(xy[q[:, 1]] - xy[q[:, 0]]).T).max()) for q in quads)
    margin = 2.0 * tolerance + 1e-4 * (float(np.abs(v).max()) + longest)
    return bool(shapely.minimum_clearance(poly) >= margin)


def lod12_solids(footprint, ground_z: float, roof_z: float, *, grid: float = 0.0) -> list[Solid]:
    """LoD1.2 prisms of a footprint: one solid per polygon part.

    A MultiPolygon footprint gives several solids; CityJSON stores them as a
    ``MultiSolid`` (the parts need not touch, which a ``CompositeSolid`` would
    require along shared faces).
    """
    parts = clean_polygon(footprint, grid=grid)
    if not parts:
        raise InputError("footprint has no polygon with a non-zero area")
    return [prism_solid(p, ground_z, roof_z, grid=grid) for p in parts]


def lod12_solid(footprint, ground_z: float, roof_z: float, *, grid: float = 0.0) -> Solid:
    """LoD1.2 prism of a single-polygon footprint (see :func:`lod12_solids` for parts).

    Raises
    ------
    InputError
        If the footprint has several parts.
    """
    solids = lod12_solids(footprint, ground_z, roof_z, grid=grid)
    if len(solids) != 1:
        raise InputError(f"footprint has {len(solids)} parts; use lod12_solids for a MultiSolid")
    return solids[0]
