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


def _brute(points, tris, chunk_pairs=1_000_000):
    """Exact nearest distance over all triangles, chunked over points."""
    n, t = len(points), len(tris)
    out = np.full(n, np.inf)
    if t == 0 or n == 0:
        return out
    step = max(1, chunk_pairs // t)
    a, b, c = tris[None, :, 0], tris[None, :, 1], tris[None, :, 2]
    for s in range(0, n, step):
        p = points[s:s + step, None, :]
        out[s:s + len(p)] = np.sqrt(point_triangle_distance2(p, a, b, c).min(axis=1))
    return out


def point_mesh_distance(points, triangles, *, cell: float | None = None,
                        brute_force_pairs: int = 4_000_000) -> np.ndarray:
    """Exact 3-D distance of each point to the nearest of a set of triangles.

    Parameters
    ----------
    points : ndarray, shape (N, 3)
    triangles : ndarray, shape (T, 3, 3)
        Triangle corners (e.g. :func:`lidar2city.lod.mesh.solid_triangles`).
    cell : float, optional
        Grid cell (metres) of the 2-D prefilter; default from the triangle
        sizes. Each point is compared with the triangles whose bounding box
        meets the 3 x 3 cells around it; a point whose nearest distance found
        there exceeds ``cell`` (so a closer triangle could lie outside) is
        searched again over all triangles.
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
    lo = tris.min(axis=1)
    hi = tris.max(axis=1)
    if cell is None:
        ext = np.median(np.max(hi[:, :2] - lo[:, :2], axis=1))
        cell = float(max(ext, 1.0))
    origin = np.minimum(lo[:, :2].min(axis=0), points[:, :2].min(axis=0)) - cell
    top = np.maximum(hi[:, :2].max(axis=0), points[:, :2].max(axis=0)) + cell
    nx, ny = (np.floor((top - origin) / cell).astype(np.int64) + 1)
    # triangle -> cells covered by its bbox (CSR)
    i0 = np.floor((lo[:, :2] - origin) / cell).astype(np.int64)
    i1 = np.floor((hi[:, :2] - origin) / cell).astype(np.int64)
    spans = (i1 - i0 + 1)
    counts = spans[:, 0] * spans[:, 1]
    tri_id = np.repeat(np.arange(t), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    cx = i0[tri_id, 0] + local % spans[tri_id, 0]
    cy = i0[tri_id, 1] + local // spans[tri_id, 0]
    key = cx * ny + cy
    order = np.argsort(key, kind="stable")
    key, tri_id = key[order], tri_id[order]
    # point -> 3 x 3 neighbourhood keys
    pc = np.floor((points[:, :2] - origin) / cell).astype(np.int64)
    offs = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)])
    nb = (pc[:, None, 0] + offs[None, :, 0]) * ny + (pc[:, None, 1] + offs[None, :, 1])
    nb = nb.ravel()
    pid = np.repeat(np.arange(n), 9)
    start = np.searchsorted(key, nb, side="left")
    stop = np.searchsorted(key, nb, side="right")
    cnt = stop - start
    pair_p = np.repeat(pid, cnt)
    pair_t = tri_id[np.repeat(start, cnt) + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))]
    # pairs are grouped by point (a triangle may repeat: harmless for a minimum)
    best = np.full(n, np.inf)
    chunk = 2_000_000
    bounds = np.searchsorted(pair_p, np.arange(0, n + 1))
    s = 0
    while s < n:
        e = int(np.searchsorted(bounds, bounds[s] + chunk, side="right")) - 1
        e = min(max(e, s + 1), n)
        lo_i, hi_i = bounds[s], bounds[e]
        if hi_i > lo_i:
            pp, tt = pair_p[lo_i:hi_i], pair_t[lo_i:hi_i]
            d2 = point_triangle_distance2(points[pp], tris[tt, 0], tris[tt, 1], tris[tt, 2])
            starts = bounds[s:e] - lo_i
            has = bounds[s + 1:e + 1] > bounds[s:e]
            red = np.minimum.reduceat(d2, np.minimum(starts, len(d2) - 1))
            best[s:e] = np.where(has, red, np.inf)
        s = e
    best = np.sqrt(best)
    far = best > cell
    if far.any():
        best[far] = _brute(points[far], tris)
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
