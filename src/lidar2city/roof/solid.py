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

__all__ = ["nudge_on_grid", "on_grid", "partition_edges", "partition_solid", "split_crossings",
           "split_saddles"]

_KEY = 1e6  # vertex keys: coordinates rounded to a micrometre


def on_grid(solid, precision):
    """``solid`` with its vertices rounded to multiples of ``precision`` metres (the output's
    CityJSON quantisation), so that the solid validated is the one written; ``solid``
    itself when ``precision`` is 0 or None."""
    if not precision:
        return solid
    return Solid(np.round(solid.vertices / precision) * precision, solid.surfaces)


#: the grid steps a vertex is moved by, in the order tried, by :func:`nudge_on_grid`
_NUDGES = ((1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (-1, 1), (-1, -1), (1, -1))


def _crossing_pairs(issues):
    """``(count, (a, b))``: how many face pairs the lone 306 issue of ``issues`` reports
    and the first of them; None for anything else."""
    if len(issues) != 1 or issues[0].code != 306:
        return None
    # "N intersecting face pair(s): a-b, ..."
    try:
        head, pairs = issues[0].detail.split(": ", 1)
        a, b = (int(s) for s in pairs.split(",")[0].split("-"))
        return int(head.split()[0]), (a, b)
    except (IndexError, ValueError):
        return None


def nudge_on_grid(solid, issues, precision, *, max_checks=12, max_pairs=8):
    """Repair a solid on the output grid whose only error is faces crossing (306).

    Rounding to ``precision`` moves a vertex inserted where two roof planes
    cross (:func:`split_crossings`) off the straight edge the two faces share, by
    a fraction of a grid step; the face bent inward can then be triangulated
    across the bend and cut the other face in a sliver. Moving a vertex the two
    faces share by one grid step (in a fixed order: the 4 axis steps, then the
    diagonals, each tried on every shared vertex) bends that edge the other way.
    The crossing pairs are taken one at a time, the first one reported first: a
    move is kept when :func:`~lidar2city.validate.solid.check_solid` then finds
    nothing, or only crossings, fewer pairs of them (a large roof can have a
    crossing vertex rounded off its edge in several places); the next pair is then
    nudged on the moved solid. Each move is one grid step, far below the planarity
    tolerance.

    Parameters
    ----------
    solid : Solid
        Vertices already on the grid.
    issues : list of Issue
        Its ``check_solid`` issues.
    precision : float
        The grid step (m).
    max_checks : int
        Most full checks tried per crossing pair.
    max_pairs : int
        Most crossing pairs repaired: a solid reporting more is left as it is.

    Returns
    -------
    (Solid, list of Issue)
        The moved solid and no issue, or ``solid`` and ``issues`` unchanged.
    """
    from ..validate.solid import check_solid

    found = _crossing_pairs(issues) if precision else None
    if found is None or found[0] > max_pairs:
        return solid, issues
    out = solid  # the solid with the pairs mended so far (kept only once all are)
    while found is not None:
        count, (a, b) = found
        if max(a, b) >= len(out.surfaces):
            break
        ids = [np.concatenate([np.asarray(r, dtype=np.int64).ravel() for r in out.surfaces[f].rings])
               for f in (a, b)]
        shared = np.intersect1d(ids[0], ids[1]).tolist()
        moves = [(dx, dy, v) for dx, dy in _NUDGES for v in shared][:max_checks]
        for dx, dy, v in moves:  # each step tried on every shared vertex before the next step
            moved = np.array(out.vertices, copy=True)
            moved[v, 0] = np.round(moved[v, 0] / precision + dx) * precision
            moved[v, 1] = np.round(moved[v, 1] / precision + dy) * precision
            now = check_solid(Solid(moved, out.surfaces))
            if not now:
                return Solid(moved, out.surfaces), []
            fewer = _crossing_pairs(now)
            if fewer is not None and fewer[0] < count:
                out, found = Solid(moved, out.surfaces), fewer
                break
        else:
            break
    return solid, issues


def _key(p):
    return (int(round(p[0] * _KEY)), int(round(p[1] * _KEY)))


def _ring_keys(r) -> list:
    """:func:`_key` of every vertex of a ring, vectorised (same rounding: half to even)."""
    return list(map(tuple, np.rint(np.asarray(r)[:, :2] * _KEY).astype(np.int64).tolist()))


def _face_rings(faces) -> list:
    """Every face's rings, exterior counter-clockwise then holes clockwise, as (m, 2) arrays
    without the closing vertex; the orientation and coordinates of all faces taken at once."""
    import shapely

    if not len(faces):
        return []
    oriented = shapely.orient_polygons(np.asarray(faces, dtype=object))
    rings, ring_face = shapely.get_rings(oriented, return_index=True)
    xy, ring_of = shapely.get_coordinates(rings, return_index=True)
    ends = np.cumsum(np.bincount(ring_of, minlength=len(rings)))
    per_ring = np.split(xy, ends[:-1])
    out = [[] for _ in range(len(faces))]
    for f, r in zip(ring_face.tolist(), per_ring, strict=True):
        out[f].append(r[:-1])
    return out


def _z(plane, p):
    return plane[0] * p[0] + plane[1] * p[1] + plane[2]


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
    at = np.array(sorted(inserts), dtype=np.int64)
    flat = list(map(np.asarray, (r for rs in rings_per_face for r in rs)))
    sizes = np.fromiter(map(len, flat), dtype=np.int64, count=len(flat))
    ends = np.cumsum(sizes)
    # the insertions of each ring that gets any: at[lo:hi]; only those rings are rebuilt
    ring_of = np.searchsorted(ends, at, side="right")
    hit, lo = np.unique(ring_of, return_index=True)
    first_edge = (ends - sizes)[hit].tolist()
    for ring, i, a, b in zip(hit.tolist(), first_edge, lo.tolist(), [*lo[1:].tolist(), len(at)],
                             strict=True):
        r = flat[ring]
        seq, k0 = [], 0
        for e in at[a:b].tolist():
            k = e - i
            seq.append(np.asarray(r[k0:k + 1]).reshape(-1, 2))
            seq.append(np.asarray(inserts[e]).reshape(-1, 2))
            k0 = k + 1
        seq.append(np.asarray(r[k0:]).reshape(-1, 2))
        flat[ring] = np.concatenate(seq)
    out, start = [], 0
    for rs in rings_per_face:
        out.append(flat[start:start + len(rs)])
        start += len(rs)
    return out


def _directed_edges(kid, sizes, face, nk):
    """The directed edges p -> q of rings given as vertex ids ``kid`` (one ring after the
    other, ``sizes`` their lengths, ``face`` each vertex's face, ``nk`` the number of ids),
    each once, in the order they first occur: ``(p, q, face, other)``, ``face`` the last
    face running it, ``other`` the last one running q -> p (-1: none). As a dict
    ``{(p, q): face}`` filled ring after ring would hold them (its keys in order, their
    values, each key's twin's value), in array form."""
    ends = np.cumsum(sizes)
    nxt = np.arange(1, len(kid) + 1)
    nxt[ends - 1] = ends - sizes  # a ring's last vertex -> its first
    code = kid * nk + kid[nxt]
    uc, first, inv = np.unique(code, return_index=True, return_inverse=True)
    last = np.full(len(uc), -1, dtype=np.int64)
    np.maximum.at(last, inv.ravel(), np.arange(len(code)))
    order = np.argsort(first, kind="stable")
    uc, last = uc[order], last[order]
    p, q = uc // nk, uc % nk
    # the twin's place among the sorted codes
    srt = np.argsort(uc)
    twin = q * nk + p
    pos = np.minimum(np.searchsorted(uc[srt], twin), len(uc) - 1)
    has = uc[srt][pos] == twin
    other = np.where(has, face[last[srt][pos]], -1)
    return p, q, face[last], other


def _key_groups(key):
    """``(order, new, group)`` of integer key rows (n, 2): their stable order by x then y,
    whether each row in that order starts a new key, and each row's key rank (the
    inverse of ``np.unique(key, axis=0)``)."""
    srt = np.lexsort((key[:, 1], key[:, 0]))
    ks = key[srt]
    new = np.ones(len(ks), dtype=bool)
    new[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    group = np.empty(len(srt), dtype=np.int64)
    group[srt] = np.cumsum(new) - 1
    return srt, new, group


def partition_edges(faces) -> tuple:
    """The faces' rings made conforming (:func:`conform`) and their directed edges: per ring
    vertex its face, position, next vertex, edge code p -> q, the twin's code and the face
    on the other side (-1: the outside). What :func:`split_crossings` needs of the faces
    (not of their planes)."""
    rings = conform(_face_rings(faces))
    flat = [r for rs in rings for r in rs]
    sizes = np.array([len(r) for r in flat], dtype=np.int64)
    fv = np.repeat(np.repeat(np.arange(len(rings)), [len(rs) for rs in rings]), sizes)
    xy = np.concatenate(flat)[:, :2]
    m = len(xy)
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    nxt = np.arange(1, m + 1)
    nxt[np.cumsum(sizes) - 1] = start[np.cumsum(sizes) - 1]  # each ring's last vertex -> its first
    # vertex ids by their keys' rank in (x, y) order (np.unique of the rows' inverse)
    kid = _key_groups(np.rint(xy * _KEY).astype(np.int64))[2]
    nk = int(kid.max()) + 1
    code = kid * nk + kid[nxt]  # directed edge p -> q
    twin = kid[nxt] * nk + kid
    # the face owning each directed edge: the last ring running it (as a dict filled in order)
    uc, inv = np.unique(code, return_inverse=True)
    last = np.full(len(uc), -1, dtype=np.int64)
    np.maximum.at(last, inv.ravel(), np.arange(m))
    pos = np.minimum(np.searchsorted(uc, twin), len(uc) - 1)
    g = np.where(uc[pos] == twin, fv[last[pos]], -1)
    return rings, fv, xy, nxt, code, twin, g


def split_crossings(faces, planes, *, tol=5e-3, min_gap=2e-3, grid=1e-3, edges=None):
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
    edges : tuple, optional
        :func:`partition_edges` of ``faces`` when already taken (it does not depend on
        the planes: a partition rebuilt with other planes reuses it).

    Returns
    -------
    list of list of ndarray
        Rings per face (exterior counter-clockwise first) with crossing vertices inserted.
    """
    rings, fv, xy, nxt, code, twin, g = edges if edges is not None else partition_edges(faces)
    zf = planes[fv, 0] * xy[:, 0] + planes[fv, 1] * xy[:, 1] + planes[fv, 2]
    gg = np.maximum(g, 0)
    p, q = xy, xy[nxt]
    dp = zf - (planes[gg, 0] * p[:, 0] + planes[gg, 1] * p[:, 1] + planes[gg, 2])
    dq = zf[nxt] - (planes[gg, 0] * q[:, 0] + planes[gg, 1] * q[:, 1] + planes[gg, 2])
    cross = (g >= fv) & (((dp > tol) & (dq < -tol)) | ((dp < -tol) & (dq > tol)))
    inserts = {}
    for i in np.flatnonzero(cross).tolist():  # in ring order: a later edge's point wins
        t = dp[i] / (dp[i] - dq[i])
        x = p[i] + t * (q[i] - p[i])
        if min(np.hypot(*(x - p[i])), np.hypot(*(x - q[i]))) < min_gap:
            continue  # the levels at that end merge instead
        x = np.round(x / grid) * grid  # on the output grid, as the faces are
        inserts[int(code[i])] = x
        inserts[int(twin[i])] = x
    if not inserts:
        return rings
    hit = np.flatnonzero(np.isin(code, np.fromiter(inserts, dtype=np.int64, count=len(inserts))))
    return _insert_at(rings, {i: [inserts[int(code[i])]] for i in hit.tolist()})


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
    # each face's box, kept beside it: the exact distance is only taken for the faces
    # whose box grown by 2e-6 holds the vertex (the rest are farther than 1e-6)
    boxes = shapely.bounds(np.asarray(faces, dtype=object)).reshape(-1, 4)
    for p in np.asarray(points, dtype=np.float64).reshape(-1, 2):
        pt = shapely.Point(p)
        near = np.flatnonzero((boxes[:, 0] - 2e-6 <= p[0]) & (p[0] <= boxes[:, 2] + 2e-6)
                              & (boxes[:, 1] - 2e-6 <= p[1]) & (p[1] <= boxes[:, 3] + 2e-6))
        at = [i for i in near.tolist() if faces[i].distance(pt) < 1e-6]
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
                boxes[i] = g.bounds
    return faces


def partition_solid(faces, planes, ground_z, *, min_height=0.2, level_tol=5e-3,
                    edges=None) -> Solid:
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
    edges : tuple, optional
        :func:`partition_edges` of ``faces``, when already taken for other planes.

    Returns
    -------
    Solid
        RoofSurface per face, WallSurface per wall piece, one GroundSurface.

    Raises
    ------
    FitError
        When a roof plane goes below the floor.

    Notes
    -----
    Array form: the heights of every partition vertex are grouped into levels
    at once, every lookup of a height's level is one ``argmin`` over a padded
    (vertex, level) table, and vertex ids are numbered in the order the
    surfaces first use them (roofs, then walls in edge order, then the floor).
    """
    planes = np.asarray(planes, dtype=np.float64)
    rings = split_crossings(faces, planes, tol=level_tol, edges=edges)
    flat_rings = [r for rs in rings for r in rs]
    sizes = np.array([len(r) for r in flat_rings], dtype=np.int64)
    ring_face = np.repeat(np.arange(len(rings)), [len(rs) for rs in rings])
    xy = np.concatenate(flat_rings)[:, :2]
    # every vertex's key (:func:`_ring_keys` of all rings at once), as rows
    key_rows = np.rint(xy * _KEY).astype(np.int64)
    vface = np.repeat(ring_face, sizes)
    # heights of every face at its vertices
    z = planes[vface, 0] * xy[:, 0] + planes[vface, 1] * xy[:, 1] + planes[vface, 2]
    low = z < ground_z + min_height
    if low.any():
        first = int(np.flatnonzero(low)[0])
        ri = int(np.searchsorted(np.cumsum(sizes), first, side="right"))
        s0 = int(sizes[:ri].sum())
        fi = int(ring_face[ri])
        raise FitError(f"roof plane {fi} goes below the floor "
                       f"({z[s0:s0 + sizes[ri]].min():.2f} < {ground_z:.2f} + {min_height})")
    # vertex keys -> ids 0.. in order of first appearance; coordinates of the last one
    # (np.unique of the rows, sorted by x then y; each key's first index and group)
    srt, new, inverse = _key_groups(key_rows)
    first = np.minimum.reduceat(srt, np.flatnonzero(new))
    by_first = np.argsort(first)
    rank = np.empty(len(first), dtype=np.int64)
    rank[by_first] = np.arange(len(first))
    kid = rank[inverse]
    kid_of = dict(zip(map(tuple, key_rows[first[by_first]].tolist()), range(len(first))))
    nk = len(kid_of)
    last = np.full(nk, -1, dtype=np.int64)
    np.maximum.at(last, kid, np.arange(len(kid)))
    kxy = xy[last]
    # directed edges and which face uses them
    e_kp, e_kq, e_f, e_o = _directed_edges(kid, sizes, vface, nk)
    outer_edges = e_o < 0  # no face runs the edge the other way
    outer_kids = np.column_stack([e_kp[outer_edges], e_kq[outer_edges]]).ravel()
    # unify levels per vertex: sorted heights split where they step by more than level_tol
    lev_k = np.concatenate([kid, outer_kids])
    lev_z = np.concatenate([z, np.full(len(outer_kids), float(ground_z))])
    order = np.lexsort((lev_z, lev_k))
    lev_k, lev_z = lev_k[order], lev_z[order]
    start = np.ones(len(lev_k), dtype=bool)
    start[1:] = (lev_k[1:] != lev_k[:-1]) | (np.diff(lev_z) > level_tol)
    starts = np.flatnonzero(start)
    counts = np.diff(np.append(starts, len(lev_k)))
    # each group's mean as np.mean takes it: summed left to right below 8 values,
    # numpy's pairwise sum from 8 on (rare: a vertex with that many heights)
    sums = lev_z[starts].copy()
    for j in range(1, min(int(counts.max()), 8)):
        more = counts > j
        sums[more] += lev_z[starts[more] + j]
    means = sums / counts
    for g in np.flatnonzero(counts >= 8):
        means[g] = lev_z[starts[g]:starts[g] + counts[g]].mean()
    g_k = lev_k[starts]
    n_lev = np.bincount(g_k, minlength=nk)
    first_g = np.concatenate([[0], np.cumsum(n_lev)[:-1]])
    table = np.full((nk, int(n_lev.max())), np.inf)
    table[g_k, np.arange(len(g_k)) - first_g[g_k]] = means

    def level_index(k, zz):
        """Index of the level at each vertex k nearest to zz (the first of equals)."""
        return np.argmin(np.abs(table[k] - np.asarray(zz)[:, None]), axis=1)

    # vertex requests (key id, level index) in the order the surfaces use them
    roof_lev = level_index(kid, z)
    requests = [kid * table.shape[1] + roof_lev]
    # walls: each directed edge (p -> q) of face f whose other side is lower (or outside)
    p, q = kxy[e_kp], kxy[e_kq]

    def plane_z(f, pts):
        return planes[f, 0] * pts[:, 0] + planes[f, 1] * pts[:, 1] + planes[f, 2]

    zf_p, zf_q = level_index(e_kp, plane_z(e_f, p)), level_index(e_kq, plane_z(e_f, q))
    outside = e_o < 0
    o = np.where(outside, 0, e_o)
    zo_p = level_index(e_kp, np.where(outside, ground_z, plane_z(o, p)))
    zo_q = level_index(e_kq, np.where(outside, ground_z, plane_z(o, q)))
    # the wall belongs to the higher side (crossings were split away)
    wall = ~((zf_p < zo_p) | (zf_q < zo_q) | ((zf_p == zo_p) & (zf_q == zo_q)))
    width = table.shape[1]
    # every wall's ring at once: seen from the lower side, up along q (levels oq..fq), down
    # along p (fp..op), counter-clockwise seen from outside (the face is on the left of p -> q)
    kp_w, kq_w, fp_w, op_w = e_kp[wall], e_kq[wall], zf_p[wall], zo_p[wall]
    oq_w = zo_q[wall]
    up = np.maximum(zf_q[wall] - oq_w + 1, 0)
    n_w = up + np.maximum(fp_w - op_w + 1, 0)
    w_of = np.repeat(np.arange(len(n_w)), n_w)
    pos = np.arange(len(w_of)) - np.repeat(np.cumsum(n_w) - n_w, n_w)
    wall_codes = np.where(pos < up[w_of], kq_w[w_of] * width + oq_w[w_of] + pos,
                          kp_w[w_of] * width + fp_w[w_of] - (pos - up[w_of]))
    requests.append(wall_codes)  # their vertices exist even if a wall is dropped
    # repeated vertices dropped (a run keeps its first; the last when it closes the ring)
    keep = np.ones(len(w_of), dtype=bool)
    keep[1:] = (wall_codes[1:] != wall_codes[:-1]) | (w_of[1:] != w_of[:-1])
    kept = np.flatnonzero(keep)
    n_kept = np.bincount(w_of[kept], minlength=len(n_w))
    has = np.flatnonzero(n_kept > 1)
    last = kept[np.cumsum(n_kept)[has] - 1]
    first = kept[(np.cumsum(n_kept) - n_kept)[has]]
    closes = wall_codes[last] == wall_codes[first]
    keep[last[closes]] = False
    n_kept[has[closes]] -= 1
    keep &= (n_kept >= 3)[w_of]
    wall_codes, wall_len = wall_codes[keep], n_kept[n_kept >= 3]
    # floor: the polygons the outer edges enclose (pinched outlines give several), facing down
    import shapely
    from shapely.geometry.polygon import orient

    lines = shapely.linestrings(np.stack([kxy[outer_kids[0::2]], kxy[outer_kids[1::2]]], axis=1)) \
        if outer_edges.any() else []
    face_array = np.asarray(faces, dtype=object)
    floor_rings = []
    for poly in shapely.get_parts(shapely.polygonize(lines)):
        if poly.area < 1e-3 * poly.length or \
                not shapely.dwithin(face_array, poly.representative_point(), 1e-7).any():
            continue  # the inside of a courtyard, or a zero-width loop of outline edges
        poly = orient(poly, -1.0)  # clockwise from above: the normal points down
        rs = []
        for r in [poly.exterior, *poly.interiors]:
            k = np.array([kid_of[c] for c in _ring_keys(np.asarray(r.coords)[:-1])], dtype=np.int64)
            rs.append(k * width + level_index(k, np.full(len(k), float(ground_z))))
        floor_rings.append(rs)
    requests += [r for rs in floor_rings for r in rs]
    # ids in order of first use
    uniq, first = np.unique(np.concatenate(requests), return_index=True)
    by_use = np.argsort(first, kind="stable")
    rank = np.empty(len(uniq), dtype=np.int64)
    rank[by_use] = np.arange(len(uniq))
    used = uniq[by_use]
    verts = np.column_stack([kxy[used // width], table[used // width, used % width]])

    def ids(codes):
        return rank[np.searchsorted(uniq, codes)]

    roof_ids = ids(requests[0])
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    surfaces = []
    ring_i = 0
    for rs in rings:
        surfaces.append(Surface([roof_ids[bounds[ring_i + j]:bounds[ring_i + j + 1]]
                                 for j in range(len(rs))], "RoofSurface"))
        ring_i += len(rs)
    if len(wall_len):
        wall_ids, ends = ids(wall_codes), np.cumsum(wall_len).tolist()
        surfaces += [Surface([wall_ids[i:j]], "WallSurface")
                     for i, j in zip([0, *ends[:-1]], ends, strict=True)]
    surfaces[:0] = [Surface([ids(r) for r in rs], "GroundSurface") for rs in floor_rings]
    return Solid(verts.reshape(-1, 3), surfaces)
