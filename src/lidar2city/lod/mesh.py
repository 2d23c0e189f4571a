"""Triangulation of planar polygon surfaces (with holes) into index triangles.

Shared by the validator (self-intersection tests), the model metrics (point
to mesh distances) and the OBJ writer. No new vertices are created: the
triangles index the solid's own vertices.
"""

from __future__ import annotations

import weakref

import numpy as np

__all__ = ["dot3", "cross3", "plane_bases", "newell_normal", "plane_basis", "triangulate_polygon", "triangulate_surfaces",
           "solid_mesh", "solid_triangles"]


def dot3(a, b):
    """Row-wise dot product over the last axis of (..., 3) arrays (fast for small arrays)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def cross3(a, b):
    """Cross product over the last axis of (..., 3) arrays (fast for small arrays)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def plane_bases(normals):
    """Vectorised :func:`plane_basis`: ``u, v`` of shape (F, 3) for normals (F, 3)."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.sqrt(dot3(n, n))[:, None]
    zero = np.zeros(len(n))
    near_x = np.abs(n[:, 0]) >= 0.9
    u = np.where(near_x[:, None], np.column_stack([n[:, 2], zero, -n[:, 0]]),
                 np.column_stack([zero, -n[:, 2], n[:, 1]]))
    u = u / np.sqrt(dot3(u, u))[:, None]
    return u, cross3(n, u)


def newell_normal(points: np.ndarray) -> np.ndarray:
    """Area-weighted normal of a closed ring (Newell's method), not normalised.

    Parameters
    ----------
    points : ndarray, shape (K, 3)
        Ring vertices without the repeated closing vertex.

    Returns
    -------
    ndarray, shape (3,)
        Twice the vector area: its length is twice the (projected) area, its
        direction follows the right-hand rule on the ring order.
    """
    p = np.asarray(points, dtype=np.float64)
    q = np.concatenate([p[1:], p[:1]])  # the next vertex (np.roll without its overhead)
    d, s = p - q, p + q
    return np.array([np.sum(d[:, 1] * s[:, 2]), np.sum(d[:, 2] * s[:, 0]),
                     np.sum(d[:, 0] * s[:, 1])])


def plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal vectors ``u, v`` with ``u x v`` along ``normal``."""
    nx, ny, nz = np.asarray(normal, dtype=np.float64) / np.sqrt(np.dot(normal, normal))
    # u = helper x n with helper = x axis (or y axis when n is close to x)
    if abs(nx) < 0.9:
        u = np.array([0.0, -nz, ny])
    else:
        u = np.array([nz, 0.0, -nx])
    u /= np.sqrt(u @ u)
    v = np.array([ny * u[2] - nz * u[1], nz * u[0] - nx * u[2], nx * u[1] - ny * u[0]])
    return u, v


def _fan_ok(p2: np.ndarray) -> bool:
    """True when a single 2-D ring (CCW) is strictly convex, so a fan triangulates it."""
    d1 = np.concatenate([p2[1:], p2[:1]]) - p2  # np.roll(p2, -1) without its overhead
    d2 = np.concatenate([d1[1:], d1[:1]])
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    return bool(np.all(cross > 0))


def triangulate_polygon(vertices: np.ndarray, rings) -> np.ndarray:
    """Triangles (vertex index triples) covering a planar polygon with holes.

    Parameters
    ----------
    vertices : ndarray, shape (M, 3)
    rings : list of ndarray of int
        Exterior ring first (orientation defines the normal), then holes.

    Returns
    -------
    ndarray, shape (T, 3), int64
        Triangles oriented like the exterior ring (same normal direction).
        Empty for a degenerate polygon (zero area, fewer than 3 vertices).

    Notes
    -----
    Triangles and quadrilaterals that are convex are fanned; anything else is
    projected on its plane (Newell normal) and triangulated by GEOS's
    constrained Delaunay triangulation, which adds no vertex.
    """
    import shapely

    rings = [np.asarray(r, dtype=np.int64) for r in rings]
    ext = rings[0]
    if len(ext) < 3:
        return np.zeros((0, 3), dtype=np.int64)
    n = newell_normal(vertices[ext])
    area2 = np.linalg.norm(n)
    if not np.isfinite(area2) or area2 < 1e-12:
        return np.zeros((0, 3), dtype=np.int64)
    if len(rings) == 1 and len(ext) == 3:
        return ext.reshape(1, 3).copy()
    u, v = plane_basis(n)
    allidx = np.concatenate(rings)
    p2 = np.column_stack([vertices[allidx] @ u, vertices[allidx] @ v])
    if len(rings) == 1 and _fan_ok(p2):
        k = len(ext)
        return np.column_stack([np.full(k - 2, ext[0]), ext[1:-1], ext[2:]])
    offsets = np.cumsum([0] + [len(r) for r in rings])
    shell = p2[offsets[0]:offsets[1]]
    holes = [p2[offsets[i]:offsets[i + 1]] for i in range(1, len(rings))]
    try:
        poly = shapely.Polygon(shell, holes)
        if not poly.is_valid:
            poly = shapely.make_valid(poly)
        tris = shapely.get_parts(shapely.constrained_delaunay_triangles(poly))
    except Exception:  # GEOS failures on degenerate input
        return np.zeros((0, 3), dtype=np.int64)
    tris = tris[shapely.get_type_id(tris) == 3]
    if len(tris) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    coords = shapely.get_coordinates(tris).reshape(len(tris), -1, 2)[:, :3]
    out = _vertex_ids(p2, allidx, coords.reshape(-1, 2)).reshape(len(tris), 3)
    keep = (out[:, 0] != out[:, 1]) & (out[:, 1] != out[:, 2]) & (out[:, 0] != out[:, 2])
    out = out[keep]
    c = coords[keep]
    signed = ((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
              - (c[:, 2, 0] - c[:, 0, 0]) * (c[:, 1, 1] - c[:, 0, 1]))
    flip = signed < 0
    out[flip] = out[flip][:, ::-1]
    return out


def _vertex_ids(p2, ids, q):
    """``ids`` of the points of ``p2`` (n, 2) equal to each query point of ``q`` (m, 2).

    Exact coordinate matches (the last of equal points when several are); a query
    point matching none (make_valid moved it) takes its nearest point (the first
    of equally near ones).
    """
    key = np.empty(len(p2), dtype=np.complex128)  # complex numbers sort as (x, y) pairs
    key.real, key.imag = p2[:, 0], p2[:, 1]
    qk = np.empty(len(q), dtype=np.complex128)
    qk.real, qk.imag = q[:, 0], q[:, 1]
    order = np.argsort(key, kind="stable")
    pos = np.searchsorted(key[order], qk, side="right") - 1
    hit = order[np.maximum(pos, 0)]
    found = (pos >= 0) & (key[hit] == qk)
    out = np.asarray(ids, dtype=np.int64)[hit]
    for m in np.flatnonzero(~found):
        d = np.sum((p2 - q[m]) ** 2, axis=1)
        out[m] = ids[np.argmin(d)]
    return out


def triangulate_surfaces(vertices: np.ndarray, surfaces) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate every surface of a boundary.

    Parameters
    ----------
    vertices : ndarray, shape (M, 3)
    surfaces : sequence of :class:`~lidar2city.datamodel.Surface` or of ring lists

    Returns
    -------
    triangles : ndarray, shape (T, 3), int64
    face : ndarray, shape (T,), int64
        Index of the surface each triangle comes from.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    all_rings = [s.rings if hasattr(s, "rings") else s for s in surfaces]
    tris: list = [None] * len(all_rings)
    # single-ring faces, most of them walls: those clearly convex are fanned in one go per
    # vertex count; the others (and any close call) go through triangulate_polygon
    by_len: dict[int, list] = {}
    for i, rings in enumerate(all_rings):
        if len(rings) == 1 and 3 <= len(rings[0]) <= _FAN_MAX:
            by_len.setdefault(len(rings[0]), []).append(i)
    for k, idx in by_len.items():
        ext = np.array([np.asarray(all_rings[i][0], dtype=np.int64).reshape(-1) for i in idx])
        fan = _clear_fans(vertices[ext])
        if not fan.any():
            continue
        e = ext[fan]
        t = np.stack([np.repeat(e[:, :1], k - 2, axis=1), e[:, 1:-1], e[:, 2:]], axis=-1)
        for j, i in enumerate(np.asarray(idx)[fan]):
            tris[i] = t[j]
    faces = []
    for i, rings in enumerate(all_rings):
        if tris[i] is None:
            tris[i] = triangulate_polygon(vertices, rings)
        faces.append(np.full(len(tris[i]), i, dtype=np.int64))
    if not tris:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    return np.concatenate(tris), np.concatenate(faces)


#: largest ring fanned by :func:`triangulate_surfaces`' batched path
_FAN_MAX = 8


def _clear_fans(p):
    """Which rings ``p`` (F, k, 3) :func:`triangulate_polygon` surely fans.

    A ring is fanned there when its area is not negligible and it is strictly
    convex in its plane (or a triangle). Here only rings whose every turn is
    convex by a margin far above rounding (sine of the turn > 1e-6, area well
    above the threshold) count, so the answer is the one the per-face test
    gives; rings near a straight angle are left to that test.
    """
    q = np.concatenate([p[:, 1:], p[:, :1]], axis=1)
    d, s = p - q, p + q
    n = np.stack([np.sum(d[..., 1] * s[..., 2], axis=1), np.sum(d[..., 2] * s[..., 0], axis=1),
                  np.sum(d[..., 0] * s[..., 1], axis=1)], axis=1)
    area2 = np.sqrt(dot3(n, n))
    ok = np.isfinite(area2) & (area2 > 1e-9)
    if p.shape[1] == 3:
        return ok
    u, v = plane_bases(np.where(ok[:, None], n, 1.0))
    p2 = np.stack([dot3(p, u[:, None, :]), dot3(p, v[:, None, :])], axis=-1)
    d1 = np.concatenate([p2[:, 1:], p2[:, :1]], axis=1) - p2
    d2 = np.concatenate([d1[:, 1:], d1[:, :1]], axis=1)
    cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    lens = np.sqrt(np.sum(d1 * d1, axis=-1))
    margin = 1e-6 * lens * np.concatenate([lens[:, 1:], lens[:, :1]], axis=1)
    return ok & np.all(cross > margin, axis=1)


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def solid_mesh(solid) -> tuple[np.ndarray, np.ndarray]:
    """:func:`triangulate_surfaces` of a solid, computed once per solid object.

    Solids are treated as immutable (their dataclass is frozen): the cache is
    keyed by the object and dropped with it.
    """
    try:
        return _CACHE[solid]
    except (KeyError, TypeError):
        pass
    out = triangulate_surfaces(solid.vertices, solid.surfaces)
    try:
        _CACHE[solid] = out
    except TypeError:
        pass
    return out


def solid_triangles(solids) -> np.ndarray:
    """Corner coordinates of the triangles of one or several solids, shape (T, 3, 3)."""
    if hasattr(solids, "vertices"):
        solids = [solids]
    out = []
    for s in solids:
        t, _ = solid_mesh(s)
        out.append(s.vertices[t])
    if not out:
        return np.zeros((0, 3, 3))
    return np.concatenate(out)
