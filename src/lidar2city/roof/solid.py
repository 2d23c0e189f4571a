"""A closed LoD2.2 solid from a roof partition: roof faces on their planes, walls, floor.

Each face of a planar partition of the footprint carries a plane. Roof surfaces
are the faces lifted onto their planes; where two adjacent faces are at
different heights along their shared edge a vertical wall closes the gap (a
step edge); the footprint boundary gets walls down to the ground; the floor is
the footprint at ground height. Every vertical edge is split at every height
level present at its vertex, so the shell is closed and 2-manifold, and every
surface is planar by construction.
"""

from __future__ import annotations

import numpy as np

from ..datamodel import Solid, Surface
from ..errors import FitError

__all__ = ["on_grid", "partition_solid", "split_crossings", "split_saddles"]

_KEY = 1e6  # vertex keys: coordinates rounded to a micrometre


def on_grid(solid, precision):
    """``solid`` with its vertices rounded to multiples of ``precision`` metres (the output's
    CityJSON quantisation), so that the solid validated is the one written; ``solid``
    itself when ``precision`` is 0 or None."""
    if not precision:
        return solid
    return Solid(np.round(solid.vertices / precision) * precision, solid.surfaces)


def _key(p):
    return (int(round(p[0] * _KEY)), int(round(p[1] * _KEY)))


def _ring_keys(r) -> list:
    """:func:`_key` of every vertex of a ring, vectorised (same rounding: half to even)."""
    return list(map(tuple, np.rint(np.asarray(r)[:, :2] * _KEY).astype(np.int64).tolist()))


def _rings(poly):
    """Exterior counter-clockwise then holes clockwise, as (m, 2) arrays without closing vertex."""
    from shapely.geometry.polygon import orient

    poly = orient(poly, 1.0)
    out = [np.asarray(poly.exterior.coords)[:-1, :2]]
    out += [np.asarray(r.coords)[:-1, :2] for r in poly.interiors]
    return out


def _z(plane, p):
    return plane[0] * p[0] + plane[1] * p[1] + plane[2]


def _edge_owner(rings_per_face, keys_per_face=None) -> dict:
    """Directed edge ``(key(p), key(q))`` -> index of the face whose ring runs p -> q."""
    if keys_per_face is None:
        keys_per_face = [[_ring_keys(r) for r in rs] for rs in rings_per_face]
    owner = {}
    for fi, ks in enumerate(keys_per_face):
        for k in ks:
            owner.update(zip(zip(k, k[1:] + k[:1]), [fi] * len(k)))
    return owner


def conform(rings_per_face, *, tol=1e-3):
    """Insert every partition vertex lying on another face's edge into that edge (no T-junctions).

    Faces merged or snapped separately can disagree on how a shared boundary is
    subdivided; a solid needs each edge shared exactly.
    """
    import shapely

    rings = [r for rs in rings_per_face for r in rs]
    allp = np.concatenate(rings)
    allp = allp[np.lexsort((allp[:, 1], allp[:, 0]))]
    pts = allp[np.r_[True, np.any(allp[1:] != allp[:-1], axis=1)]]  # np.unique(axis=0)
    tree = shapely.STRtree(shapely.points(pts))
    # every directed edge p -> q of every ring, in ring order
    P = np.concatenate(rings)
    Q = np.concatenate([np.concatenate([r[1:], r[:1]]) for r in rings])
    lo, hi = np.minimum(P, Q) - tol, np.maximum(P, Q) + tol
    # candidates: points in the edge's box grown by tol (a superset of its tol-buffer),
    # then the exact test below
    e, c = tree.query(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
    d = Q - P
    L2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    keep = L2[e] != 0
    e, c = e[keep], c[keep]
    cp, de, pe, qe = pts[c], d[e], P[e], Q[e]
    t = ((cp[:, 0] - pe[:, 0]) * de[:, 0] + (cp[:, 1] - pe[:, 1]) * de[:, 1]) / L2[e]
    cross = (cp[:, 0] - pe[:, 0]) * de[:, 1] - (cp[:, 1] - pe[:, 1]) * de[:, 0]
    dist = np.abs(cross) / np.sqrt(L2[e])
    ends = np.minimum(np.hypot(*(cp - pe).T), np.hypot(*(cp - qe).T))
    on = (t > 0) & (t < 1) & (dist < tol) & (ends > tol)
    e, cp, t = e[on], cp[on], t[on]
    order = np.lexsort((t, e))
    inserts: dict = {}
    for i, x in zip(e[order].tolist(), cp[order], strict=True):
        inserts.setdefault(i, []).append(x)
    return _insert_at(rings_per_face, inserts)


def _insert_at(rings_per_face, inserts: dict):
    """The rings with ``inserts[i]`` (points in order) added inside the i-th edge (edges
    numbered through all rings of all faces in order)."""
    if not inserts:
        return [list(rs) for rs in rings_per_face]
    out = []
    i = 0
    for rs in rings_per_face:
        new_rs = []
        for r in rs:
            seq = []
            for k in range(len(r)):
                seq.append(r[k])
                seq.extend(inserts.get(i + k, ()))
            i += len(r)
            new_rs.append(np.asarray(seq))
        out.append(new_rs)
    return out


def split_crossings(faces, planes, *, tol=5e-3, min_gap=2e-3, grid=1e-3):
    """Insert a vertex where two adjacent faces' planes cross along their shared edge.

    A wall between two faces is only a simple polygon when one face stays above
    the other along the whole edge.

    Parameters
    ----------
    faces : list of shapely Polygon
    planes : ndarray, shape (len(faces), 3)
        The plane of each face.
    tol : float
        Height differences below this (m) count as equal (the solid's level tolerance).
    min_gap : float
        No vertex is inserted closer than this (m) to an edge's end.
    grid : float
        Inserted vertices are snapped to this grid (m), the output's precision.

    Returns
    -------
    list of list of ndarray
        Rings per face (exterior counter-clockwise first) with crossing vertices inserted.
    """
    rings = conform([_rings(f) for f in faces])
    keys = [[_ring_keys(r) for r in rs] for rs in rings]
    owner = _edge_owner(rings, keys)
    inserts = {}
    for fi, rs in enumerate(rings):
        for r, ks in zip(rs, keys[fi], strict=True):
            zf = planes[fi, 0] * r[:, 0] + planes[fi, 1] * r[:, 1] + planes[fi, 2]
            m = len(r)
            for k in range(m):
                kp, kq = ks[k], ks[(k + 1) % m]
                g = owner.get((kq, kp))
                if g is None or g < fi:
                    continue
                p, q = r[k], r[(k + 1) % m]
                dp = zf[k] - _z(planes[g], p)
                dq = zf[(k + 1) % m] - _z(planes[g], q)
                if (dp > tol and dq < -tol) or (dp < -tol and dq > tol):
                    t = dp / (dp - dq)
                    x = p + t * (q - p)
                    if min(np.hypot(*(x - p)), np.hypot(*(x - q))) < min_gap:
                        continue  # the levels at that end merge instead
                    x = np.round(x / grid) * grid  # on the output grid, as the faces are
                    inserts[(kp, kq)] = x
                    inserts[(kq, kp)] = x
    if not inserts:
        return rings
    at = {}
    i = 0
    for ks_face in keys:
        for ks in ks_face:
            m = len(ks)
            for k in range(m):
                x = inserts.get((ks[k], ks[(k + 1) % m]))
                if x is not None:
                    at[i + k] = [x]
            i += m
    return _insert_at(rings, at)


def split_saddles(faces, points, *, radius=0.05, grid=5e-3):
    """Replace each saddle vertex by a tiny patch of one face, so that only three faces meet.

    Where four or more faces (the outside counting as one, at ground height)
    meet at a vertex with heights alternating around it (high, low, high,
    low), every wall between them rises along the same vertical edge: the
    shell is not 2-manifold there, whatever the planes. Cut a small square
    (half-diagonal ``radius``, less near other vertices) around the vertex out
    of every face touching it and give it to the largest of them, or, on the
    footprint's outline, to none (a notch): each vertex left on the square's
    outline then touches at most three faces (two neighbours and the patch or
    the outside), and around three faces the heights cannot alternate. Roof
    planes are unchanged; the geometry moves by less than ``radius``.

    Parameters
    ----------
    faces : list of shapely Polygon
        A partition (vertices on the ``grid``).
    points : ndarray, shape (M, 2)
        The saddle vertices.
    radius : float
        Largest half-diagonal (m) of the square cut out.
    grid : float
        The changed faces are snapped to this grid (m), as the partition is.

    Returns
    -------
    list of shapely Polygon
        The faces, in the same order; a saddle where the cut would break a face
        into pieces or leave the square smaller than two grid steps is left as it is.
    """
    import shapely

    faces = list(faces)
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 2):
        pt = shapely.Point(p)
        at = [i for i, f in enumerate(faces) if f.distance(pt) < 1e-6]
        if len(at) < 2:
            continue
        xy = shapely.get_coordinates([faces[i] for i in at])
        d = np.hypot(*(xy - p).T)
        d = d[d > 1e-6]
        r = min(radius, float(d.min()) / 3) if len(d) else radius
        r = np.floor(r / grid) * grid
        if r < 2 * grid:
            continue
        square = pt.buffer(r, quad_segs=1)
        pieces = [faces[i].intersection(square) for i in at]
        new = {i: shapely.set_precision(faces[i].difference(square), grid) for i in at}
        if sum(g.area for g in pieces) > 0.99 * square.area:
            keep = max(at, key=lambda i: (faces[i].area, -i))
            new[keep] = shapely.set_precision(shapely.union(faces[keep], shapely.union_all(pieces)), grid)
        # else the vertex is on the outline: the square is left out of every face (a notch)
        if all(g.geom_type == "Polygon" and not g.is_empty for g in new.values()):
            for i, g in new.items():
                faces[i] = g
    return faces


def partition_solid(faces, planes, ground_z, *, min_height=0.2, level_tol=5e-3) -> Solid:
    """Build the closed solid of a roof partition.

    Parameters
    ----------
    faces : list of shapely Polygon
        A partition of the footprint (shared edges with identical vertices).
    planes : ndarray, shape (len(faces), 3)
        Plane ``(a, b, c)`` of each face.
    ground_z : float
        Floor height (m).
    min_height : float
        A roof lower than ``ground_z + min_height`` anywhere is an error.
    level_tol : float
        Heights at one vertex closer than this are the same level.

    Returns
    -------
    Solid
        RoofSurface per face, WallSurface per wall piece, one GroundSurface.

    Raises
    ------
    FitError
        When a roof plane goes below the floor.
    """
    planes = np.asarray(planes, dtype=np.float64)
    rings = split_crossings(faces, planes, tol=level_tol)
    # heights of every face at its vertices
    keys = [[_ring_keys(r) for r in rs] for rs in rings]
    levels: dict = {}
    zs_face = []
    for fi, rs in enumerate(rings):
        zs_face.append([])
        for r, ks in zip(rs, keys[fi], strict=True):
            z = planes[fi, 0] * r[:, 0] + planes[fi, 1] * r[:, 1] + planes[fi, 2]
            if np.any(z < ground_z + min_height):
                raise FitError(f"roof plane {fi} goes below the floor ({z.min():.2f} < {ground_z:.2f} + {min_height})")
            zs_face[fi].append(z)
            for k, zz in zip(ks, z, strict=True):
                levels.setdefault(k, []).append(zz)
    # directed edges and which face uses them
    owner = _edge_owner(rings, keys)
    outer_edges = [e for e in owner if (e[1], e[0]) not in owner]
    for e in outer_edges:
        levels[e[0]].append(ground_z)
        levels[e[1]].append(ground_z)
    # unify levels per vertex
    xy_of = {}
    for rs, ks_face in zip(rings, keys, strict=True):
        for r, ks in zip(rs, ks_face, strict=True):
            xy_of.update(zip(ks, r))
    level_sets = _level_sets(levels, level_tol)

    verts: list = []
    index: dict = {}
    level_lists = {k: v.tolist() for k, v in level_sets.items()}

    def level_index(k, z):
        """Index of the level at vertex k nearest to z (the first of equals)."""
        zs = level_lists[k]
        if len(zs) == 1:
            return 0
        best, bj = abs(zs[0] - z), 0
        for j in range(1, len(zs)):
            d = abs(zs[j] - z)
            if d < best:
                best, bj = d, j
        return bj

    def vid_at(k, zi):
        key = (k, zi)
        i = index.get(key)
        if i is None:
            i = index[key] = len(verts)
            p = xy_of[k]
            verts.append((p[0], p[1], level_lists[k][zi]))
        return i

    def vid(k, z):
        zi = level_index(k, z)
        return vid_at(k, zi), zi

    surfaces = []
    # roofs
    for fi, rs in enumerate(rings):
        ids = []
        for ks, z in zip(keys[fi], zs_face[fi], strict=True):
            ids.append(np.asarray([vid(k, zz)[0] for k, zz in zip(ks, z, strict=True)]))
        surfaces.append(Surface(ids, "RoofSurface"))

    def stack(k, lo, hi):
        """Vertex ids at vertex k from level index lo to hi inclusive (ascending or descending)."""
        step = 1 if hi >= lo else -1
        return [vid_at(k, j) for j in range(lo, hi + step, step)]

    # walls: each directed edge (p -> q) of face f whose other side is lower (or outside)
    for (kp, kq), fi in owner.items():
        other = owner.get((kq, kp))
        p, q = xy_of[kp], xy_of[kq]
        zf_p, zf_q = level_index(kp, _z(planes[fi], p)), level_index(kq, _z(planes[fi], q))
        if other is None:
            zo_p, zo_q = level_index(kp, ground_z), level_index(kq, ground_z)
        else:
            zo_p = level_index(kp, _z(planes[other], p))
            zo_q = level_index(kq, _z(planes[other], q))
        # the wall belongs to the higher side (crossings were split away)
        if zf_p < zo_p or zf_q < zo_q or (zf_p == zo_p and zf_q == zo_q):
            continue
        # seen from the lower side, the wall runs p(top) -> ... ; build: bottom p->q, up q, top q->p, down p
        ring = stack(kq, zo_q, zf_q)  # up along q
        ring += stack(kp, zf_p, zo_p)  # down along p
        # the face's edge p -> q runs counter-clockwise around f (f on the left); the wall's
        # outward normal points to the right of p -> q (towards the lower side): order
        # q(bottom..top), p(top..bottom) is counter-clockwise seen from there.
        ring = _dedupe(ring)
        if len(ring) >= 3:
            surfaces.append(Surface([np.asarray(ring)], "WallSurface"))
    # floor: the polygons the outer edges enclose (pinched outlines give several), facing down
    import shapely
    from shapely.geometry import LineString
    from shapely.geometry.polygon import orient

    lines = [LineString([xy_of[kp], xy_of[kq]]) for kp, kq in outer_edges]
    inside = shapely.union_all([shapely.Polygon(rs[0], rs[1:]) for rs in rings]).buffer(1e-7)
    floors = []
    for poly in shapely.get_parts(shapely.polygonize(lines)):
        if poly.area < 1e-3 * poly.length or not inside.contains(poly.representative_point()):
            continue  # the inside of a courtyard, or a zero-width loop of outline edges
        poly = orient(poly, -1.0)  # clockwise from above: the normal points down
        ids = [[vid(_key(p), ground_z)[0] for p in np.asarray(r.coords)[:-1]]
               for r in [poly.exterior, *poly.interiors]]
        floors.append(Surface([np.asarray(r) for r in ids], "GroundSurface"))
    surfaces[:0] = floors
    return Solid(np.asarray(verts), surfaces)


def _level_sets(levels: dict, tol: float) -> dict:
    """Per vertex key, its heights sorted and grouped where consecutive ones differ by more
    than ``tol``, each group replaced by its mean: all vertices at once (sorted by key,
    then height), bit for bit as ``np.mean`` of each group."""
    keys = list(levels)
    if not keys:
        return {}
    counts = np.fromiter((len(levels[k]) for k in keys), dtype=np.int64, count=len(keys))
    owner = np.repeat(np.arange(len(keys)), counts)
    z = np.fromiter((v for k in keys for v in levels[k]), dtype=np.float64, count=int(counts.sum()))
    order = np.lexsort((z, owner))
    z, owner = z[order], owner[order]
    new = np.r_[True, (owner[1:] != owner[:-1]) | (np.diff(z) > tol)]
    starts = np.flatnonzero(new)
    sizes = np.diff(np.r_[starts, len(z)])
    means = np.empty(len(starts))
    for m in np.unique(sizes):  # groups of one size as rows: a row sum is np.mean's sum
        sel = np.flatnonzero(sizes == m)
        means[sel] = z[starts[sel, None] + np.arange(m)].sum(axis=1) / m
    per_key = np.searchsorted(owner[starts], np.arange(len(keys) + 1))
    return {k: means[per_key[i]:per_key[i + 1]] for i, k in enumerate(keys)}


def _dedupe(ring):
    out = []
    for i in ring:
        if not out or out[-1] != i:
            out.append(i)
    if len(out) > 1 and out[0] == out[-1]:
        out.pop()
    return out
