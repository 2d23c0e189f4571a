"""Triangulation of planar polygon surfaces (with holes) into index triangles.

Shared by the validator (self-intersection tests), the model metrics (point
to mesh distances) and the OBJ writer. No new vertices are created: the
triangles index the solid's own vertices.
"""

from __future__ import annotations

import weakref

import numpy as np

__all__ = ["dot3", "cross3", "plane_bases", "newell_normal", "ragged_newell", "plane_basis",
           "triangulate_polygon", "triangulate_surfaces", "solid_mesh", "solid_triangles"]


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


def ragged_newell(p, nxt, starts):
    """Newell vectors (twice the vector areas) of rings stored one after the other: ``p``
    (n, 3) their vertices, ``nxt`` (n,) each vertex's next in its ring, ``starts`` (R,)
    each ring's first position. Shape (R, 3); summed in ring order (``np.add.reduceat``)."""
    q = p[nxt]
    d, s = p - q, p + q
    return np.add.reduceat(np.column_stack([d[:, 1] * s[:, 2], d[:, 2] * s[:, 0],
                                            d[:, 0] * s[:, 1]]), starts, axis=0)


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
    out = _fan_or_projection(vertices, rings)
    return out if isinstance(out, np.ndarray) else _delaunay_many([out])[0]


_NO_TRIANGLES = np.zeros((0, 3), dtype=np.int64)


def _fan_or_projection(vertices, rings):
    """A polygon's triangles when it is degenerate, a triangle or a strictly convex ring
    (a fan); else ``(p2, allidx, lens)``: its rings' vertices projected on its plane
    (Newell normal), their indices and the rings' lengths, for :func:`_delaunay_many`."""
    rings = [np.asarray(r, dtype=np.int64) for r in rings]
    ext = rings[0]
    if len(ext) < 3:
        return _NO_TRIANGLES
    n = newell_normal(vertices[ext])
    area2 = np.linalg.norm(n)
    if not np.isfinite(area2) or area2 < 1e-12:
        return _NO_TRIANGLES
    if len(rings) == 1 and len(ext) == 3:
        return ext.reshape(1, 3).copy()
    u, v = plane_basis(n)
    allidx = np.concatenate(rings) if len(rings) > 1 else ext
    p2 = np.column_stack([vertices[allidx] @ u, vertices[allidx] @ v])
    if len(rings) == 1 and _fan_ok(p2):
        k = len(ext)
        return np.column_stack([np.full(k - 2, ext[0]), ext[1:-1], ext[2:]])
    return p2, allidx, [len(r) for r in rings]


def _delaunay_many(items):
    """:func:`_delaunay_batch` of ``items``, ``(p2, allidx, lens)`` of
    :func:`_fan_or_projection`: a list of triangle arrays, one per item."""
    if not items:
        return []
    tris, owner = _delaunay_batch(np.concatenate([it[0] for it in items]),
                                  np.concatenate([it[1] for it in items]),
                                  np.concatenate([it[2] for it in items]),
                                  np.array([len(it[2]) for it in items]))
    return np.split(tris, np.cumsum(np.bincount(owner, minlength=len(items)))[:-1])


def _delaunay_batch(p2, ids, ring_lens, n_rings):
    """GEOS's constrained Delaunay triangles of several projected polygons at once.

    ``p2`` (n, 2) the polygons' ring vertices one after the other, projected on their
    planes, ``ids`` (n,) their vertex indices, ``ring_lens`` each ring's length,
    ``n_rings`` each polygon's ring count (exterior first). One vectorised shapely pass
    over all of them (polygons built, made valid where not, triangulated, triangle
    corners mapped back to vertex indices): the triangles each polygon gets alone,
    without the per-polygon calls. A polygon GEOS fails on gets none, as alone.

    Returns ``(triangles (T, 3), polygon index of each (T,))``, each polygon's in order.
    """
    import shapely

    n_poly = len(n_rings)
    if not n_poly:
        return _NO_TRIANGLES, np.zeros(0, dtype=np.int64)
    ring_of_poly = np.repeat(np.arange(n_poly), n_rings)
    pts_per_poly = np.bincount(ring_of_poly, weights=ring_lens, minlength=n_poly).astype(np.int64)
    try:
        rings = shapely.linearrings(p2, indices=np.repeat(np.arange(len(ring_lens)), ring_lens))
        polys = shapely.polygons(rings, indices=ring_of_poly)
        bad = ~shapely.is_valid(polys)
        if bad.any():
            polys[bad] = shapely.make_valid(polys[bad])
        cdt = shapely.constrained_delaunay_triangles(polys)
    except Exception:  # GEOS failures on degenerate input: each polygon alone
        if n_poly == 1:
            return _NO_TRIANGLES, np.zeros(0, dtype=np.int64)
        pe, re = np.cumsum(pts_per_poly), np.cumsum(n_rings)
        out = [_delaunay_batch(p2[e - n:e], ids[e - n:e], ring_lens[r - m:r], n_rings[k:k + 1])[0]
               for k, (e, n, r, m) in enumerate(zip(pe, pts_per_poly, re, n_rings, strict=True))]
        return (np.concatenate(out),
                np.repeat(np.arange(n_poly), [len(t) for t in out]).astype(np.int64))
    tris, owner = shapely.get_parts(cdt, return_index=True)
    is_tri = shapely.get_type_id(tris) == 3
    tris, owner = tris[is_tri], owner[is_tri]
    coords = shapely.get_coordinates(tris).reshape(len(tris), -1, 2)[:, :3]
    # corners back to vertex indices, each among its own polygon's points
    point_owner = np.repeat(np.arange(n_poly), pts_per_poly)
    out = _vertex_ids(p2, ids, coords.reshape(-1, 2), point_owner,
                      np.repeat(owner, 3)).reshape(len(tris), 3)
    keep = (out[:, 0] != out[:, 1]) & (out[:, 1] != out[:, 2]) & (out[:, 0] != out[:, 2])
    out, c, owner = out[keep], coords[keep], owner[keep]
    signed = ((c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1])
              - (c[:, 2, 0] - c[:, 0, 0]) * (c[:, 1, 1] - c[:, 0, 1]))
    flip = signed < 0
    out[flip] = out[flip][:, ::-1]
    return out, owner.astype(np.int64)


def _vertex_ids(p2, ids, q, p_owner=None, q_owner=None):
    """``ids`` of the points of ``p2`` (n, 2) equal to each query point of ``q`` (m, 2).

    Exact coordinate matches (the last of equal points when several are); a query
    point matching none (make_valid moved it) takes its nearest point (the first
    of equally near ones). With ``p_owner`` (n,) and ``q_owner`` (m,), integer
    labels (a polygon each), a query point is matched among its own polygon's
    points only: the answer of one call per polygon.
    """
    ids = np.asarray(ids, dtype=np.int64)
    if p_owner is None:
        p_owner, q_owner = np.zeros(len(p2), dtype=np.int64), np.zeros(len(q), dtype=np.int64)
    n = len(p2)
    x = np.concatenate([p2[:, 0], q[:, 0]])
    y = np.concatenate([p2[:, 1], q[:, 1]])
    own = np.concatenate([p_owner, q_owner])
    is_query = np.arange(n + len(q)) >= n
    # points and queries in (owner, x, y) order, a query after the points equal to it and
    # equal points in their given order (a stable sort): the point at or before a query is
    # the last one not greater than it, as a right-sided binary search finds it
    order = np.lexsort((is_query, y, x, own))
    last = np.maximum.accumulate(np.where(is_query[order], -1, np.arange(len(order))))
    back = np.empty_like(order)
    back[order] = np.arange(len(order))
    hit = last[back[n:]]
    safe = order[np.maximum(hit, 0)]
    found = ((hit >= 0) & (p_owner[safe] == q_owner) & (p2[safe, 0] == q[:, 0])
             & (p2[safe, 1] == q[:, 1]))
    out = ids[safe]
    for m in np.flatnonzero(~found):
        mine = np.flatnonzero(p_owner == q_owner[m])
        d = np.sum((p2[mine] - q[m]) ** 2, axis=1)
        out[m] = ids[mine[np.argmin(d)]]
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
    if not all_rings:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    # single-ring faces, most of them walls: those clearly convex are fanned in one pass
    # over all of them; the others (and any close call) are fanned or triangulated one by
    # one as triangulate_polygon does it, their Delaunay triangulations in one batch
    single = [i for i, rings in enumerate(all_rings) if len(rings) == 1 and len(rings[0]) >= 3]
    fanned = np.zeros(len(all_rings), dtype=bool)
    chunks, owners = [], []
    if single:
        ext = [np.asarray(all_rings[i][0], dtype=np.int64).reshape(-1) for i in single]
        lens = np.array([len(r) for r in ext])
        idx = np.concatenate(ext)
        fan = _clear_fans(vertices, idx, lens)
        if fan.any():
            k = lens[fan] - 2
            first = np.repeat((np.cumsum(lens) - lens)[fan], k)
            j = first + np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k) + 1
            chunks.append(np.column_stack([idx[first], idx[j], idx[j + 1]]))
            owners.append(np.repeat(np.asarray(single)[fan], k))
            fanned[np.asarray(single)[fan]] = True
    # the other single-ring faces, by ring length; then the faces with holes (or fewer
    # than 3 vertices) one by one; every Delaunay triangulation in one batch
    batch: list = [[], [], [], [], []]  # p2, ids, ring lengths, ring counts, face
    _single_rings(vertices, {i: ext[j] for j, i in enumerate(single) if not fanned[i]},
                  chunks, owners, batch)
    for i in np.flatnonzero(~fanned):
        if len(all_rings[i]) == 1 and len(all_rings[i][0]) >= 3:
            continue
        t = _fan_or_projection(vertices, all_rings[i])
        if isinstance(t, np.ndarray):
            chunks.append(t)
            owners.append(np.full(len(t), i, dtype=np.int64))
        else:
            for part, x in zip(batch, (t[0], t[1], t[2], [len(t[2])], [i]), strict=True):
                part.append(np.asarray(x))
    if batch[0]:
        t, poly = _delaunay_batch(*(np.concatenate(x) for x in batch[:4]))
        chunks.append(t)
        owners.append(np.concatenate(batch[4])[poly])
    tris = np.concatenate(chunks) if chunks else np.zeros((0, 3), dtype=np.int64)
    face = np.concatenate(owners) if owners else np.zeros(0, dtype=np.int64)
    order = np.argsort(face, kind="stable")  # by face, each face's triangles in their order
    return tris[order], face[order]


def _single_rings(vertices, exts, chunks, owners, batch):
    """:func:`_fan_or_projection` of single-ring faces ``{face: ring}``, vectorised over
    the rings of each length with the same arithmetic (the same floating-point results
    as one call per ring). Fans are appended to ``chunks`` (triangles) and ``owners``
    (their faces), projections to ``batch`` (p2, ids, ring lengths, ring counts, faces)."""
    by_len: dict[int, list] = {}
    for i, r in exts.items():
        by_len.setdefault(len(r), []).append(i)
    for k, faces in by_len.items():
        if k == 3:  # near-degenerate triangles (the clear ones are fanned already)
            for i in faces:
                t = _fan_or_projection(vertices, [exts[i]])
                chunks.append(t)
                owners.append(np.full(len(t), i, dtype=np.int64))
            continue
        faces = np.asarray(faces)
        ext = np.stack([exts[i] for i in faces])
        p = vertices[ext]                                  # (F, k, 3)
        q = np.concatenate([p[:, 1:], p[:, :1]], axis=1)
        d, s = p - q, p + q
        n = np.stack([np.sum(d[..., 1] * s[..., 2], axis=1), np.sum(d[..., 2] * s[..., 0], axis=1),
                      np.sum(d[..., 0] * s[..., 1], axis=1)], axis=1)
        area2 = np.sqrt(dot3(n, n))
        ok = np.isfinite(area2) & (area2 >= 1e-12)
        u, v = plane_bases(np.where(ok[:, None], n, 1.0))
        # stacked products: per ring the floating-point result of ``p[j] @ u[j]``
        p2 = np.stack([np.matmul(p, u[:, :, None])[..., 0], np.matmul(p, v[:, :, None])[..., 0]],
                      axis=-1)
        d1 = np.concatenate([p2[:, 1:], p2[:, :1]], axis=1) - p2
        d2 = np.concatenate([d1[:, 1:], d1[:, :1]], axis=1)
        fan = ok & np.all(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0] > 0, axis=1)
        if fan.any():
            e = ext[fan]
            chunks.append(np.stack([np.repeat(e[:, :1], k - 2, axis=1), e[:, 1:-1], e[:, 2:]],
                                   axis=-1).reshape(-1, 3))
            owners.append(np.repeat(faces[fan], k - 2))
        cdt = ok & ~fan
        if cdt.any():
            m = int(cdt.sum())
            for part, x in zip(batch, (p2[cdt].reshape(-1, 2), ext[cdt].ravel(), np.full(m, k),
                                       np.ones(m, dtype=np.int64), faces[cdt]), strict=True):
                part.append(x)


def _clear_fans(vertices, idx, lens):
    """Which rings :func:`triangulate_polygon` surely fans: ``idx`` the rings' vertex
    indices one after the other, ``lens`` (R,) their lengths (each >= 3).

    A ring is fanned there when its area is not negligible and it is strictly
    convex in its plane (or a triangle). Here only rings whose every turn is
    convex by a margin far above rounding (sine of the turn > 1e-6, area well
    above the threshold) count, so the answer is the one the per-face test
    gives; rings near a straight angle are left to that test.
    """
    starts = np.cumsum(lens) - lens
    nxt = np.arange(len(idx)) + 1
    nxt[starts + lens - 1] = starts
    p = vertices[idx]
    n = ragged_newell(p, nxt, starts)
    area2 = np.sqrt(dot3(n, n))
    ok = np.isfinite(area2) & (area2 > 1e-9)
    u, v = plane_bases(np.where(ok[:, None], n, 1.0))
    ring = np.repeat(np.arange(len(lens)), lens)
    p2 = np.column_stack([dot3(p, u[ring]), dot3(p, v[ring])])
    d1 = p2[nxt] - p2
    d2 = d1[nxt]
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    el = np.sqrt(np.sum(d1 * d1, axis=1))
    convex = cross > 1e-6 * el * el[nxt]
    return ok & ((lens == 3) | np.logical_and.reduceat(convex, starts))


_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

#: the last solids meshed, newest last: ``[surfaces, vertices, ring indices, ring lengths,
#: rings per surface, mesh]``; a solid with the same surfaces list and a few vertices moved
#: (a vertex nudged on the output grid) re-triangulates only the surfaces using them
_RECENT: list = []
_RECENT_SIZE = 4
#: the largest share of vertices moved for which the surfaces are re-triangulated alone
_REMESH_SHARE = 0.25


def solid_mesh(solid) -> tuple[np.ndarray, np.ndarray]:
    """:func:`triangulate_surfaces` of a solid, computed once per solid object.

    Solids are treated as immutable (their dataclass is frozen): the cache is
    keyed by the object and dropped with it. A solid sharing its surfaces list (and
    rings) with one of the last solids meshed, with a few vertices moved, reuses that
    mesh: only the surfaces using a moved vertex are triangulated again. Each surface's
    triangles depend on its own vertices only, so the mesh is the one of the whole
    solid triangulated anew.
    """
    try:
        return _CACHE[solid]
    except (KeyError, TypeError):
        pass
    out, layout = _remesh(solid)
    if out is None:
        out = triangulate_surfaces(solid.vertices, solid.surfaces)
    try:
        _CACHE[solid] = out
    except TypeError:
        pass
    if isinstance(solid.surfaces, list):
        _RECENT.append([solid.surfaces, np.array(solid.vertices, dtype=np.float64), layout, out])
        del _RECENT[:-_RECENT_SIZE]
    return out


def _surface_layout(surfaces):
    """The rings of ``surfaces`` as ``(indices, ring lengths, rings per surface)``, or None
    when a ring is not a flat integer array (then no mesh is reused)."""
    all_rings = [s.rings if hasattr(s, "rings") else s for s in surfaces]
    rings = [r for rs in all_rings for r in rs]
    if not rings or not all(isinstance(r, np.ndarray) and r.ndim == 1 and r.dtype.kind in "iu"
                            for r in rings):
        return None
    return (np.concatenate(rings).astype(np.int64, copy=False),
            np.fromiter(map(len, rings), dtype=np.int64, count=len(rings)),
            np.fromiter(map(len, all_rings), dtype=np.int64, count=len(all_rings)))


def _remesh(solid):
    """``(mesh, layout)``: the mesh of ``solid`` from a recent one with the same surfaces
    (None when there is none or too many vertices moved) and its surfaces' layout
    (:func:`_surface_layout`, None when not taken)."""
    verts = np.asarray(solid.vertices, dtype=np.float64)
    for entry in reversed(_RECENT):
        surfaces, old, layout, mesh = entry
        if surfaces is not solid.surfaces or old.shape != verts.shape or not len(verts):
            continue
        # bit-wise comparison: a vertex is moved unless its bytes are the same
        moved = np.flatnonzero(np.any(verts.view(np.int64) != old.view(np.int64), axis=1))
        if len(moved) > _REMESH_SHARE * len(verts):
            return None, None
        if layout is None:
            layout = entry[2] = _surface_layout(surfaces)
        now = _surface_layout(solid.surfaces)  # the rings as they are (lists are mutable)
        if layout is None or now is None or any(
                not np.array_equal(a, b) for a, b in zip(layout, now, strict=True)):
            return None, now
        idx, lens, n_rings = layout
        if not len(moved):
            return mesh, layout
        if idx.max() >= len(verts):
            return None, layout
        ring_face = np.repeat(np.arange(len(n_rings)), n_rings)
        hit = np.zeros(len(verts), dtype=bool)
        hit[moved] = True
        touched = np.unique(ring_face[np.repeat(np.arange(len(lens)), lens)[hit[idx]]])
        tris, face = mesh
        keep = ~np.isin(face, touched)
        new_t, new_f = triangulate_surfaces(verts, [solid.surfaces[f] for f in touched.tolist()])
        tris = np.concatenate([tris[keep], new_t])
        face = np.concatenate([face[keep], touched[new_f]])
        order = np.argsort(face, kind="stable")  # by face, each face's triangles in their order
        return (tris[order], face[order]), layout
    return None, None


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
