"""How well a 3-D model fits the points: point-to-mesh distances, RMSE, coverage.

The distance of a point to a model is the exact Euclidean distance to the
nearest point of its triangulated boundary (faces, not just roofs), as
3DBAG roofer's ``rf_rmse``. It is computed in numpy on (point, triangle)
pairs; a 2-D grid over the triangles' bounding boxes restricts the pairs to
the neighbourhood of each point, and the few points whose nearest triangle
may lie further away fall back to the exact search over all triangles.
"""

from __future__ import annotations

import numpy as np

from ..lod.mesh import cross3, dot3

__all__ = ["point_triangle_distance2", "point_mesh_distance", "rmse", "model_rmse",
           "footprint_coverage"]


_dot = dot3
_cross = cross3


def _segment_distance2(p, a, b):
    ab = b - a
    denom = _dot(ab, ab)
    num = _dot(p - a, ab)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(denom > 0, num / np.where(denom > 0, denom, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    d = p - (a + t[..., None] * ab)
    return _dot(d, d)


def point_triangle_distance2(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                             c: np.ndarray) -> np.ndarray:
    """Squared distance of points to triangles (arrays broadcast together).

    Parameters
    ----------
    p, a, b, c : ndarray, shape (..., 3)
        Points and triangle corners; e.g. ``p`` (K, 3) with ``a, b, c`` (K, 3)
        for row-wise pairs, or ``p[:, None]`` (N, 1, 3) with ``a`` (T, 3) for
        all N x T pairs.

    Returns
    -------
    ndarray, broadcast shape without the last axis

    Notes
    -----
    If the orthogonal projection of ``p`` on the triangle's plane lies inside
    the triangle, the distance is the plane distance; otherwise the nearest
    point is on one of the three edges. Degenerate triangles reduce to the
    edge distances. Exact up to floating point.
    """
    n = _cross(b - a, c - a)
    nn = _dot(n, n)
    inside = ((_dot(_cross(b - a, p - a), n) >= 0) & (_dot(_cross(c - b, p - b), n) >= 0)
              & (_dot(_cross(a - c, p - c), n) >= 0) & (nn > 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        dp = np.where(nn > 0, _dot(p - a, n) ** 2 / np.where(nn > 0, nn, 1.0), np.inf)
    edges = np.minimum(np.minimum(_segment_distance2(p, a, b), _segment_distance2(p, b, c)),
                       _segment_distance2(p, c, a))
    return np.where(inside, dp, edges)


def _unique_edges(tris):
    """Distinct edges (E, 2, 3) of triangles (T, 3, 3), by exact corner coordinates."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    # orient each edge so that its lexicographically smaller end comes first
    a, b = e[:, 0], e[:, 1]
    gt = (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & ((a[:, 1] > b[:, 1]) |
                                                          ((a[:, 1] == b[:, 1]) & (a[:, 2] > b[:, 2]))))
    e = np.where(gt[:, None, None], e[:, ::-1], e)
    return np.unique(e.reshape(len(e), 6), axis=0).reshape(-1, 2, 3)


def _brute(points, tris, chunk_pairs=262_144):
    """Exact nearest distance over all triangles (dense, via matrix products).

    The nearest point of a mesh is either the orthogonal projection on a
    triangle whose interior it falls in, or a point of an edge; so the
    distance is the minimum of the plane distances of the triangles whose
    (in-plane) edge half-spaces contain the point and of the distances to
    every distinct edge. Every term is an affine function of the point, so
    they come from ``(N, 3) @ (3, T)`` products.
    """
    n, t = len(points), len(tris)
    out = np.full(n, np.inf)
    if t == 0 or n == 0:
        return out
    centre = tris.reshape(-1, 3).mean(axis=0)  # keeps squared terms small
    tr = tris - centre
    pts = points - centre
    a, b, c = tr[:, 0], tr[:, 1], tr[:, 2]
    nrm = cross3(b - a, c - a)
    nn = dot3(nrm, nrm)
    ok = nn > 0
    nrm, nn, a, b, c = nrm[ok], nn[ok], a[ok], b[ok], c[ok]
    # in-plane edge normals pointing inside: m_i = n x (v_{i+1} - v_i)
    ms = [cross3(nrm, b - a), cross3(nrm, c - b), cross3(nrm, a - c)]
    cs = [dot3(ms[0], a), dot3(ms[1], b), dot3(ms[2], c)]
    pn = dot3(a, nrm)
    edges = _unique_edges(tr)
    ea, eb = edges[:, 0], edges[:, 1] - edges[:, 0]
    ll = dot3(eb, eb)
    ll_safe = np.where(ll > 0, ll, 1.0)
    ea_eb = dot3(ea, eb)
    ea2 = dot3(ea, ea)
    cols = max(len(nrm), len(ea), 1)
    step = max(1, chunk_pairs // cols)
    for s in range(0, n, step):
        p = pts[s:s + step]
        best = np.full(len(p), np.inf)
        if len(nrm):
            inside = ((p @ ms[0].T >= cs[0]) & (p @ ms[1].T >= cs[1]) & (p @ ms[2].T >= cs[2]))
            dp = (p @ nrm.T - pn) ** 2 / nn
            best = np.where(inside, dp, np.inf).min(axis=1)
        pe = p @ eb.T - ea_eb                             # (p - a) . ab
        tt = np.clip(pe / ll_safe, 0.0, 1.0)
        p2 = dot3(p, p)[:, None]
        pa2 = p2 - 2.0 * (p @ ea.T) + ea2                 # |p - a|^2
        d2 = pa2 - 2.0 * tt * pe + tt * tt * ll
        best = np.minimum(best, np.maximum(d2, 0.0).min(axis=1))
        out[s:s + len(p)] = np.sqrt(best)
    return out


def point_mesh_distance(points, triangles, *, cell: float | None = None,
                        brute_force_pairs: int = 100_000) -> np.ndarray:
    """Exact 3-D distance of each point to the nearest of a set of triangles.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
    triangles : ndarray, shape (T, 3, 3)
        Triangle corners (e.g. :func:`lidar2city.lod.mesh.solid_triangles`).
    cell : float, optional
        Grid cell (metres) of the 2-D prefilter; default about 64 points a
        cell (at least 0.5 m). Each point is compared with the triangles whose
        plan (an STRtree of their 2-D convex hulls) crosses the 3 x 3 cells
        around it; a point whose nearest distance ``d`` found there exceeds
        ``cell`` (so a closer triangle could lie outside) is searched again
        over the triangles crossing the cells within ``d`` of it. The cost
        grows with the number of points times the triangles near each, not
        with all pairs.
    brute_force_pairs : int
        Below ``N * T`` pairs, every pair is evaluated (faster than indexing).

    Returns
    -------
    ndarray, shape (N,)
        Distances (``inf`` when there is no triangle).

    Examples
    --------
    >>> tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=float)
    >>> point_mesh_distance(np.array([[0.2, 0.2, 2.0]]), tri)
    array([2.])
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tris = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    n, t = len(points), len(tris)
    if n == 0:
        return np.zeros(0)
    if t == 0:
        return np.full(n, np.inf)
    if n * t <= brute_force_pairs:
        return _brute(points, tris)
    if cell is None:  # about 64 points per cell
        span = np.ptp(points[:, :2], axis=0)
        cell = float(max(np.sqrt(max(float(span[0] * span[1]), 1e-6) * 64.0 / n), 0.5))
    import shapely

    # each triangle's plan (its convex hull: a segment for a wall) in an STRtree, so that a
    # block of cells gets the triangles that really cross it, not every long thin triangle
    # whose bounding box covers it
    plan = shapely.convex_hull(shapely.multipoints(tris[:, :, :2]))
    tree = shapely.STRtree(plan)
    origin = points[:, :2].min(axis=0)
    pc = np.floor((points[:, :2] - origin) / cell).astype(np.int64)
    ny = int(pc[:, 1].max()) + 1
    pkey = pc[:, 0] * ny + pc[:, 1]
    best = np.full(n, np.inf)

    def search(idx_groups, radii):
        """Nearest distances of each group of points (one cell) over the triangles crossing
        the cells within ``radius`` of theirs."""
        if not idx_groups:
            return
        c = np.array([pc[g[0]] for g in idx_groups], dtype=np.float64)
        r = np.asarray(radii, dtype=np.float64)[:, None]
        boxes = shapely.box(*(origin + (c - r) * cell).T, *(origin + (c + r + 1) * cell).T)
        ib, it = tree.query(boxes, predicate="intersects")
        starts = np.searchsorted(ib, np.arange(len(idx_groups) + 1))
        for k, g in enumerate(idx_groups):
            cand = it[starts[k]:starts[k + 1]]
            if len(cand):
                best[g] = _brute(points[g], tris[np.sort(cand)])

    porder = np.argsort(pkey, kind="stable")
    _, gstart = np.unique(pkey[porder], return_index=True)
    groups = np.split(porder, gstart[1:])
    search(groups, [1] * len(groups))
    # a closer triangle lies within ``best`` of the point: it crosses the cells within
    # ceil(best / cell) around it; search those (every triangle when nothing was found)
    far = best > cell
    if not far.any():
        return best
    lost = far & ~np.isfinite(best)
    if lost.any():
        best[lost] = _brute(points[lost], tris)
    far &= ~lost
    fidx = np.flatnonzero(far)
    forder = np.argsort(pkey[fidx], kind="stable")
    _, fstart = np.unique(pkey[fidx][forder], return_index=True)
    fgroups = np.split(fidx[forder], fstart[1:])
    search(fgroups, [int(np.ceil(best[g].max() / cell)) for g in fgroups])
    return best


def rmse(distances) -> float:
    """Root mean square of distances (NaN when empty)."""
    d = np.asarray(distances, dtype=np.float64)
    return float(np.sqrt(np.mean(d * d))) if len(d) else float("nan")


def model_rmse(points, solids) -> float:
    """RMSE of the 3-D distances from ``points`` (N, 3) to the boundary of ``solids``."""
    from ..lod.mesh import solid_triangles

    return rmse(point_mesh_distance(points, solid_triangles(solids)))


def footprint_coverage(footprint, xy, *, cell: float = 1.0) -> float:
    """Share of a footprint's cells (``cell`` metres) holding at least one point.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
    xy : ndarray, shape (N, 2)
        Points (already selected inside the footprint or not: points outside
        do not count).

    Returns
    -------
    float
        In [0, 1]; 1 - coverage is the share of the footprint without points
        (3DBAG's ``nodata`` fraction). Cells count when their centre is inside.
    """
    import shapely

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    x0, y0, x1, y1 = footprint.bounds
    nx = max(int(np.ceil((x1 - x0) / cell)), 1)
    ny = max(int(np.ceil((y1 - y0) / cell)), 1)
    gx, gy = np.meshgrid(x0 + (np.arange(nx) + 0.5) * cell, y0 + (np.arange(ny) + 0.5) * cell,
                         indexing="ij")
    inside = shapely.contains_xy(footprint, gx.ravel(), gy.ravel()).reshape(nx, ny)
    total = int(inside.sum())
    if total == 0:  # footprint smaller than a cell: covered if any point falls in it
        return 1.0 if len(xy) and shapely.contains_xy(footprint, xy[:, 0], xy[:, 1]).any() else 0.0
    if len(xy) == 0:
        return 0.0
    ix = np.floor((xy[:, 0] - x0) / cell).astype(np.int64)
    iy = np.floor((xy[:, 1] - y0) / cell).astype(np.int64)
    ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
    hit = np.zeros((nx, ny), dtype=bool)
    hit[ix[ok], iy[ok]] = True
    return float((hit & inside).sum() / total)
