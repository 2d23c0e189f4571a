"""Intersection and step edges, and moving topology vertices onto plane intersections.

For each pair of adjacent faces with planes h1, h2, DH(e) = mean over the shared
edge of |h1 - h2| (seed eq. 2). Below ``T_step = 2 dh_T`` (dh_T the elevation
error of the data) the edge is an *intersection edge*, above it a *step edge*.
As the raw boundary can sit off the true ridge by up to the snake window, an
edge whose vertices all lie within ``max_shift`` of the line where the two
planes meet is also an intersection edge: evaluated on that line, DH is 0.

Vertices then move (seed step 6): a vertex on two or more intersection edges to
the joint point of the planes (least squares of their intersection lines); a
vertex on one intersection edge and a step edge or the footprint outline to
the point where the intersection line meets that wall. Intersection edges become
straight. No fake walls remain where roofs meet.
"""

from __future__ import annotations

import collections
import logging

import numpy as np

from .solid import _KEY, _key, _ring_keys

logger = logging.getLogger(__name__)

__all__ = ["edge_types", "refine_partition"]


def _plane_line(pa, pb):
    """The 2-D line where two planes meet: (g, c) with g . (x, y) + c = 0, |g| = 1; None if parallel."""
    g = np.array([pa[0] - pb[0], pa[1] - pb[1]])
    n = np.hypot(*g)
    if n < 1e-3:
        return None
    return g / n, (pa[2] - pb[2]) / n


def edge_types(faces, labels, planes, *, t_step=0.3, max_shift=1.0, samples=10):
    """Classify the shared edges between faces.

    Returns
    -------
    dict
        ``{(i, j): {"type": "intersection" | "step", "dh": float, "line": (g, c) or None}}``
        for every pair of adjacent faces i < j with different labels.
    """
    import shapely

    out = {}
    arr = np.asarray(faces, dtype=object)
    # every touching pair (i, j), i < j, of different labels, in the order of a query per
    # face, and the boundary they share (longer than 1e-9 m), in vectorised calls
    ii, jj = shapely.STRtree(arr).query(arr, predicate="intersects")
    lab = np.asarray(labels)
    keep = (jj > ii) & (lab[ii] != lab[jj]) if len(ii) else np.zeros(0, dtype=bool)
    ii, jj = ii[keep], jj[keep]
    bounds = shapely.boundary(arr)
    shared = shapely.intersection(bounds[ii], bounds[jj])
    length = shapely.length(shared)
    ok = ~shapely.is_empty(shared) & (length > 1e-9)
    ii, jj, shared, length = ii[ok], jj[ok], shared[ok], length[ok]
    # DH: mean |h1 - h2| over points sampled along each shared edge, the samples of all
    # edges in one call (each edge's mean over its own, as alone)
    m = samples * np.maximum(length.astype(np.int64), 1)
    t = (np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m) + 0.5) / np.repeat(m, m)
    pts = shapely.get_coordinates(shapely.line_interpolate_point(np.repeat(shared, m), t,
                                                                 normalized=True))
    pa_all, pb_all = np.asarray(planes)[lab[ii]], np.asarray(planes)[lab[jj]]
    ca, cb = np.repeat(pa_all, m, axis=0), np.repeat(pb_all, m, axis=0)
    gap = np.abs((ca[:, 0] - cb[:, 0]) * pts[:, 0] + (ca[:, 1] - cb[:, 1]) * pts[:, 1]
                 + ca[:, 2] - cb[:, 2])
    ends = np.cumsum(m)
    parts = _merged_parts(shared)
    for e, (i, j, inter) in enumerate(zip(ii.tolist(), jj.tolist(), shared, strict=True)):
        pa, pb = planes[labels[i]], planes[labels[j]]
        dh = float(np.mean(gap[ends[e] - m[e]:ends[e]]))
        line = _plane_line(pa, pb)
        kind = "step"
        if dh < t_step:
            kind = "intersection"
        elif line is not None:
            coords = shapely.get_coordinates(inter)
            dist = np.abs(coords @ line[0] + line[1])
            if dist.max() <= max_shift:
                kind = "intersection"
        if kind == "intersection" and line is None:
            kind = "step"  # coplanar-parallel planes only meet as steps
        out[(i, j)] = {"type": kind, "dh": dh, "line": line, "shared": inter, "planes": (pa, pb),
                       "parts": parts[e]}
    return out


def _merged_parts(shared):
    """The maximal polylines (line-merged; points dropped) of each geometry of ``shared``
    as coordinate arrays (k, 2), in vectorised calls over all of them."""
    import shapely

    out = [[] for _ in range(len(shared))]
    parts, owner = shapely.get_parts(shared, return_index=True)
    tid = shapely.get_type_id(parts)
    keep = (tid == 1) | (tid == 2)  # LineString, LinearRing
    if not keep.any():
        return out
    parts, owner = parts[keep], owner[keep]
    xy, which = shapely.get_coordinates(parts, return_index=True)
    lines = shapely.linestrings(xy, indices=which)
    has, compact = np.unique(owner, return_inverse=True)
    merged = shapely.line_merge(shapely.multilinestrings(lines, indices=compact))
    mparts, mowner = shapely.get_parts(merged, return_index=True)
    xy, which = shapely.get_coordinates(mparts, return_index=True)
    ends = np.cumsum(np.bincount(which, minlength=len(mparts)))[:-1]
    for g, c in zip(has[mowner].tolist(), np.split(xy, ends), strict=True):
        out[g].append(c)
    return out


def _remove_spikes(pts, tol=1e-6):
    """Drop back-and-forth vertices (A, X, A -> A) left when vertices collapse onto each other."""
    pts = [np.asarray(p, dtype=float) for p in pts]
    changed = True
    while changed and len(pts) >= 3:
        changed = False
        n = len(pts)
        for i in range(n):
            a, c = pts[i - 1], pts[(i + 1) % n]
            if np.hypot(*(a - c)) < tol:
                # remove X and one copy of A
                for j in sorted({i, (i + 1) % n}, reverse=True):
                    del pts[j]
                changed = True
                break
    return pts


def _lines_point(lines):
    """Least-squares point of 2-D lines g . x + c = 0."""
    G = np.array([g for g, _ in lines])
    c = np.array([cc for _, cc in lines])
    sol, *_ = np.linalg.lstsq(G, -c, rcond=None)
    return sol


def _segment_line(p, q):
    d = np.asarray(q, float) - np.asarray(p, float)
    n = np.hypot(*d)
    if n < 1e-12:
        return None
    g = np.array([-d[1], d[0]]) / n
    return g, -float(g @ p)


def _split_mixed(coords, edge, t_step, on_line=1e-4):
    """A shared boundary classified as an intersection, split where it leaves the planes'
    line: a straight boundary of the line arrangement that lies exactly on the line
    for part of its length and elsewhere runs where the planes differ by ``t_step`` or
    more (a dormer's valley, then its side wall) keeps the wall vertices. Returns
    ``[(kind, vertices), ...]`` with ``kind`` "intersection" or "step"; other
    boundaries come back whole as one intersection piece."""
    line = edge["line"]
    if len(coords) < 3 or line is None:
        return [("intersection", coords)]
    g, c = line
    pa, pb = edge["planes"]
    on = np.abs(coords @ g + c) < on_line
    mid = (coords[1:] + coords[:-1]) / 2
    dz = np.abs(mid @ (pa[:2] - pb[:2]) + pa[2] - pb[2])
    seg_on = on[1:] & on[:-1]
    seg_step = ~seg_on & (dz >= t_step)
    if not seg_step.any() or not seg_on.any():
        return [("intersection", coords)]
    out, lo = [], 0
    for k in range(1, len(seg_step) + 1):
        if k == len(seg_step) or seg_step[k] != seg_step[lo]:
            piece = coords[lo:k + 1]
            out.append(("step" if seg_step[lo] else "intersection", piece))
            lo = k
    return out


def refine_partition(faces, labels, planes, *, t_step=0.3, max_shift=1.0, snap=0.25, fixed=()):
    """Move vertices onto plane intersections and straighten intersection edges.

    Parameters
    ----------
    faces : list of shapely Polygon
        Partition of the footprint.
    labels : ndarray of int
        Plane index per face.
    planes : ndarray, shape (K, 3)
    t_step : float
        DH threshold (m), 2 x the elevation error of the data.
    max_shift : float
        Largest distance (m) a vertex may move, and the largest distance of an
        edge from its planes' intersection line to count as an intersection edge.
    snap : float
        A moved vertex this close (m) to a fixed vertex lands exactly on it.
    fixed : iterable of (x, y)
        Vertices that must not move (footprint corners are always fixed).

    Returns
    -------
    faces : list of shapely Polygon
        The refined partition (the input when refinement would break it).
    info : dict
        ``intersection`` and ``step`` edge counts, ``moved`` vertices, ``fallback`` flag.
    """
    import shapely

    from .arrangement import _flat_rings, _spike_free

    types = edge_types(faces, labels, planes, t_step=t_step, max_shift=max_shift)
    n_int = sum(v["type"] == "intersection" for v in types.values())
    info = {"intersection": n_int, "step": len(types) - n_int, "moved": 0, "fallback": False,
            "types": {k: v["type"] for k, v in types.items()}}
    if n_int == 0:
        return faces, info
    fixed_keys = {_key(p) for p in fixed}
    # vertex -> incident constraint lines
    inter_lines: dict = {}
    wall_lines: dict = {}
    interior_of_intersection = set()
    for v in types.values():
        coords_parts = [(v["type"], c) for c in v["parts"]]
        if v["type"] == "intersection":
            coords_parts = [q for _, c in coords_parts for q in _split_mixed(c, v, t_step)]
        for kind, coords in coords_parts:
            ends = [coords[0], coords[-1]]
            if kind == "intersection":
                for p in ends:
                    inter_lines.setdefault(_key(p), []).append(v["line"])
                for p in coords[1:-1]:
                    interior_of_intersection.add(_key(p))
            else:
                for a, b in ((coords[0], coords[1]), (coords[-1], coords[-2])):
                    wall_lines.setdefault(_key(a), []).append((a, b))
    # footprint outline segments are walls too
    union = shapely.union_all(faces)
    # every face's rings as given (coordinates without the closing vertex, exterior then
    # holes) and their keys, flat, taken for all faces at once; the rings per face
    flat_xy, ring_owner, ring_sizes = _flat_rings(faces)
    flat_keys = _ring_keys(flat_xy) if len(flat_xy) else []
    ring_sizes = ring_sizes.tolist()
    rings_per_face = np.bincount(ring_owner, minlength=len(faces)).tolist()
    face_count = collections.Counter(flat_keys)  # rings holding each vertex key
    redundant = set()  # straight-outline vertices inside one face carry nothing and block moves
    for ring in shapely.get_rings(union):
        c = np.asarray(ring.coords)[:-1]
        keys = _ring_keys(c)
        nxt = np.roll(np.arange(len(c)), -1)
        u = c[nxt] - c
        w = c - c[np.roll(np.arange(len(c)), 1)]
        # a footprint corner (not collinear with its neighbours) stays fixed
        corner = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0]) > \
            1e-6 * np.hypot(u[:, 0], u[:, 1]) * np.hypot(w[:, 0], w[:, 1])
        for k in range(len(c)):
            wall_lines.setdefault(keys[k], []).extend(((c[k], c[nxt[k]]), (c[k], c[k - 1])))
            if corner[k]:
                fixed_keys.add(keys[k])
            elif face_count.get(keys[k], 0) == 1:
                redundant.add(keys[k])
    outline = union.boundary
    moves, wanted = {}, []
    fixed_pts = np.array(sorted(fixed_keys), dtype=float) / _KEY if fixed_keys else None
    for k, lines in inter_lines.items():
        if k in fixed_keys:
            continue
        p = np.array(k, dtype=float) / _KEY
        uniq = []
        for g, c in lines:
            if not any(abs(abs(g @ g2) - 1) < 1e-9 and abs(c - np.sign(g @ g2) * c2) < 1e-9 for g2, c2 in uniq):
                uniq.append((g, c))
        target = None
        if len(uniq) >= 2:
            G = np.array([g for g, _ in uniq])
            if np.linalg.matrix_rank(G, tol=0.17) == 2:  # lines not nearly parallel (~10 deg)
                target = _lines_point(uniq)
        if target is None:
            line = uniq[0]
            walls = [ln for ln in (_segment_line(a, b) for a, b in wall_lines.get(k, []))
                     if ln is not None]
            best, best_sin = None, 0.17
            for wl in walls:
                s = abs(line[0][0] * wl[0][1] - line[0][1] * wl[0][0])
                if s > best_sin:
                    best, best_sin = wl, s
            if best is not None:
                target = _lines_point([line, best])
            else:
                g, c = line
                target = p - (g @ p + c) * g
        if fixed_pts is not None and len(fixed_pts):
            d = np.hypot(*(fixed_pts - target).T)
            if d.min() <= snap:
                target = fixed_pts[d.argmin()]  # onto the footprint corner itself
        wanted.append((k, p, target))
    if wanted:
        # a vertex on the footprint outline slides along it, never off it (the distances
        # to the outline of every vertex and target in two calls)
        on_p = shapely.distance(outline, shapely.points([p for _, p, _ in wanted])) < 1e-6
        off_t = shapely.distance(outline, shapely.points([t for _, _, t in wanted])) > 1e-6
        for (k, p, target), a, b in zip(wanted, on_p, off_t, strict=True):
            if not (a and b) and np.hypot(*(target - p)) <= max_shift:
                moves[k] = target
    info["moved"] = len(moves)

    # every vertex of every ring, flat, with what a rebuild asks of it: moved (its
    # target), an intersection line's interior, redundant
    moved_at = [i for i, k in enumerate(flat_keys) if k in moves]
    if moved_at:
        flat_xy = flat_xy.copy()
        flat_xy[moved_at] = [moves[flat_keys[i]] for i in moved_at]
    interior = np.fromiter((k in interior_of_intersection for k in flat_keys), dtype=bool,
                           count=len(flat_keys))
    dropped = np.fromiter((k in redundant for k in flat_keys), dtype=bool, count=len(flat_keys))
    ring_ends = np.cumsum(ring_sizes)

    def rebuild(drop_interior):
        gone = dropped | interior if drop_interior else dropped
        rings_all, ring_face, r = [], [], 0
        for fi, n_rings in enumerate(rings_per_face):
            rings = []
            for _ in range(n_rings):
                lo, hi = ring_ends[r] - ring_sizes[r], ring_ends[r]
                r += 1
                pts = flat_xy[lo:hi][~gone[lo:hi]]
                if len(pts) > 1:
                    step = pts[1:] - pts[:-1]
                    if (np.hypot(step[:, 0], step[:, 1]) < 1e-6).any():
                        # a vertex on (or moved onto) the one before: dropped, in order
                        seq = []
                        for q in pts:
                            if seq and np.hypot(*(seq[-1] - q)) < 1e-6:
                                continue
                            seq.append(q)
                        pts = np.asarray(seq).reshape(-1, 2)
                if len(pts) > 1 and np.hypot(*(pts[0] - pts[-1])) < 1e-6:
                    pts = pts[:-1]
                rings.append(_spike_free(pts))
            if len(rings[0]) < 3:
                return None
            for h in [rings[0], *(h for h in rings[1:] if len(h) >= 3)]:
                rings_all.append(h)
                ring_face.append(fi)
        lr = shapely.linearrings(np.concatenate(rings_all),
                                 indices=np.repeat(np.arange(len(rings_all)), list(map(len, rings_all))))
        return shapely.polygons(lr, indices=ring_face)

    total = sum(f.area for f in faces)
    for drop in (True, False):
        new = rebuild(drop)
        if new is None:
            continue
        areas = shapely.area(new)
        if shapely.is_valid(new).all() and (areas > 1e-6).all():
            union_area = shapely.union_all(new).area
            if abs(sum(areas.tolist()) - total) < 1e-6 * max(total, 1) and \
                    abs(union_area - total) < 1e-6 * max(total, 1):
                return list(shapely.normalize(new)), info
    info["fallback"] = True
    logger.debug("refinement would break the partition; keeping the unrefined faces")
    return faces, info
