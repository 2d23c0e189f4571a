"""Roof partition from an arrangement of straight lines: exact ridges, hips, valleys and steps.

The label grid (:mod:`.topology`) says which facets meet and roughly where; its
boundaries are staircases. Here every boundary chain between two facets is
replaced by straight segments:

- an **intersection edge** (the chain lies near the line where the two facets'
  planes meet, or the planes are at the same height along it) becomes that
  exact line, projected, over the chain's extent;
- a **step edge** is split into the fewest straight pieces that each fit its
  raw chain within 1.5 cells (split where Douglas-Peucker would, then merged
  where neighbours fit one line), each piece made parallel / perpendicular to
  the building direction when within ``snap_angle`` of it; consecutive pieces
  meet at their lines' intersection.

A chain near its planes' intersection line is an intersection edge only when
that line explains the nearby points about as well as the chain does. A chain
that starts or ends well off the line, where the planes differ in height (a
dormer's side wall running into its valley), is cut there: a straight step piece
(snapped to the axes from twice ``snap_angle``, its direction being noisy) and
the exact line.

Segments overshoot their ends a little; together with the footprint outline
they are noded and polygonised, so the cells always partition the footprint
and dangling overshoots vanish. Each cell takes the facet plane that fits its
points best (robust, capped residuals); small or empty cells and faces join the
neighbour they share the longest boundary with, and so do slivers narrower than
a cell; same-plane cells dissolve into faces. Junction vertices are then moved
to the least-squares meeting point of the planes by
:func:`.refine.refine_partition`, and edges shorter than 1.5 cells collapse
(:func:`collapse_short_edges`).

References
----------
Main seed framework, steps 3-6 (raw topology, simplification keeping junctions,
intersection and step edges). The arrangement-and-labelling idea follows
3DBAG roofer's roof partition (line arrangement, then face labels).
"""

from __future__ import annotations

import logging

import numpy as np

from .._stats import median
from ..errors import AlgorithmError, InputError
from .facets import quantile_side
from .refine import _plane_line
from .topology import boundary_chains, label_grid

logger = logging.getLogger(__name__)

__all__ = ["arrangement_cells", "rim_strips", "dissolve_cells", "drop_collinear", "extend_to_hits", "collapse_short_edges", "chain_segments", "snake_steps", "roof_lines", "arrangement_partition", "restore_facets", "raised_parts"]


def arrangement_cells(footprint, segments):
    """The cells into which polylines (each (m, 2)) cut a footprint polygon.

    Parts of the polylines outside the footprint and dangling ends are dropped.
    Returns a list of shapely Polygons covering the footprint without overlap.
    """
    import shapely

    rings = [np.asarray(r.coords) for r in shapely.get_rings(footprint)]
    lines = rings + [np.asarray(s, dtype=np.float64) for s in segments if len(s) >= 2]
    # snap-rounded noding on a micrometre grid (robust: a crossing computed twice lands on
    # one vertex, overlapping collinear pieces dissolve); plane lines made in one call
    if all(c.ndim == 2 and c.shape[1] == 2 for c in lines):
        sizes = np.fromiter(map(len, lines), dtype=np.int64, count=len(lines))
        multi = shapely.multilinestrings(shapely.linestrings(
            np.concatenate(lines), indices=np.repeat(np.arange(len(lines)), sizes)))
    else:
        multi = shapely.MultiLineString(lines)
    noded = shapely.set_precision(shapely.union_all(multi, grid_size=1e-6), 0)
    cells = shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
    cells = cells[shapely.area(cells) > 1e-9]
    inside = shapely.dwithin(footprint, shapely.point_on_surface(cells), 1e-9)
    return list(cells[inside])


def _adjacency(cells):
    """Shared boundary length between touching cells: dict (i, j) -> length, i < j."""
    import shapely

    tree = shapely.STRtree(cells)
    a, b = tree.query(cells, predicate="intersects")
    keep = a < b
    a, b = a[keep], b[keep]
    if not len(a):
        return {}
    lengths = _shared_lengths(cells, a, b)
    return {(int(i), int(j)): float(L) for i, j, L in zip(a, b, lengths, strict=True) if L > 1e-9}


def _shared_lengths(cells, a, b):
    """Length of the boundary cells ``a[k]`` and ``b[k]`` share, for noded cells (a shared
    edge has the same vertices in both): the edges of all rings keyed by their two end
    points, each edge held by two cells counted for that pair, in vectorised passes
    (``shapely.length(shapely.intersection(boundary(a), boundary(b)))`` without an overlay
    per pair)."""
    xy, owner, sizes = _flat_rings(cells)
    if not len(xy) or not len(a):
        return np.zeros(len(a))
    _, nxt = _ring_neighbours(sizes)
    cell = np.repeat(owner, sizes)
    p, q = xy, xy[nxt]
    swap = (q[:, 0] < p[:, 0]) | ((q[:, 0] == p[:, 0]) & (q[:, 1] < p[:, 1]))
    lo, hi = np.where(swap[:, None], q, p), np.where(swap[:, None], p, q)
    d = hi - lo
    seg_len = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    order = np.lexsort((cell, hi[:, 1], hi[:, 0], lo[:, 1], lo[:, 0]))
    key = np.column_stack([lo, hi])[order]
    same = np.all(key[1:] == key[:-1], axis=1)  # the next edge in the order is this one
    i, j = order[:-1][same], order[1:][same]
    ci, cj = cell[i], cell[j]
    ok = ci != cj
    ci, cj, L = ci[ok], cj[ok], seg_len[i[ok]]
    lo_c, hi_c = np.minimum(ci, cj), np.maximum(ci, cj)
    n = len(cells)
    # each queried pair's edges summed in ring order of the lower cell
    by = np.argsort(np.minimum(i[ok], j[ok]), kind="stable")
    pair_key = lo_c[by] * n + hi_c[by]
    want = np.asarray(a, dtype=np.int64) * n + np.asarray(b, dtype=np.int64)
    uk, inv = np.unique(np.concatenate([pair_key, want]), return_inverse=True)
    tot = np.bincount(inv[:len(pair_key)], weights=L[by], minlength=len(uk))
    return tot[inv[len(pair_key):]]


_INF = float("inf")


def _close_points(p, q) -> bool:
    """``np.allclose(p, q)`` of two points, coordinate by coordinate in Python floats (the
    same double arithmetic, without its array set-up; called per chain end)."""
    return all(a == b or (abs(a - b) <= 1e-08 + 1e-05 * abs(b) and abs(a) < _INF > abs(b))
               for a, b in zip(np.asarray(p, dtype=np.float64).tolist(),
                               np.asarray(q, dtype=np.float64).tolist(), strict=True))


def _seq_sum(values) -> float:
    """Left-to-right sum from 0.0 (the order ``np.bincount`` adds its weights in); a short
    list of floats is added in Python (the same double additions, without numpy's set-up)."""
    if isinstance(values, list) and len(values) < 64:
        total = 0.0
        for v in values:
            total += v
        return total
    return float(np.cumsum(values)[-1]) if len(values) else 0.0


def dissolve_cells(cells, labels, *, min_area=0.0, weights=None, min_width=0.0):
    """Merge cells into faces: same-label neighbours join; small faces take a neighbour's label.

    Parameters
    ----------
    cells : list of shapely Polygon
        A partition (noded: shared edges have identical vertices).
    labels : ndarray of int, shape (len(cells),)
        Label per cell, -1 for unknown (such cells always join a neighbour).
    min_area : float
        Faces smaller than this (m2) join the neighbouring face they share the
        longest boundary with (smallest first).
    weights : ndarray, optional
        Per-cell evidence (e.g. point counts); a face with none joins a neighbour too.
    min_width : float
        Faces narrower than this on average (2 area / perimeter, m) join a neighbour too.

    Returns
    -------
    faces : list of shapely Polygon
    face_labels : ndarray of int

    Notes
    -----
    One merge at a time, the smallest bad face first (ties: known label before
    unknown... as ``lexsort((index, label >= 0, area))`` orders them), into the
    neighbouring face it shares the longest boundary with. Faces are kept in a
    union-find (rooted at their smallest cell) and the bad ones in a heap: a merge
    only changes the faces it joins, so each step costs the size of the face
    merged, not a pass over every cell (the roofs of a block of row houses have
    ~1000 cells and ~500 merges). A face's area, weight and perimeter are summed
    in cell order, as a pass with ``np.bincount`` would, whenever they decide
    whether it is bad: the faces and labels are those of merging one face per
    pass over all cells.
    """
    import heapq

    import shapely

    n = len(cells)
    labels = np.asarray(labels, dtype=np.int64).copy()
    if n == 0:
        return [], labels
    area = shapely.area(np.asarray(cells, dtype=object))
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    adj = _adjacency(cells)
    length = shapely.length(np.asarray(cells, dtype=object))
    pair_len = np.fromiter(adj.values(), dtype=np.float64, count=len(adj))
    nbr: dict = {}  # cell -> [(neighbour, shared length, pair index in adj's order)]
    for p, ((i, j), L) in enumerate(adj.items()):
        nbr.setdefault(i, []).append((j, L, p))
        nbr.setdefault(j, []).append((i, L, p))
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i, j in adj:
        if labels[i] == labels[j]:
            a, b = find(i), find(j)
            if a != b:  # the smaller index roots the face
                parent[max(a, b)] = min(a, b)
    members: dict = {}
    for i in range(n):
        members.setdefault(find(i), []).append(i)

    area_l, w_l, length_l = area.tolist(), w.tolist(), length.tolist()
    pair2_l = (2 * pair_len).tolist()

    def exact(r):
        """(area, weight, perimeter) of face r, summed in cell order."""
        m = members[r]
        perim = 0.0
        if min_width > 0:
            inner = sorted({p for i in m for j, _, p in nbr.get(i, ()) if find(j) == r})
            perim = _seq_sum([length_l[i] for i in m]) - _seq_sum([pair2_l[p] for p in inner])
        return _seq_sum([area_l[i] for i in m]), _seq_sum([w_l[i] for i in m]), perim

    def is_bad(a, wt, perim, lab):
        return (a < min_area or wt <= 0 or lab < 0
                or (min_width > 0 and 2 * a < min_width * perim))

    # running sums (any order) screen out the faces far from every threshold; the ones
    # near a threshold, or bad, get their exact sums
    approx: dict = {}
    version = dict.fromkeys(members, 0)
    heap: list = []

    def settle(r, a, wt, perim):
        approx[r] = (a, wt, perim)
        lab = labels[r]
        tol = 1e-9 * (abs(a) + abs(min_area) + abs(wt) + min_width * abs(perim)) + 1e-12
        near = (a < min_area + tol or wt <= tol or lab < 0
                or (min_width > 0 and 2 * a < min_width * perim + tol))
        if near:
            ea, ew, ep = exact(r)
            if is_bad(ea, ew, ep, lab):
                heapq.heappush(heap, (ea, lab >= 0, r, version[r]))

    for r in members:
        settle(r, *exact(r))
    skipped = []
    for _ in range(4 * n):
        merged = False
        while heap:
            entry = heapq.heappop(heap)
            c = entry[2]
            if parent[c] != c or version.get(c) != entry[3]:
                continue  # merged away or changed since pushed
            shared: dict = {}
            for i in members[c]:
                for j, L, _ in nbr.get(i, ()):
                    rj = find(j)
                    if rj != c:
                        shared[rj] = shared.get(rj, 0.0) + L
            cand = [(L, -k) for k, L in shared.items() if labels[k] >= 0 or labels[c] < 0]
            if not cand:
                skipped.append(entry)
                continue
            new = labels[-max(cand)[1]]
            joined = [k for k in shared if labels[k] == new]
            inner = sum(L for i in members[c] for j, L, _ in nbr.get(i, ()) if find(j) in joined)
            a, wt, perim = approx[c]
            for k in joined:
                a, wt, perim = a + approx[k][0], wt + approx[k][1], perim + approx[k][2]
            perim -= 2 * inner
            root = min(c, *joined)
            cells_all = sorted(members[c] + [i for k in joined for i in members[k]])
            labels[members[c]] = new
            for k in (c, *joined):
                parent[k] = root
                if k != root:
                    del members[k], approx[k], version[k]
            members[root] = cells_all
            version[root] += 1
            settle(root, a, wt, perim)
            merged = True
            break
        if not merged:
            break
        for entry in skipped:  # their neighbours may have changed: tried again in order
            heapq.heappush(heap, entry)
        skipped = []
    faces, face_labels = [], []
    for r in sorted(members):
        idx = members[r]
        poly = shapely.union_all([cells[i] for i in idx]) if len(idx) > 1 else cells[idx[0]]
        for p in shapely.get_parts(poly):
            if p.geom_type == "Polygon" and p.area > 1e-9:
                faces.append(p)
                face_labels.append(labels[idx[0]])
    return drop_collinear(faces), np.asarray(face_labels, dtype=np.int64)


def _snap_close(pts, tol):
    """``pts`` with every vertex within ``tol`` of another (transitively) moved onto
    the first vertex of its cluster."""
    from scipy.spatial import cKDTree

    from .._components import component_labels

    pairs = cKDTree(pts).query_pairs(tol, output_type="ndarray")
    if len(pairs):
        comp = component_labels(len(pts), pairs[:, 0], pairs[:, 1])
        first = np.full(comp.max() + 1, -1)
        first[comp[::-1]] = np.arange(len(pts))[::-1]
        pts = pts[first[comp]]
    return pts


def _merge_close(rings, tol):
    """Rings (lists of (m, 2) arrays) with vertices closer than ``tol`` made one (consistently
    across all rings) and consecutive repeats removed."""
    flat = [r for rs in rings for r in rs]
    if not flat:
        return rings
    pts = np.concatenate(flat)
    pts = _snap_close(pts, tol)
    out, k = [], 0
    for rs in rings:
        new_rs = []
        for r in rs:
            c = pts[k:k + len(r)]
            k += len(r)
            new_rs.append(c[np.any(c != np.concatenate([c[-1:], c[:-1]]), axis=1)])  # np.roll(c, 1)
        out.append(new_rs)
    return out


def _flat_rings(faces):
    """Every ring of every face without its closing vertex, flat: coordinates (N, 2), each
    ring's face, its vertex count, in vectorised calls (the rings of a face in
    ``shapely.get_rings`` order)."""
    import shapely

    rings, owner = shapely.get_rings(np.asarray(faces, dtype=object), return_index=True)
    xy, which = shapely.get_coordinates(rings, return_index=True)
    sizes = np.bincount(which, minlength=len(rings))
    last = np.cumsum(sizes) - 1
    keep = np.ones(len(xy), dtype=bool)
    keep[last[sizes > 0]] = False  # the closing vertex
    return xy[keep], owner, np.maximum(sizes - 1, 0)


def _ring_neighbours(sizes):
    """Index of the vertex before and after each vertex of flat rings of ``sizes`` vertices
    (cyclic within each ring): ``np.roll(r, 1)`` and ``np.roll(r, -1)`` of every ring at once."""
    n = int(sizes.sum())
    ids = np.arange(n)
    start = np.repeat(np.cumsum(sizes) - sizes, sizes)
    size = np.repeat(sizes, sizes)
    pos = ids - start
    return start + (pos - 1) % np.maximum(size, 1), start + (pos + 1) % np.maximum(size, 1)


def _merge_close_flat(pts, sizes, tol):
    """:func:`_merge_close` of flat rings (coordinates (N, 2), vertex count per ring): the
    merged coordinates of the vertices kept and the rings' new vertex counts."""
    if not len(pts):
        return pts, sizes
    pts = _snap_close(pts, tol)
    prev, _ = _ring_neighbours(sizes)
    keep = np.any(pts != pts[prev], axis=1)  # a vertex equal to the one before it goes
    ring = np.repeat(np.arange(len(sizes)), sizes)
    return pts[keep], np.bincount(ring[keep], minlength=len(sizes))


def _key_groups(pts):
    """Group id of each vertex by its :func:`.solid._key` (equal keys, equal ids)."""
    from .solid import _KEY

    k = np.rint(pts * _KEY).astype(np.int64)
    order = np.lexsort((k[:, 1], k[:, 0]))
    ks = k[order]
    new = np.ones(len(ks), dtype=bool)
    new[1:] = np.any(ks[1:] != ks[:-1], axis=1)
    gid = np.empty(len(ks), dtype=np.int64)
    gid[order] = np.cumsum(new) - 1
    return gid


def drop_collinear(faces, *, tol=1e-6, merge=1e-4):
    """Faces without the vertices that are straight (within ``tol`` m) in every ring holding them.

    Such vertices are where a dissolved cut ended; a vertex where any face turns
    (a junction) is kept in every face, so shared edges keep identical vertices.
    Vertices closer than ``merge`` (m; nearly concurrent lines) are first made one.
    The rings of all faces are handled as one flat array (coordinates and ring sizes).
    """
    import shapely

    faces = list(faces)
    if not faces:
        return []
    xy, owner, sizes = _flat_rings(faces)
    pts, sizes = _merge_close_flat(xy, sizes, merge)
    prev, nxt = _ring_neighbours(sizes)
    u, v = pts - pts[prev], pts[nxt] - pts
    cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    w = pts[nxt] - pts[prev]
    dev = cross / np.maximum(np.hypot(w[:, 0], w[:, 1]), 1e-12)
    back = u[:, 0] * v[:, 0] + u[:, 1] * v[:, 1] < 0
    turns = ((dev > tol) | back) & (np.repeat(sizes, sizes) >= 3)
    gid = _key_groups(pts)
    turning = np.zeros(int(gid.max()) + 1 if len(gid) else 0, dtype=bool)
    turning[gid[turns]] = True
    kept = turning[gid]
    ring = np.repeat(np.arange(len(sizes)), sizes)
    n_kept = np.bincount(ring[kept], minlength=len(sizes))
    first = np.ones(len(owner), dtype=bool)
    first[1:] = owner[1:] != owner[:-1]
    shell_ok = np.zeros(len(faces), dtype=bool)
    shell_ok[owner[first]] = n_kept[first] >= 3
    use = shell_ok[owner] & (n_kept >= 3)  # a face's shell and its holes of 3 vertices or more
    out = np.asarray(faces, dtype=object).copy()
    if use.any():
        take = kept & use[ring]
        lr = shapely.linearrings(pts[take], indices=np.repeat(np.arange(use.sum()), n_kept[use]))
        face_of = np.cumsum(np.r_[True, owner[use][1:] != owner[use][:-1]]) - 1
        out[shell_ok] = shapely.polygons(lr, indices=face_of)
    areas = shapely.area(out)
    if not (shapely.is_valid(out).all() and (areas > 0).all()) or \
            abs(sum(areas.tolist()) - sum(f.area for f in faces)) > 1e-3 * max(1.0, len(faces)):
        return faces
    return list(out)


def _dp(points, tol):
    from shapely.geometry import LineString

    return np.asarray(LineString(points).simplify(tol, preserve_topology=False).coords)


def _axis_snap(d, direction, snap_angle):
    """Unit direction d snapped to the nearest building axis when within ``snap_angle`` (deg)."""
    ang = np.arctan2(d[1], d[0])
    k = np.round((ang - direction) / (np.pi / 2))
    axis = direction + k * np.pi / 2
    if abs(ang - axis) <= np.radians(snap_angle):
        return np.array([np.cos(axis), np.sin(axis)])
    return d


def _meet(p, d, q, e, fallback):
    """Intersection of lines p + s d and q + t e; ``fallback`` when nearly parallel (< 20 deg)."""
    cross = d[0] * e[1] - d[1] * e[0]
    if abs(cross) < np.sin(np.radians(20)):
        return None
    s = ((q[0] - p[0]) * e[1] - (q[1] - p[1]) * e[0]) / cross
    x = p + s * d
    return x if np.hypot(*(x - fallback)) < 3.0 else None


def _cov2(x):
    """``np.cov(x.T)`` of points (k, 2), k >= 2: the same operations in the same order
    (and so the same doubles), without its argument handling (called per piece)."""
    x = np.array(x.T, ndmin=2, dtype=np.float64)
    x -= (np.add.reduce(x, axis=1) / x.shape[1])[:, None]  # x.mean(axis=1), without its set-up
    c = np.dot(x, x.T.conj())
    c *= np.true_divide(1, x.shape[1] - 1)
    return c


def _fit_line(sub, direction, snap_angle):
    """Total-least-squares line (point, unit direction from the first to the last point) of
    points (m, 2), its direction snapped to the building axes; and the largest distance to it."""
    m = np.add.reduce(sub, axis=0) / len(sub)  # sub.mean(axis=0): the same sum and division
    if len(sub) < 3:
        d = sub[-1] - sub[0]
    else:
        w, v = np.linalg.eigh(_cov2(sub - m))
        d = v[:, 1]
    n = np.hypot(*d)
    if n < 1e-12:
        return None
    d = d / n
    if (sub[-1] - sub[0]) @ d < 0:
        d = -d
    d = _axis_snap(d, direction, snap_angle)
    normal = np.array([-d[1], d[0]])
    return m, d, float(np.abs((sub - m) @ normal).max())


def _split_fit(raw, lo, hi, tol, direction, snap_angle, out, fits):
    """Pieces (lo, hi) of raw[lo..hi] each fitted by one line within ``tol`` (split at the point
    farthest from the chord, as Douglas-Peucker). ``fits``: :func:`_span_fit`'s memo."""
    sub = raw[lo:hi + 1]
    fit = _span_fit(raw, lo, hi, direction, snap_angle, fits)
    if hi - lo < 3 or (fit is not None and fit[2] <= tol):
        out.append((lo, hi))
        return
    a, b = raw[lo], raw[hi]
    d = b - a
    n = np.hypot(*d)
    if n < 1e-9:
        dist = np.hypot(*(sub - a).T)
    else:
        dist = np.abs((sub - a) @ np.array([-d[1], d[0]]) / n)
    k = lo + int(np.argmax(dist[1:-1])) + 1
    _split_fit(raw, lo, k, tol, direction, snap_angle, out, fits)
    _split_fit(raw, k, hi, tol, direction, snap_angle, out, fits)


def _span_fit(raw, lo, hi, direction, snap_angle, fits):
    """:func:`_fit_line` of raw[lo..hi], memoised in the dict ``fits`` by ``(lo, hi)``: a
    chain's splitting, merging and final pieces fit many spans more than once."""
    key = (lo, hi)
    if key not in fits:
        fits[key] = _fit_line(raw[lo:hi + 1], direction, snap_angle)
    return fits[key]


def _step_polyline(chain, *, tol, direction, snap_angle, closed):
    """Straight, direction-snapped polyline of a step chain (raw grid corners (m, 2)).

    The chain is split into the fewest pieces (Douglas-Peucker order) that each
    fit one line within ``tol``, neighbouring pieces that fit one line together
    merge, and consecutive lines meet at their intersection (or, nearly
    parallel, in a short jog at the vertex they share).
    """
    raw = np.asarray(chain, dtype=float)
    raw = raw[np.concatenate(([True], np.any(np.diff(raw, axis=0) != 0, axis=1)))]
    if len(raw) < 2 or (closed and len(raw) < 5):
        return None
    spans, fits = [], {}
    _split_fit(raw, 0, len(raw) - 1, tol, direction, snap_angle, spans, fits)
    merged = True
    while merged and len(spans) > 1:
        merged = False
        for i in range(len(spans) - 1):
            fit = _span_fit(raw, spans[i][0], spans[i + 1][1], direction, snap_angle, fits)
            if fit is not None and fit[2] <= tol:
                spans[i:i + 2] = [(spans[i][0], spans[i + 1][1])]
                merged = True
                break
    pieces = []
    for lo, hi in spans:
        fit = _span_fit(raw, lo, hi, direction, snap_angle, fits)
        if fit is not None:
            pieces.append((fit[0], fit[1], raw[lo:hi + 1]))
    if not pieces or (closed and len(pieces) < 3):
        return None
    pts = []
    m = len(pieces)
    for k in range(m if closed else m - 1):
        (p, d, sa), (q, e, _) = pieces[k], pieces[(k + 1) % m]
        corner = sa[-1]
        x = _meet(p, d, q, e, corner)
        if x is None:
            # nearly parallel neighbours: a jog at the raw vertex they share
            pts += [p + ((corner - p) @ d) * d, q + ((corner - q) @ e) * e]
        else:
            pts.append(x)
    if closed:
        return np.vstack([pts, pts[:1]]) if len(pts) >= 3 else None
    p, d, sa = pieces[0]
    q, e, sb = pieces[-1]
    start = p + ((sa[0] - p) @ d) * d
    end = q + ((sb[-1] - q) @ e) * e
    return np.vstack([start, *pts, end]) if pts else np.vstack([start, end])


def _refit_lines(polys, raws, *, max_shift):
    """Open polylines (k, 2) whose straight pieces keep their directions and move along
    their normals to the median of the raw chain vertices (m, 2) nearest to them (away
    from the pieces' ends); pieces on one line (collinear, of any chains) move together.
    Consecutive pieces meet at their lines' intersection, and the ends are the raw
    chains' ends projected on the first and last lines.

    The snake's grid quantises positions, and its deviation energy (an integral along
    the edge) shortens a free end; this takes the offsets and the ends back to the
    data, as :func:`lidar2city.regularize.snake.regularize_polygon` does with
    ``refine``, keeping the snake's directions and collinearities. A line keeps its
    offset when the median is more than ``max_shift`` (m) away. None stays None.
    """
    geo, offsets = [], {}
    for poly, raw in zip(polys, raws, strict=True):
        if poly is None:
            geo.append(None)
            continue
        a, b = poly[:-1], poly[1:]
        d = b - a
        length = np.hypot(d[:, 0], d[:, 1])
        t = d / length[:, None]
        n = np.stack([-t[:, 1], t[:, 0]], axis=1)
        n[(n[:, 0] < -1e-12) | ((np.abs(n[:, 0]) <= 1e-12) & (n[:, 1] < 0))] *= -1
        c = np.einsum("kc,kc->k", n, a)
        keys = [(round(float(np.arctan2(v[1], v[0])), 6), round(float(w), 4)) for v, w in zip(n, c, strict=True)]
        s = np.einsum("nkc,kc->nk", raw[:, None, :] - a[None], t) / length
        foot = a[None] + np.clip(s, 0, 1)[..., None] * d[None]
        near = np.argmin(np.hypot(*(raw[:, None, :] - foot).transpose(2, 0, 1)), axis=1)
        rows = np.arange(len(raw))
        inner = (s[rows, near] > 0.1) & (s[rows, near] < 0.9)
        proj = np.einsum("nc,nc->n", raw, n[near])
        for k, key in enumerate(keys):
            offsets.setdefault(key, (c[k], []))[1].append(proj[inner & (near == k)])
        geo.append((n, keys))
    shift = {}
    for key, (c0, parts) in offsets.items():
        proj = np.concatenate(parts)
        mid = median(proj) if len(proj) >= 2 else None
        shift[key] = float(mid) if mid is not None and abs(mid - c0) <= max_shift else float(c0)
    out = []
    for poly, raw, g in zip(polys, raws, geo, strict=True):
        if g is None:
            out.append(None)
            continue
        n, keys = g
        c = np.array([shift[k] for k in keys])
        pts = [raw[0] + (c[0] - n[0] @ raw[0]) * n[0]]
        for i in range(len(c) - 1):
            det = n[i, 0] * n[i + 1, 1] - n[i, 1] * n[i + 1, 0]
            if abs(det) < 1e-6:
                break
            pts.append(np.array([(c[i] * n[i + 1, 1] - c[i + 1] * n[i, 1]) / det,
                                 (n[i, 0] * c[i + 1] - n[i + 1, 0] * c[i]) / det]))
        else:
            pts.append(raw[-1] + (c[-1] - n[-1] @ raw[-1]) * n[-1])
            out.append(np.asarray(pts))
            continue
        out.append(poly)
    return out


def _straight(pts, closed):
    """Vertices (k, 2) without repeats and without collinear interior vertices."""
    while len(pts) > 1:
        pts = pts[np.concatenate(([True], np.hypot(*np.diff(pts, axis=0).T) > 1e-9))]
        if closed and len(pts) > 1 and np.hypot(*(pts[0] - pts[-1])) <= 1e-9:
            pts = pts[:-1]
        if len(pts) <= 2:
            break
        prev = np.roll(pts, 1, axis=0) if closed else np.vstack([pts[:1], pts[:-1]])
        nxt = np.roll(pts, -1, axis=0) if closed else np.vstack([pts[1:], pts[-1:]])
        u, v = pts - prev, nxt - pts
        cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
        flat = cross <= 1e-9 * np.maximum(np.hypot(*u.T) * np.hypot(*v.T), 1e-12)
        if not closed:
            flat[[0, -1]] = False
        if not flat.any():
            break
        pts = np.delete(pts, int(np.argmax(flat)), axis=0)
    return pts


def snake_steps(chains, closed, *, cell, direction, window=3, snake_cell=0.5, tol=None,
                t_adjust=None, c_short=None, max_work=1e8, subdivide=4, sample_step=2.0):
    """Step chains regularised together by the exact 2-D snake (seed step 5).

    Each raw step chain (the label grid's staircase between two facets at different
    heights) is simplified to the fewest straight pieces within ``tol`` (split where
    Douglas-Peucker would, merged where neighbours fit one line; their directions as
    the data give them, not snapped); the simplified chains, joined where they
    share a junction (a chain's end on the same grid corner), form one planar graph whose
    vertices move to the global minimum of ``E = C_Dir E_Dir + C_Dis E_Dis (+ E_Short)``
    (:func:`lidar2city.regularize.snake.adjust_planar_graph`: the direction energy
    pulls an edge whose smaller extent is within ``t_adjust`` onto the building axes,
    the deviation energy keeps it on the raw chains, minimised exactly by graph
    reduction). The intersection edges and the outline are not in the graph: they
    stay where they are, and the step lines are extended to them afterwards
    (:func:`extend_to_hits`). Each straight piece of the result then moves along its
    normal to the median of its raw vertices (the snake's grid quantises offsets).

    Parameters
    ----------
    chains : list of ndarray (m, 2)
        Raw step chains (label grid corners, local metres).
    closed : list of bool
        Whether each chain is a closed loop (an island facet).
    cell : float
        Label grid cell (m).
    direction : float
        Building direction (rad).
    window, snake_cell : int, float
        Snake half-window (candidates ``(2w+1)^2`` per vertex) and grid step as a
        fraction of ``cell``. Window 2 (25 candidates) would cost about a third of
        these energy tables for roofs as good on Delft and the synthetic roofs, but
        made a roof spike on ISPRS samp11 (benchmarks/HISTORY.md, session 13,
        lines15); a coarser grid step with the same reach (0.75 with window 2)
        lets a short wall escape the direction energy by turning oblique.
    subdivide, sample_step : int, float
        Distance raster cells per snake grid step and the spacing (raster cells)
        of the deviation's samples along a candidate edge
        (:func:`lidar2city.regularize.snake.adjust_planar_graph`); the default
        step 2 reads every other raster cell, half the samples of the footprint
        snake's, within a raster cell of its integral.
    tol : float, optional
        Simplification tolerance (m) of the chains before the snake, and the length
        below which an edge is a jog (``E_Short``, weight ``tol**2``); default
        ``1.5 * cell`` (the label grid's staircase of a straight wall stays within it).
    t_adjust : float, optional
        ``T`` (m) of the direction energy; default ``2 * cell``: the label grid puts
        a wall's ends up to a cell off on either side, so an edge whose smaller extent
        is within two cells may be a wall on the building's axes.
    c_short : float, optional
        Weight of ``E_Short`` (m2); default ``tol**2``.
    max_work : float
        The largest exact solve (table elements, :func:`lidar2city.snake.solver.reduction_work`);
        beyond it no chain is changed.

    Returns
    -------
    list of (ndarray (k, 2) or None)
        The snake's polyline per chain (closed ones repeat their first vertex), or
        None where it gave none (too few vertices, collapsed, or the solve skipped).
    """
    from ..regularize.snake import _grid_pivot, adjust_planar_graph
    from ..snake.solver import reduction_work

    tol = 1.5 * cell if tol is None else tol
    h = snake_cell * cell
    out = [None] * len(chains)
    xy, ids, segs, ends = [], [], [], {}
    for raw, cl in zip(chains, closed, strict=True):
        raw = np.asarray(raw, dtype=float)
        raw = raw[np.concatenate(([True], np.any(np.diff(raw, axis=0) != 0, axis=1)))]
        # the fewest straight pieces within tol, their directions as the data give them
        # (no snapping: the direction energy decides which become parallel to the axes)
        s = _step_polyline(raw, tol=tol, direction=direction, snap_angle=0.0, closed=cl) \
            if len(raw) >= 2 else None
        if s is None:
            s = _dp(raw, tol) if len(raw) >= 2 else raw
        if cl:
            s = s[:-1] if len(s) > 1 and _close_points(s[0], s[-1]) else s
        if len(s) < (3 if cl else 2):
            ids.append(None)
            continue
        row = list(range(len(xy), len(xy) + len(s)))
        xy += list(s)
        if not cl:
            # chains ending at the same junction (a grid corner) share one vertex there
            for end, v in ((raw[0], row[0]), (raw[-1], row[-1])):
                ends.setdefault((round(float(end[0]), 6), round(float(end[1]), 6)), []).append(v)
        ids.append(row)
        segs.append(np.stack([raw[:-1], raw[1:]], axis=1))
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    alias = np.arange(len(xy))
    for group in ends.values():
        if len(group) > 1:
            xy[group[0]] = xy[group].mean(axis=0)
            alias[group] = group[0]
    ids = [None if row is None else [int(alias[v]) for v in row] for row in ids]
    edges = sorted({(min(a, b), max(a, b)) for row, cl in zip(ids, closed, strict=True)
                    if row is not None for a, b in zip(row, row[1:] + row[:1] if cl else row[1:])
                    if a != b})
    if not edges:
        return out
    e = np.array(edges, dtype=np.int64)
    d = (2 * window + 1) ** 2
    # a graph of paths and cycles (no vertex of degree 3) reduces by I-III alone, no table
    # over more than three vertices: its work is at most len(xy) d^3 without simulating it
    simple = np.bincount(e.ravel(), minlength=len(xy)).max() <= 2 and len(xy) * d ** 3 <= max_work
    if not simple and reduction_work(np.full(len(xy), d), e) > max_work:
        return out
    # The chains' ends merged into another vertex are on no edge: they are left out of
    # the solve (a vertex of no edge is minimised alone, its state unused), on the grid
    # of the whole vertex set (its pivot), so the others' minimum is unchanged.
    used = np.unique(e)
    index = np.full(len(xy), -1, dtype=np.int64)
    index[used] = np.arange(len(used))
    moved, _ = adjust_planar_graph(xy[used], index[e], original_segments=np.concatenate(segs), cell=h,
                                   window=window, direction=direction,
                                   t_adjust=2 * cell if t_adjust is None else t_adjust,
                                   c_short=tol * tol if c_short is None else c_short, short_length=tol,
                                   subdivide=subdivide, sample_step=sample_step,
                                   pivot=_grid_pivot(xy, h))
    new = xy.copy()
    new[used] = moved
    for i, row in enumerate(ids):
        if row is None:
            continue
        pts = _straight(new[row + row[:1] if closed[i] else row], closed[i])
        if len(pts) < (3 if closed[i] else 2):
            continue
        out[i] = np.vstack([pts, pts[:1]]) if closed[i] else pts
    opened = [i for i in range(len(out)) if out[i] is not None and not closed[i]]
    refit = _refit_lines([out[i] for i in opened], [np.asarray(chains[i], dtype=float) for i in opened],
                         max_shift=cell)
    for i, poly in zip(opened, refit, strict=True):
        out[i] = poly
    return out


def _extend(poly, ext):
    """An open polyline with both end segments lengthened by ``ext``."""
    poly = np.array(poly, dtype=float)
    for i, j in ((0, 1), (-1, -2)):
        d = poly[i] - poly[j]
        n = np.hypot(*d)
        if n > 1e-9:
            poly[i] = poly[i] + d / n * ext
    return poly


def _near_chain(xyz, lab, chain, a, b, radius, *, block=256):
    """Indices (ascending) of the points (N, 2+) of facets ``a`` or ``b`` within ``radius`` of
    a vertex of ``chain`` (m, 2): a k-d tree's ball query at every vertex (squared distance
    against ``radius**2``), by brute force over the two facets' points in the chain's box,
    ``block`` vertices at a time (bounded memory), with no tree to build."""
    idx = np.flatnonzero((lab == a) | (lab == b))
    chain = np.asarray(chain, dtype=np.float64).reshape(-1, 2)
    if not len(chain) or not len(idx):
        return np.zeros(0, np.int64)
    pad = radius * (1 + 1e-9) + 1e-9  # the box only prefilters: a little wide, never narrow
    lo, hi = chain.min(axis=0) - pad, chain.max(axis=0) + pad
    x, y = xyz[idx, 0], xyz[idx, 1]
    box = (x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1])
    idx, x, y = idx[box], x[box], y[box]
    r2 = radius * radius
    keep = np.zeros(len(idx), dtype=bool)
    for s in range(0, len(chain), block):
        c = chain[s:s + block]
        d2 = (x[:, None] - c[None, :, 0]) ** 2 + (y[:, None] - c[None, :, 1]) ** 2
        keep |= (d2 <= r2).any(axis=1)
    return idx[keep].astype(np.int64)


def _line_explains(points, chain, a, b, pa, pb, g, c0, *, radius, cap, tol):
    """Whether the planes' intersection line explains the points of facets ``a`` and ``b``
    near a chain about as well as the chain (a step) does: points beyond the line take
    the other plane; their mean capped residual may grow by at most ``tol`` (m)."""
    xyz, lab = points[:2]
    near = _near_chain(xyz, lab, chain, a, b, radius)
    if len(near) < 6:
        return True
    p = xyz[near]
    side = p[:, :2] @ g + c0 > 0
    is_a = lab[near] == a
    a_side = np.mean(side[is_a]) >= 0.5 if is_a.any() else not np.mean(side[~is_a]) >= 0.5
    za = p[:, :2] @ pa[:2] + pa[2]
    zb = p[:, :2] @ pb[:2] + pb[2]
    r_step = np.minimum(np.abs(p[:, 2] - np.where(is_a, za, zb)), cap)
    r_line = np.minimum(np.abs(p[:, 2] - np.where(side == a_side, za, zb)), cap)
    return float(np.mean(r_line) - np.mean(r_step)) <= tol


def _runs(flags):
    """Maximal runs of equal flags: list of [lo, hi) index pairs."""
    cut = np.flatnonzero(flags[1:] != flags[:-1]) + 1
    bounds = np.concatenate(([0], cut, [len(flags)]))
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def _mixed_runs(chain, dz, dist, t_step, min_dist, min_length):
    """A boundary chain (m, 2) split where its two facets stop meeting in a line and start to
    differ in height (a dormer's valley running into its side wall).

    ``dz`` (m,) is the height difference of the two planes at the chain's vertices and
    ``dist`` (m,) their distance to the planes' line; a vertex is on a step where the
    running medians (3 vertices) of both reach ``t_step`` and ``min_dist`` (a staircase
    along a steep intersection line stays one line) and it lies in a run at either end
    of the chain; runs shorter than ``min_length`` (m) join their neighbours. Returns
    ``[(kind, sub), ...]`` with ``kind`` "intersection" or "step" and consecutive
    sub-chains sharing a vertex, or None when the chain is not clearly both.
    """
    if len(chain) < 4:
        return None
    def med3(a):
        # the median of each vertex and its two neighbours (ends repeated), picked by
        # min / max: the value np.median returns (NaN where one is NaN), without its set-up
        a = np.abs(np.asarray(a, dtype=float))
        prev, nxt = np.concatenate([a[:1], a[:-1]]), np.concatenate([a[1:], a[-1:]])
        return np.maximum(np.minimum(prev, a), np.minimum(np.maximum(prev, a), nxt))

    step = (med3(dz) >= t_step) & (med3(dist) >= min_dist)
    along = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    # a wall leaves the line at a chain's end (at the outline or a junction); a step
    # between two stretches on the line is the staircase of the label grid
    for lo, hi in _runs(step)[1:-1]:
        step[lo:hi] = False
    while True:
        runs = _runs(step)
        if len(runs) < 2:
            return None
        lengths = [along[min(hi, len(chain) - 1)] - along[lo] for lo, hi in runs]
        k = int(np.argmin(lengths))
        if lengths[k] >= min_length:
            break
        lo, hi = runs[k]
        step[lo:hi] = ~step[lo]
    # each piece ends on the first vertex of the next, so the pieces meet
    return [("step" if step[lo] else "intersection", chain[lo:min(hi, len(chain) - 1) + 1])
            for lo, hi in runs]


def chain_segments(chains, pairs, planes, *, cell, direction, t_step=0.3, max_shift=1.0,
                   snap_angle=15.0, step_tol=1.5, overshoot=None, points=None, cap=0.45,
                   tol_gain=0.05, step_snake=False, snake_window=3, snake_cell=0.5):
    """Straight boundary polylines replacing the label grid's chains.

    Parameters
    ----------
    chains, pairs : the inner boundary chains of a label grid and their label pairs
        (from :func:`.topology.boundary_chains`; pairs with -1 are skipped).
    planes : ndarray (K, 3)
    cell : float
        Label grid cell (m): the simplification tolerance of step edges.
    direction : float
        Building direction (rad).
    t_step : float
        Height difference (m) below which two facets meet in an intersection edge.
    max_shift : float
        A chain within this distance (90th percentile, m) of its planes' intersection
        line is an intersection edge.
    snap_angle : float
        Step pieces within this angle (deg) of the building axes are made parallel to them.
    step_tol : float
        Largest distance (in cells) of a step chain's raw vertices from its straight piece.
    overshoot : float, optional
        Length (m) by which open polylines are extended; default one cell.
    points : (xyz (N, 3), labels (N,)), optional
        With points, a chain near its planes' intersection line is an intersection
        edge only when that line explains the nearby points of both facets about as
        well as the chain does (mean capped residual, at most ``cap`` m per point,
        grows by at most ``tol_gain`` m); else it is a step.
    step_snake : bool
        Step chains through the exact 2-D snake together (:func:`snake_steps`, with
        ``snake_window`` and ``snake_cell``) instead of split-and-merge pieces snapped
        by angle; a chain the snake gives no polyline for keeps its pieces.

    Returns
    -------
    segments : list of ndarray (m, 2)
    kinds : list of str
        ``"intersection"`` or ``"step"`` per polyline.
    """
    ext = cell if overshoot is None else overshoot
    segs, kinds, steps = [], [], []
    for c, (a, b) in zip(chains, pairs, strict=True):
        if a < 0 or b < 0 or len(c) < 2:
            continue
        c = np.asarray(c, dtype=float)
        closed = len(c) > 3 and _close_points(c[0], c[-1])
        pa, pb = planes[a], planes[b]
        dz = (pa[0] - pb[0]) * c[:, 0] + (pa[1] - pb[1]) * c[:, 1] + pa[2] - pb[2]
        line = _plane_line(pa, pb)
        if line is not None:
            g, c0 = line
            dist = np.abs(c @ g + c0)
            near_line = quantile_side(dist, 0.9, max_shift)  # np.percentile(dist, 90) <= max_shift
            if near_line is None:
                near_line = np.percentile(dist, 90) <= max_shift
            runs = None
            if near_line and not closed:
                runs = _mixed_runs(c, dz, dist, t_step, step_tol * cell, 2 * cell)
            if runs:
                u = np.array([-g[1], g[0]])
                foot = -c0 * g
                for kind, sub in runs:
                    if kind == "step":
                        # a wall this short (a dormer's side) has a noisy direction of its
                        # own: it snaps to the building axes from twice as far
                        poly = _step_polyline(sub, tol=step_tol * cell, direction=direction,
                                              snap_angle=2 * snap_angle, closed=False)
                        if poly is not None:
                            steps.append((len(segs), sub, False))
                            segs.append(_extend(poly, ext))
                            kinds.append("step")
                        continue
                    t = sub @ u
                    segs.append(np.vstack([foot + (t.min() - ext) * u, foot + (t.max() + ext) * u]))
                    kinds.append("intersection")
                continue
            if near_line and points is not None and np.mean(np.abs(dz)) >= t_step:
                near_line = _line_explains(points, c, a, b, pa, pb, g, c0, radius=max_shift + cell,
                                           cap=cap, tol=tol_gain)
            if np.mean(np.abs(dz)) < t_step or near_line:
                u = np.array([-g[1], g[0]])
                t = c @ u
                foot = -c0 * g
                lo, hi = t.min() - ext, t.max() + ext
                segs.append(np.vstack([foot + lo * u, foot + hi * u]))
                kinds.append("intersection")
                continue
        # its split-and-merge pieces, made below only where the snake gives none (with
        # ``step_snake`` they are the fallback, and the snake fits its chains itself)
        steps.append((len(segs), c, closed))
        segs.append(None)
        kinds.append("step")

    def pieces(c, closed):
        poly = _step_polyline(c, tol=step_tol * cell, direction=direction, snap_angle=snap_angle,
                              closed=closed)
        if poly is None or (closed and len(poly) < 4):
            # too few vertices for straight pieces (a small island): its simplified outline
            poly = _dp(c, cell)
            if closed and len(poly) < 4:
                poly = c
        return poly if closed else _extend(poly, ext)

    snaked = [None] * len(steps)
    if step_snake and steps:
        try:
            snaked = snake_steps([c for _, c, _ in steps], [cl for _, _, cl in steps], cell=cell,
                                 direction=direction, window=snake_window, snake_cell=snake_cell)
        except (AlgorithmError, InputError) as exc:
            # a solve the snake refuses (a table over its limit, a degenerate graph):
            # the step chains keep their split-and-merge pieces
            logger.debug("step snake skipped (%s)", exc)
            snaked = [None] * len(steps)
    for (i, c, cl), poly in zip(steps, snaked, strict=True):
        if poly is not None:
            segs[i] = poly if cl else _extend(poly, ext)
        elif segs[i] is None:
            segs[i] = pieces(c, cl)
    return segs, kinds


def extend_to_hits(segments, footprint, *, max_ext, eps=1e-3):
    """Open polylines lengthened at each end, along their end segment, to the first line they
    meet (another polyline or the footprint outline), at most ``max_ext`` (m), plus ``eps``.

    So the boundaries close the cells they are meant to close even when a chain
    stopped short of its junction; a polyline that meets nothing keeps its end.
    """
    import shapely

    segments = [np.array(s, dtype=float) for s in segments]
    rings = [np.asarray(r.coords) for r in shapely.get_rings(footprint)]
    # the outline and the polylines cut into their straight pieces: a ray is tested against
    # the few pieces near it, not against every vertex of a long line whose box it meets
    # (the long outline of a large block met most rays); the hits are the same points
    chains = rings + [s for s in segments if len(s) >= 2]
    pieces = np.concatenate([np.stack([c[:-1], c[1:]], axis=1) for c in chains])
    lines = shapely.linestrings(pieces[np.any(pieces[:, 0] != pieces[:, 1], axis=1)])
    rays, where = [], []
    for k, s in enumerate(segments):
        if len(s) < 2 or _close_points(s[0], s[-1]):
            continue
        for i, j in ((0, 1), (-1, -2)):
            d = s[i] - s[j]
            n = np.hypot(*d)
            if n < 1e-9:
                continue
            d = d / n
            rays.append(np.array([s[i] + d * 1e-6, s[i] + d * max_ext]))
            where.append((k, i, d))
    out = [s.copy() for s in segments]
    if not rays:
        return out
    # each ray against the pieces whose boxes meet the ray's first ``reach`` metres (an
    # index, not every piece), ``reach`` growing while rays are left without a hit in it:
    # a ray across a large block is not cut with every line it crosses (its first hit is
    # what counts). The candidates' crossings are placed along the ray in closed form, and
    # GEOS cuts the ray only with those at its first crossing (and with pieces parallel to
    # it): the hits kept are GEOS's, the first the same as with every line
    tree = shapely.STRtree(lines)
    ends = np.stack(rays)
    dirs = np.array([w[2] for w in where])
    base = np.array([segments[k][i] for k, i, _ in where])
    rays = shapely.linestrings(ends)
    seg_xy = shapely.get_coordinates(lines).reshape(-1, 2, 2)
    todo = np.arange(len(rays))
    # a small footprint's rays in one round: its few pieces cost less than the rounds
    reach = _FIRST_REACH if max_ext > _ONE_ROUND else max_ext
    while len(todo):
        last = reach >= max_ext
        if last:
            lo, hi = np.minimum(ends[todo, 0], ends[todo, 1]), np.maximum(ends[todo, 0], ends[todo, 1])
        else:
            near = base[todo] + dirs[todo] * reach
            lo, hi = np.minimum(ends[todo, 0], near), np.maximum(ends[todo, 0], near)
        ir, il = tree.query(shapely.box(*(lo - _REACH_PAD).T, *(hi + _REACH_PAD).T))
        order = np.lexsort((il, ir))
        ir, il = todo[ir[order]], il[order]
        keep = _first_crossings(ir, il, base, dirs, seg_xy, max_ext)
        done = _cut_first(rays, lines, ir[keep], il[keep], where, segments, out, eps,
                          None if last else reach)
        left = ~np.isin(todo, done)
        if last:
            # a first crossing GEOS did not confirm (a near miss): every piece then
            again = np.isin(ir, todo[left])
            if (again & ~keep).any():
                _cut_first(rays, lines, ir[again], il[again], where, segments, out, eps, None)
            break
        todo = todo[left]
        reach *= 4
    return out


#: the first length (m) of the rays of :func:`extend_to_hits` tested, and the margin (m) of
#: their boxes (a hit computed on the whole ray lies off it by rounding only)
_FIRST_REACH = 2.0
#: the longest rays (m: the footprint's diagonal) tested whole in one round: a small
#: footprint's few pieces cost less than the rounds' calls (Delft's 132 BGT footprints,
#: diagonals of 4.5-38 m: 0.13 -> 0.094 CPU s, the same hits; `bench_traced_kernels.py
#: --only extend_to_hits --footprints`)
_ONE_ROUND = 32.0
_REACH_PAD = 1e-6
#: how far (m) along a ray a crossing placed in closed form may lie from GEOS's
_CROSS_TOL = 1e-7


def _first_crossings(ray, piece, base, dirs, seg_xy, max_ext):
    """Mask of the (ray, piece) pairs (ray ids sorted) worth cutting: the pieces crossing
    the ray within :data:`_CROSS_TOL` of its first crossing in closed form, pieces
    parallel to it, and every piece of a ray with no crossing found (GEOS decides)."""
    p, d = base[ray], dirs[ray]
    a, e = seg_xy[piece, 0], seg_xy[piece, 1] - seg_xy[piece, 0]
    den = d[:, 0] * e[:, 1] - d[:, 1] * e[:, 0]
    w = a - p
    scale = np.hypot(e[:, 0], e[:, 1])
    par = np.abs(den) <= 1e-9 * np.maximum(scale, 1e-300)
    safe = np.where(par, 1.0, den)
    t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / safe
    u = (w[:, 0] * d[:, 1] - w[:, 1] * d[:, 0]) / safe
    tol_u = _CROSS_TOL / np.maximum(scale, 1e-300)
    # the ray starts 1e-6 m past its polyline's end (the piece ending there is no hit)
    cross = ~par & (u >= -tol_u) & (u <= 1 + tol_u) & (t >= 1e-6 - _CROSS_TOL) \
        & (t <= max_ext + _CROSS_TOL)
    first = np.full(int(ray.max()) + 1 if len(ray) else 0, np.inf)
    np.minimum.at(first, ray[cross], t[cross])
    # the first crossing's pieces; a ray with none keeps every candidate
    return par | (cross & (t <= first[ray] + 2 * _CROSS_TOL)) | ~np.isfinite(first[ray])


def _cut_first(rays, lines, ir, il, where, segments, out, eps, reach):
    """GEOS's hits of rays ``ir`` with pieces ``il`` (sorted by ray); each ray's end moved to
    its first hit (plus ``eps``) unless that lies beyond ``reach``; returns the rays done."""
    import shapely

    hits = shapely.intersection(rays[ir], lines[il])
    coords, counts = shapely.get_coordinates(hits), shapely.get_num_coordinates(hits)
    owner = np.repeat(ir, counts)
    done = []
    if not len(owner):
        return np.zeros(0, dtype=np.int64)
    starts = np.concatenate(([0], np.flatnonzero(np.diff(owner)) + 1))
    for a, b in zip(starts, np.concatenate((starts[1:], [len(owner)])), strict=True):
        k, i, d = where[owner[a]]
        t = (coords[a:b] - segments[k][i]) @ d
        if reach is not None and t.min() > reach:
            continue  # a hit beyond the box: a nearer one may lie outside it
        out[k][i] = segments[k][i] + d * (t.min() + eps)
        done.append(owner[a])
    return np.asarray(done, dtype=np.int64)


def _cell_points(cells, xyz):
    """``(ip, ic, counts)``: the points in the cells (indices into ``xyz``) and the cell of
    each, a point on a shared edge in its first cell only; the count per cell (float)."""
    ip, ic = _point_cells(cells, xyz[:, :2])
    return ip, ic, np.bincount(ic, minlength=len(cells)).astype(float)


#: (cell, point) pairs tested together by :func:`_point_cells`
_PAIR_BATCH = 1 << 17


def _point_cells(cells, xy):
    """``(points, cells)``: the points of ``xy`` (n, 2) in a cell and the cell of each, in
    point order; a point on a shared edge counts once, in its first cell as an STRtree
    query of the points against the cells orders them.

    Each cell (prepared) tests only the points in its box, found on the points sorted by
    x: half the CPU of querying every point against the tree. The few points in several
    cells are put to the tree's query for its order, so the answer is the query's.
    """
    import shapely

    arr = np.asarray(cells, dtype=object)
    shapely.prepare(arr)
    box = shapely.bounds(arr)
    order = np.argsort(xy[:, 0], kind="stable")
    xs = xy[order, 0]
    lo, hi = np.searchsorted(xs, box[:, 0], side="left"), np.searchsorted(xs, box[:, 2], side="right")
    cell_of = np.full(len(xy), -1, dtype=np.int64)
    hits = np.zeros(len(xy), dtype=np.int64)
    # the (cell, point) pairs of the cells' x ranges, a batch of cells at a time (bounded
    # memory), tested in one call each: a point in one cell only gets that cell, the
    # others are settled by the tree's query below
    span = hi - lo
    j0 = 0
    while j0 < len(arr):
        j1 = j0 + 1 + int(np.searchsorted(np.cumsum(span[j0 + 1:]), _PAIR_BATCH - span[j0], side="right"))
        js = np.repeat(np.arange(j0, j1), span[j0:j1])
        first = np.cumsum(span[j0:j1]) - span[j0:j1]
        cand = order[lo[js] + np.arange(len(js)) - np.repeat(first, span[j0:j1])]
        y = xy[cand, 1]
        inbox = (y >= box[js, 1]) & (y <= box[js, 3])
        js, cand = js[inbox], cand[inbox]
        inside = shapely.intersects_xy(arr[js], xy[cand, 0], xy[cand, 1])
        js, cand = js[inside], cand[inside]
        cell_of[cand] = js
        hits += np.bincount(cand, minlength=len(xy))
        j0 = j1
    multi = np.flatnonzero(hits > 1)
    if len(multi):
        ip, ic = shapely.STRtree(arr).query(shapely.points(xy[multi]), predicate="intersects")
        first = np.unique(ip, return_index=True)[1]
        cell_of[multi[ip[first]]] = ic[first]
    ip = np.flatnonzero(cell_of >= 0)
    return ip, cell_of[ip]


def _cell_labels(cells, xyz, planes, cap):
    """Per cell: the plane with the least capped residual sum of its points, and point counts."""
    n = len(cells)
    ip, ic, counts = _cell_points(cells, xyz)
    cost = np.zeros((n, len(planes)))
    # a plane at a time: a block of many houses has ~1e4-1e5 points and ~1e2 planes;
    # bincount adds each cell's residuals in point order, as a running sum from zero
    x, y, z = xyz[ip, 0], xyz[ip, 1], xyz[ip, 2]
    for k, (a, b, c) in enumerate(planes[:, :3]):
        res = np.abs(z - (x * a + y * b + c))
        cost[:, k] = np.bincount(ic, weights=np.minimum(res, cap), minlength=n)
    labels = np.where(counts > 0, np.argmin(cost, axis=1), -1)
    return labels, counts


def _nearest(pts, queries, tree_type):
    """Index into ``pts`` of the nearest point to each query: ``tree_type(pts).query``'s
    answer. Small sets (the usual rim candidates) by brute force, which gives the same
    index whenever the nearest point is clear of the second by more than rounding; any
    query with a (near) tie, and large sets, go to the tree."""
    if len(pts) * len(queries) <= 65_536 and len(pts) >= 2:
        d2 = (queries[:, None, 0] - pts[None, :, 0]) ** 2 + (queries[:, None, 1] - pts[None, :, 1]) ** 2
        two = np.partition(d2, 1, axis=1)[:, :2]
        if np.all(two[:, 1] > two[:, 0] * (1.0 + 1e-9) + 1e-300):
            return np.argmin(d2, axis=1)
    return tree_type(pts).query(queries)[1]


def rim_strips(footprint, xyz, labels, planes, *, cell, t_step=0.3, level_tol=0.1, min_points=6,
               outside=0.5):
    """Raised rims along the outline (parapet tops): level runs of points above the roof inside.

    A rim is too narrow for the label grid and the faces (narrower than a cell,
    it would join the roof inside it), and its points are often unlabelled (their
    normals lean to the walls on both sides) or labelled with a plane at the
    same height elsewhere. Per outline edge, the points inside the footprint
    within 1.5 ``cell`` of it are taken at their most common height (within
    ``level_tol``); a run of at least ``min_points`` of them, no gap longer than
    3 cells and at least 6 cells long, is a rim when it stands ``t_step`` above
    the plane of the roof just inside it (evaluated under the rim: a roof
    sloping up to the edge is no rim), and when the points just outside the
    edge (up to ``outside`` m) do not continue at its height (that is a taller
    neighbour's roof reaching over the outline, not ours).

    Returns
    -------
    list of (z, members, line, width, label)
        The rim's height, the indices of its points, its inner step line (2, 2)
        (the edge section offset inwards by the rim's width), that width (m), and
        the rim's own facet when the segmentation found it (else -1).
    """
    import shapely
    from scipy.spatial import cKDTree

    xyz = np.asarray(xyz, dtype=np.float64)
    xy = xyz[:, :2]
    inside = shapely.contains_xy(footprint, xy[:, 0], xy[:, 1])
    rims = []
    d_out = None  # distances to the outline, of the points that need them (a rim facet's)
    for ring in shapely.get_rings(footprint):
        c = np.asarray(ring.coords)
        for a, b in zip(c[:-1], c[1:], strict=True):
            L = float(np.hypot(*(b - a)))
            if L < 6 * cell:
                continue
            u = (b - a) / L
            nrm = np.array([-u[1], u[0]])  # made to point into the footprint
            if not footprint.contains(shapely.Point((a + b) / 2 + 0.1 * cell * nrm)):
                nrm = -nrm
            rel = xy - a
            t, d = rel @ u, rel @ nrm
            along = (t > -cell) & (t < L + cell)
            cand = np.flatnonzero(inside & along & (d > -1e-9) & (d < 1.5 * cell))
            inner = np.flatnonzero(inside & along & (labels >= 0) & (d >= 1.5 * cell) & (d < 4.5 * cell))
            if len(cand) < min_points or not len(inner):
                continue
            # only points standing t_step above the plane of the nearest roof point inside
            near = inner[_nearest(xy[inner], xy[cand], cKDTree)]
            pl = planes[labels[near]]
            cand = cand[xyz[cand, 2] - np.einsum("ij,ij->i", xy[cand], pl[:, :2]) - pl[:, 2] >= t_step]
            if len(cand) < min_points:
                continue
            z = xyz[cand, 2]
            support = (np.abs(z[:, None] - z[None, :]) <= level_tol).sum(axis=1)
            z0 = float(median(z[np.abs(z - z[np.lexsort((-z, -support))[0]]) <= level_tol]))
            members = cand[np.abs(z - z0) <= level_tol]
            members = members[np.argsort(t[members], kind="stable")]
            gaps = np.flatnonzero(np.diff(t[members]) > 3 * cell)
            for run in np.split(members, gaps + 1):
                if len(run) < min_points or t[run[-1]] - t[run[0]] < 6 * cell:
                    continue
                lo, hi = t[run[0]], t[run[-1]]
                width = float(np.clip(np.max(d[run]) + cell / 4, cell / 2, 3 * cell))
                zone = along & (t >= lo) & (t <= hi)
                inner = zone & inside & (labels >= 0) & (d > width + cell) & (d < width + 4 * cell)
                if inner.sum() < min_points:
                    continue
                inner_label = np.bincount(labels[inner]).argmax()
                pl = planes[inner_label]
                if median(xyz[run, 2] - xy[run] @ pl[:2] - pl[2]) < t_step:
                    continue
                # the segmentation's own rim facet: most of the run on one facet other than the
                # roof inside, that facet's points along the outline
                own = labels[run]
                own = int(np.bincount(own[own >= 0]).argmax()) if (own >= 0).sum() > len(run) / 2 else -1
                if own >= 0 and own != inner_label:
                    if d_out is None:
                        d_out = np.full(len(xy), np.nan)
                    on = np.flatnonzero(labels == own)
                    todo = on[np.isnan(d_out[on])]
                    d_out[todo] = shapely.distance(footprint.boundary, shapely.points(xy[todo]))
                    if np.mean(d_out[on] < width + 1.5 * cell) < 0.8:
                        own = -1
                elif own >= 0:
                    own = -1
                out = zone & ~inside & (d < -outside / 2) & (d > -outside)
                if out.sum() and np.mean(np.abs(xyz[out, 2] - z0) <= 2 * level_tol) >= 0.3:
                    continue
                lo = 0.0 if lo < 3 * cell else lo - cell
                hi = L if hi > L - 3 * cell else hi + cell
                line = np.array([a + lo * u + width * nrm, a + hi * u + width * nrm])
                rims.append((z0, run, line, width, own))
    return rims


def roof_lines(footprint, xyz, labels, planes, *, cell, direction, t_step=0.3, max_shift=1.0,
               snap_angle=15.0, cap=None, step_snake=False, snake_window=3, snake_cell=0.5):
    """The straight boundary polylines of a footprint's roof facets, before any rim.

    The label grid of the facets (:func:`.topology.label_grid`), its inner
    boundary chains, and their polylines (:func:`chain_segments`, with the points
    for the intersection test). It is the costly part of
    :func:`arrangement_partition` and does not depend on its ``rims``: the
    partitions with and without rims take the same ``lines``.

    Parameters are those of :func:`arrangement_partition`.

    Returns
    -------
    segments : list of ndarray (m, 2)
    kinds : list of str
    """
    planes = np.asarray(planes, dtype=np.float64)
    cap = 1.5 * t_step if cap is None else cap
    grid = label_grid(footprint, xyz[:, :2], labels, cell=cell)
    chains, pairs = boundary_chains(grid)
    return chain_segments(chains, pairs, planes, cell=cell, direction=direction, t_step=t_step,
                          max_shift=max_shift, snap_angle=snap_angle,
                          points=(xyz, labels), cap=cap,
                          step_snake=step_snake, snake_window=snake_window, snake_cell=snake_cell)


def arrangement_partition(footprint, xyz, labels, planes, *, cell, direction, t_step=0.3,
                          max_shift=1.0, snap_angle=15.0, min_face_area=None, cap=None, rims=True,
                          step_snake=False, snake_window=3, snake_cell=0.5, lines=None):
    """A partition of a footprint polygon into roof faces with straight boundaries.

    Parameters
    ----------
    footprint : shapely Polygon (local metres)
    xyz : ndarray (N, 3)
        Roof points.
    labels : ndarray (N,)
        Facet per point (-1 none), indexing ``planes`` (K, 3).
    cell : float
        Label grid cell (m).
    direction : float
        Building direction (rad).
    t_step, max_shift, snap_angle : see :func:`chain_segments`.
    min_face_area : float, optional
        Smallest face (m2); default 4 cells.
    cap : float, optional
        Residual cap (m) of the cell labelling; default ``1.5 * t_step``.
    rims : bool
        Recover raised rims along the outline (parapet tops, :func:`rim_strips`) as
        narrow level faces of their own, kept however narrow.
    step_snake : bool
        Step edges from the exact 2-D snake (:func:`snake_steps`, half-window
        ``snake_window``, grid step ``snake_cell`` cells).
    lines : (segments, kinds), optional
        :func:`roof_lines` of the same footprint, points, planes and parameters,
        when already computed (not modified); computed here when None.

    Returns
    -------
    faces : list of shapely Polygon
    face_labels : ndarray of int
    kinds : list of str
        The kind of each boundary polyline used: ``"intersection"``, ``"step"`` or
        ``"rim"`` (a rim's inner step line).
    planes : ndarray (K', 3)
        ``planes`` and after them one level plane per rim found.
    """
    import shapely

    planes = np.asarray(planes, dtype=np.float64)
    min_face_area = 4 * cell * cell if min_face_area is None else min_face_area
    cap = 1.5 * t_step if cap is None else cap
    if lines is None:
        lines = roof_lines(footprint, xyz, labels, planes, cell=cell, direction=direction,
                           t_step=t_step, max_shift=max_shift, snap_angle=snap_angle, cap=cap,
                           step_snake=step_snake, snake_window=snake_window,
                           snake_cell=snake_cell)
    segs, kinds = list(lines[0]), list(lines[1])
    n_planes = len(planes)
    found = rim_strips(footprint, xyz, labels, planes, cell=cell, t_step=t_step) if rims and n_planes else []
    # every rim's inner line is a step (the label grid cannot hold a strip narrower than a
    # cell); a rim without a facet of its own gets a level plane, its points labelled with it
    exempt = sorted({rim[4] for rim in found if rim[4] >= 0})
    new = [rim for rim in found if rim[4] < 0]
    for rim in found:
        segs.append(rim[2])
        kinds.append("rim")
    if new:
        labels = labels.copy()
        for k, rim in enumerate(new):
            labels[rim[1]] = n_planes + k
        planes = np.vstack([planes, [[0.0, 0.0, rim[0]] for rim in new]])
        exempt += list(range(n_planes, len(planes)))
    x0, y0, x1, y1 = footprint.bounds
    segs = extend_to_hits(segs, footprint, max_ext=float(np.hypot(x1 - x0, y1 - y0)))
    cells = arrangement_cells(footprint, segs)
    if n_planes == 0 or not cells:
        return [footprint], np.zeros(1, dtype=np.int64), kinds, planes
    cell_lab, counts = _cell_labels(cells, xyz, planes, cap)
    rim = np.isin(cell_lab, exempt)
    if rim.any():
        # a rim's plane labels only the cells of its strip (within its width of its line's
        # outline section): elsewhere a new rim plane gives way to the best of the others,
        # and the cells of a rim facet found by the segmentation are held to the smallest
        # face as any other
        zone = shapely.union_all([shapely.LineString(line).buffer(width + cell / 2, cap_style="flat")
                                  for _, _, line, width, _ in found])
        far = rim & ~shapely.within(shapely.point_on_surface(np.asarray(cells, dtype=object)), zone)
        idx = np.flatnonzero(far & (cell_lab >= n_planes))
        if len(idx):
            relab, _ = _cell_labels([cells[i] for i in idx], xyz, planes[:n_planes], cap)
            cell_lab[idx] = relab
        rim &= ~far
    if rim.any():
        # rims are narrow by nature: first empty cells join a neighbour and same-plane cells
        # dissolve, then only the faces off the rims are held to the smallest area and width
        merged, merged_labels = dissolve_cells(cells, cell_lab, weights=counts)
        on = _on_rims(merged, merged_labels, exempt, [cells[i] for i in np.flatnonzero(rim)])
        merged_counts = _cell_points(merged, xyz)[2]
        keep = np.flatnonzero(~on)
        faces, face_labels = dissolve_cells([merged[i] for i in keep], merged_labels[keep],
                                            min_area=min_face_area, weights=merged_counts[keep],
                                            min_width=cell)
        faces = faces + [merged[i] for i in np.flatnonzero(on)]
        face_labels = np.concatenate([face_labels, merged_labels[on]])
    else:
        faces, face_labels = dissolve_cells(cells, cell_lab, min_area=min_face_area, weights=counts,
                                            min_width=cell)
    if not faces or (face_labels < 0).any():
        return [footprint], np.zeros(1, dtype=np.int64) + max(int(np.bincount(
            labels[labels >= 0]).argmax()) if (labels >= 0).any() else 0, 0), kinds, planes
    return faces, face_labels, kinds, planes


def _on_rims(faces, face_labels, exempt, rim_cells):
    """Which faces are rims, kept however narrow: those with a rim label (``exempt``)
    holding one of the rim strips' cells (``rim_cells``). A face of a rim facet's label
    made only of cells off the strips is held to the smallest area as any other."""
    import shapely

    on = np.isin(face_labels, exempt)
    idx = np.flatnonzero(on)
    if len(idx) and rim_cells:
        probe = shapely.get_coordinates(shapely.point_on_surface(np.asarray(rim_cells, dtype=object)))
        for i in idx:
            on[i] = bool(shapely.contains_xy(faces[i], probe[:, 0], probe[:, 1]).any())
    return on


def _spike_free(ring):
    """:func:`.refine._remove_spikes` of a ring (m, 2) as an array; a ring without a spike
    (the usual one) is found so by one vectorised test and returned as it is."""
    from .refine import _remove_spikes

    if len(ring) >= 3:
        gap = np.concatenate([ring[-1:], ring[:-1]]) - np.concatenate([ring[1:], ring[:1]])
        if not (np.hypot(gap[:, 0], gap[:, 1]) < 1e-6).any():
            return ring
    return np.asarray(_remove_spikes(list(ring)), dtype=float).reshape(-1, 2)


def _as_rebuilt(faces, rings, rebuild_face):
    """``[rebuild_face(fi, {}) for fi in range(len(faces))]`` of :func:`collapse_short_edges`:
    a face none of whose rings repeats a vertex (within 1e-9 m of the one before it, or the
    last of the first) or turns back on itself (:func:`_spike_free`'s test) comes back as
    it is (the same coordinates), tested for all rings at once; the others are rebuilt."""
    import shapely

    flat = [r for rs in rings for r in rs]
    if not flat:
        return []
    sizes = np.fromiter(map(len, flat), dtype=np.int64, count=len(flat))
    xy = np.concatenate(flat)
    prev, nxt = _ring_neighbours(sizes)
    back = xy - xy[prev]  # to the vertex before (the first vertex: to the last)
    gap = xy[prev] - xy[nxt]
    ring = np.repeat(np.arange(len(flat)), sizes)
    bad = np.zeros(len(flat), dtype=bool)
    np.logical_or.at(bad, ring, np.hypot(back[:, 0], back[:, 1]) <= 1e-9)
    np.logical_or.at(bad, ring, (np.hypot(gap[:, 0], gap[:, 1]) < 1e-6) & (sizes[ring] >= 3))
    bad |= sizes < 3
    owner = np.repeat(np.arange(len(rings)), [len(rs) for rs in rings])
    redo = np.zeros(len(rings), dtype=bool)
    np.logical_or.at(redo, owner, bad)
    area = shapely.area(np.asarray(faces, dtype=object))
    return [rebuild_face(fi, {}) if redo[fi] or area[fi] <= 1e-9 else faces[fi]
            for fi in range(len(rings))]


def collapse_short_edges(faces, footprint, *, min_length):
    """A partition without edges shorter than ``min_length`` where they can go.

    The ends of short edges are clustered; a cluster moves to the footprint
    corner in it, else to its one outline vertex, else to its mean (clusters
    holding two footprint corners or two outline vertices stay). Each cluster is
    applied only when every face stays valid, no face shrinks to nothing (a
    narrow rim or a small dormer the partition kept stays) and the faces still
    tile the footprint.

    Parameters
    ----------
    faces : list of shapely Polygon
        A partition of ``footprint`` with shared vertices.
    footprint : shapely Polygon
    min_length : float
        Shortest edge (m) kept.

    Returns
    -------
    faces : list of shapely Polygon
    kept : ndarray of int
        Index into the input faces of each returned face.
    """
    import shapely

    from .solid import _key, _ring_keys

    # every face's rings (without the closing vertex) and their vertex keys, taken at once
    flat_xy, owner, sizes = _flat_rings(faces) if len(faces) else (np.zeros((0, 2)), [], [])
    cuts = np.cumsum(sizes)[:-1].tolist() if len(sizes) else []
    flat_rings = np.split(flat_xy, cuts) if len(sizes) else []
    flat_keys = _ring_keys(flat_xy) if len(flat_xy) else []
    bounds = [0, *cuts, len(flat_keys)]
    rings = [[] for _ in faces]
    ring_keys = [[] for _ in faces]
    for ri, fi in enumerate(np.asarray(owner).tolist()):
        rings[fi].append(flat_rings[ri])
        ring_keys[fi].append(flat_keys[bounds[ri]:bounds[ri + 1]])
    xy_of = {}
    edges = set()
    faces_of: dict = {}  # vertex key -> faces using it
    for fi, rs in enumerate(rings):
        for r, keys in zip(rs, ring_keys[fi], strict=True):
            for k in keys:
                faces_of.setdefault(k, set()).add(fi)
            for p, k in zip(r, keys, strict=True):
                xy_of[k] = p
            for a, b in zip(keys, keys[1:] + keys[:1], strict=True):
                if a != b:
                    edges.add((min(a, b), max(a, b)))
    short = [(a, b) for a, b in sorted(edges) if np.hypot(*(xy_of[a] - xy_of[b])) < min_length]
    if not short:
        return list(faces), np.arange(len(faces))
    parent = {}

    def find(k):
        parent.setdefault(k, k)
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for a, b in short:
        parent[find(a)] = find(b)
    clusters: dict = {}
    for k in list(parent):
        clusters.setdefault(find(k), []).append(k)
    outline = footprint.boundary
    corners = {_key(p) for r in shapely.get_rings(footprint) for p in np.asarray(r.coords)[:-1]}
    total = footprint.area
    mapping: dict = {}

    def rebuild_face(fi, mp):
        new_rs = []
        for r, keys in zip(rings[fi], ring_keys[fi], strict=True):
            moved = [i for i, k in enumerate(keys) if k in mp] if mp else ()
            pts = r
            if moved:
                pts = np.array(r, dtype=float)
                pts[moved] = [mp[keys[i]] for i in moved]
            # a vertex equal to the one before it (moved onto it) goes
            step = pts[1:] - pts[:-1]
            pts = pts[np.concatenate(([True], np.hypot(step[:, 0], step[:, 1]) > 1e-9))]
            if len(pts) > 1 and np.hypot(*(pts[0] - pts[-1])) < 1e-9:
                pts = pts[:-1]
            new_rs.append(_spike_free(pts))
        if len(new_rs[0]) < 3:
            return None
        holes = [shapely.linearrings(h) for h in new_rs[1:] if len(h) >= 3]
        poly = shapely.polygons(shapely.linearrings(new_rs[0]), holes=holes or None)
        return None if shapely.area(poly) <= 1e-9 else poly

    # the faces as of the accepted moves; a cluster rebuilds and checks only the faces
    # using its vertices (the others keep their edges), so each check is local
    current = _as_rebuilt(faces, rings, rebuild_face)
    tol = 1e-6 * max(total, 1)

    def local_ok(old, new):
        # the moved faces stay valid and tile the same region as before (the rest of
        # the partition is untouched, so the whole still tiles the footprint)
        if not all(f.is_valid for f in new):
            return False
        a_old = sum(f.area for f in old)
        if abs(sum(f.area for f in new) - a_old) >= tol:
            return False
        u_new = shapely.union_all(new) if new else shapely.Polygon()
        if abs(u_new.area - a_old) >= tol:
            return False
        u_old = shapely.union_all(old) if old else shapely.Polygon()
        return shapely.symmetric_difference(u_new, u_old).area < tol

    for members in sorted(clusters.values()):
        pts = np.array([xy_of[k] for k in members])
        on = shapely.distance(outline, shapely.points(pts)) < 1e-6
        fixed = [k for k in members if k in corners]
        if len(fixed) > 1 or (not fixed and on.sum() > 1):
            continue
        target = xy_of[fixed[0]] if fixed else (pts[on][0] if on.any() else pts.mean(axis=0))
        trial = {**mapping, **{k: target for k in members}}
        touched = sorted(set().union(*(faces_of.get(k, ()) for k in members)))
        rebuilt = {fi: rebuild_face(fi, trial) for fi in touched}
        if any(f is None and current[fi] is not None for fi, f in rebuilt.items()):
            continue  # a face the partition kept (a rim, a dormer) is not collapsed away
        if local_ok([current[fi] for fi in touched if current[fi] is not None],
                    [f for f in rebuilt.values() if f is not None]):
            mapping = trial
            for fi, f in rebuilt.items():
                current[fi] = f
    if not mapping:
        return list(faces), np.arange(len(faces))
    idx = [fi for fi in range(len(rings)) if current[fi] is not None]
    out = [current[fi] for fi in idx]
    return [shapely.normalize(f) for f in out], np.asarray(idx, dtype=np.int64)




def _covering_height(faces, face_labels, planes, xy):
    """Height (N,) of the face over each point (x, y) on its plane; NaN outside every face."""
    import shapely

    z = np.full(len(xy), np.nan)
    for f, lab in zip(faces, face_labels, strict=True):
        on = np.isnan(z)
        on[on] = shapely.contains_xy(f, xy[on, 0], xy[on, 1])
        z[on] = xy[on] @ planes[lab][:2] + planes[lab][2]
    return z


def _cut_in(faces, face_labels, rect, label):
    """The partition with the polygon ``rect`` cut out of its faces and added as a face of
    facet ``label``: ``(faces, face_labels)``."""
    import shapely

    new_f, new_l = [], []
    for f, lab in zip(faces, face_labels, strict=True):
        parts = [f] if not f.intersects(rect) or f.touches(rect) else shapely.get_parts(f.difference(rect))
        for p in parts:
            if p.geom_type == "Polygon" and p.area > 1e-6:
                new_f.append(p)
                new_l.append(lab)
    new_f.append(shapely.normalize(rect))
    new_l.append(label)
    return new_f, np.asarray(new_l, dtype=np.int64)


def raised_parts(faces, face_labels, footprint, xyz, planes, *, direction, spacing, t_step=0.3,
                 min_points=4, outside=0.5, fit=False):
    """Clusters of points standing above the roof faces (chimneys, small dormers, roof
    boxes), cut in as level rectangles.

    The points inside the footprint more than ``t_step`` above the face over
    them are linked within 1.5 point ``spacing``; a cluster of at least
    ``min_points`` becomes the rectangle of its points in the building's axes
    (``direction``), grown by half a spacing, clipped to the footprint, with a
    level plane at its points' median height; a long thin one (narrower than 3
    spacings and over 3 times as long: a parapet, a wall's top) is left out. A
    cluster whose height goes on
    beyond the outline (30 % or more of the points within ``outside`` m of its
    rectangle, outside the footprint, within ``t_step`` of that height) is a
    neighbour's roof or wall reaching over the outline and stays out. Rectangles
    are cut in the largest cluster first, a spacing apart.

    Returns
    -------
    faces, face_labels, planes
        The partition with the rectangles and ``planes`` with one level plane per
        rectangle appended.
    added : int
        Rectangles cut in.
    lifted : tuple of ndarray
        Only with ``fit=True``: ``(index, level)``, the points (indices into ``xyz``)
        of the clusters cut in and the level of each one's rectangle: what a caller
        needs to bound the change in fit before it builds the solid.
    """
    import shapely
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    xyz = np.asarray(xyz, dtype=np.float64)
    planes = np.asarray(planes, dtype=np.float64)
    inside = shapely.contains_xy(footprint, xyz[:, 0], xyz[:, 1])
    idx = np.flatnonzero(inside)
    above = xyz[idx, 2] - _covering_height(faces, face_labels, planes, xyz[idx, :2])
    up = idx[above > t_step]
    lifted, levels = [], []
    if len(up) < min_points:
        none = list(faces), np.asarray(face_labels, dtype=np.int64), planes, 0
        return (*none, (np.zeros(0, dtype=np.int64), np.zeros(0))) if fit else none
    pairs = cKDTree(xyz[up, :2]).query_pairs(1.5 * spacing, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(up), len(up)))
    n, lab = connected_components(graph, directed=False)
    size = np.bincount(lab, minlength=n)
    c, s = np.cos(direction), np.sin(direction)
    rot = np.array([[c, s], [-s, c]])  # world -> building axes
    taken = shapely.Polygon()
    added, new_planes = 0, []
    faces, face_labels = list(faces), np.asarray(face_labels, dtype=np.int64)
    for k in sorted(np.flatnonzero(size >= min_points), key=lambda k: (-size[k], k)):
        m = up[lab == k]
        z0 = float(np.median(xyz[m, 2]))
        uv = xyz[m, :2] @ rot.T
        lo, hi = uv.min(axis=0) - spacing / 2, uv.max(axis=0) + spacing / 2
        if np.min(hi - lo) < 3 * spacing and np.max(hi - lo) > 3 * np.min(hi - lo):
            continue  # a long thin strip: a parapet, a wall's top, an eave - no compact part
        box = shapely.Polygon(np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]) @ rot)
        rect = box.intersection(footprint)
        if rect.geom_type != "Polygon" or rect.area < spacing * spacing or rect.intersects(taken):
            continue
        out = ~inside & shapely.contains_xy(rect.buffer(outside), xyz[:, 0], xyz[:, 1])
        if out.any() and np.mean(np.abs(xyz[out, 2] - z0) <= t_step) >= 0.3:
            continue  # a neighbour's roof or wall reaching over the outline
        faces, face_labels = _cut_in(faces, face_labels, rect, len(planes) + len(new_planes))
        new_planes.append([0.0, 0.0, z0])
        taken = taken.union(rect.buffer(spacing))
        added += 1
        lifted.append(m)
        levels.append(np.full(len(m), z0))
    if new_planes:
        planes = np.vstack([planes, new_planes])
    if fit:
        lifted = (np.concatenate(lifted), np.concatenate(levels)) if lifted else \
            (np.zeros(0, dtype=np.int64), np.zeros(0))
        return faces, face_labels, planes, added, lifted
    return faces, face_labels, planes, added


def restore_facets(faces, face_labels, footprint, xyz, labels, planes, *, direction, spacing, t_step=0.3,
                   min_area=1.0, max_rms=0.1, max_slope=60.0, min_fill=0.5, outside=0.5):
    """Facets the segmentation found and the partition lost, cut back in as rectangles.

    A facet narrower or smaller than the label grid holds well (a dormer, a
    higher or lower part at the outline, a small terrace) can vanish in the
    partition: its cells join a neighbour's face and its points sit off that
    face. A facet no face carries comes back, on its own plane, when it is well
    supported: its points inside the footprint cover at least ``min_area``
    (points times ``spacing`` squared), its plane fits them within ``max_rms``,
    it is no wall (slope at most ``max_slope`` deg), its points stand more than
    ``t_step`` off the faces over them (median), and they fill at least
    ``min_fill`` of their rectangle: the rectangle of its points in the
    building's axes (``direction``), grown by half the point spacing, clipped
    to the footprint, at least 3 spacings wide (no eave or gutter strip). A
    facet that goes on at its height outside the footprint (30 % or more of the
    points within ``outside`` m of its rectangle, beyond the outline, within
    ``t_step`` of its plane) is a neighbour's roof reaching over the outline
    and stays out. Rectangles are cut into the faces one at a time, the facet
    with most points first, a spacing apart from each other.

    Parameters
    ----------
    faces : list of shapely Polygon
        A partition of ``footprint``.
    face_labels : ndarray of int
        Facet (index into ``planes``) of each face.
    footprint : shapely Polygon
    xyz : ndarray (N, 3)
        Roof points; ``labels`` (N,) their facets (-1 none).
    planes : ndarray (K, 3)
    direction : float
        Building direction (rad).
    spacing : float
        Point spacing (m).

    Returns
    -------
    faces : list of shapely Polygon
    face_labels : ndarray of int
    restored : int
        Rectangles cut in.
    """
    import shapely

    faces = list(faces)
    face_labels = np.asarray(face_labels, dtype=np.int64)
    planes = np.asarray(planes, dtype=np.float64)
    xyz = np.asarray(xyz, dtype=np.float64)
    inside = shapely.contains_xy(footprint, xyz[:, 0], xyz[:, 1])
    min_n = max(4, int(np.ceil(min_area / (spacing * spacing))))
    kept = set(face_labels.tolist())
    cand = []
    for k in range(len(planes)):
        m = np.flatnonzero((labels == k) & inside)
        if k in kept or len(m) < min_n:
            continue
        pl = planes[k]
        res = xyz[m, 2] - xyz[m, :2] @ pl[:2] - pl[2]
        if np.degrees(np.arctan(np.hypot(pl[0], pl[1]))) <= max_slope and np.sqrt(np.mean(res ** 2)) <= max_rms:
            cand.append((-len(m), k, m))
    if not cand:
        return faces, face_labels, 0
    c, s = np.cos(direction), np.sin(direction)
    rot = np.array([[c, s], [-s, c]])  # world -> building axes
    taken = shapely.Polygon()
    restored = 0
    for _, k, m in sorted(cand, key=lambda t: t[:2]):
        pts, pl = xyz[m], planes[k]
        model = _covering_height(faces, face_labels, planes, pts[:, :2])
        if not np.isfinite(model).any() or np.nanmedian(np.abs(pts[:, 2] - model)) <= t_step:
            continue
        uv = pts[:, :2] @ rot.T
        lo, hi = uv.min(axis=0) - spacing / 2, uv.max(axis=0) + spacing / 2
        if np.min(hi - lo) < 3 * spacing:
            continue  # a strip: an eave, a gutter, a facade's top
        box = shapely.Polygon(np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]) @ rot)
        rect = box.intersection(footprint)
        if (rect.geom_type != "Polygon" or rect.area < min_area or rect.intersects(taken)
                or len(m) * spacing * spacing < min_fill * rect.area):
            continue
        out = ~inside & shapely.contains_xy(rect.buffer(outside), xyz[:, 0], xyz[:, 1])
        if out.any() and np.mean(np.abs(xyz[out, 2] - xyz[out, :2] @ pl[:2] - pl[2]) <= t_step) >= 0.3:
            continue  # a neighbour's roof reaching over the outline
        faces, face_labels = _cut_in(faces, face_labels, rect, k)
        taken = taken.union(rect.buffer(spacing))
        restored += 1
    return faces, face_labels, restored
