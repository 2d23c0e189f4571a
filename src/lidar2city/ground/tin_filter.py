"""Progressive TIN densification (Axelsson 2000), vectorised per iteration."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from ._grid import cell_of, grid_spec
from .outliers import _check_positive, _check_xyz, low_outliers

logger = logging.getLogger(__name__)

__all__ = ["ptd", "seeded_tin"]


def ptd(xyz, *, cell: float = 1.0, seed_cell: float = 20.0, seed_tolerance: float = 3.0,
        iteration_angle: float = 20.0, iteration_distance: float = 1.5, threshold: float = 0.5,
        scalar: float = 1.25, max_iterations: int = 60, outlier_radius: float = 5.0,
        outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by progressive TIN densification.

    1. Low outliers (:func:`~lidar2city.ground.low_outliers`) are set aside.
    2. The candidates are the lowest point of every ``cell`` x ``cell`` cell.
    3. Seeds: the lowest candidate of every ``seed_cell`` cell (the largest
       building should fit in one). A seed more than ``seed_tolerance``
       metres above the plane through its Delaunay neighbours (a roof
       filling a whole seed cell) is dropped, three rounds. Four virtual corner points
       continue the seeds' nearest plane to the tile corners so that every
       candidate lies inside the TIN.
    4. Densification: each iteration, a candidate inside a facet whose
       perpendicular distance ``d`` to the facet plane is at most
       ``iteration_distance`` and whose angles ``asin(d / |p - v|)`` to the
       facet's three vertices are at most ``iteration_angle`` degrees is eligible;
       per facet the eligible candidate closest to the plane joins the TIN
       (Axelsson 2000). The TIN is rebuilt and this repeats until no point
       joins or ``max_iterations``.
    5. Every point within ``threshold + scalar * g`` of the final TIN
       (vertical distance, ``g`` the facet's gradient) is ground.

    A cloud without area (one point, a line) has no TIN: its points within
    ``threshold`` of the lowest are ground.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell : float
        Candidate thinning cell (metres): about the point spacing.
    seed_cell : float
        Seed grid cell (metres): about the largest building size.
    seed_tolerance : float
        Height (metres) above its neighbours' mean at which a seed is dropped.
    iteration_angle : float
        Iteration angle (degrees); 20 is the value of the grid of
        ``benchmarks/bench_ground.py --loo --loo-methods ptd`` chosen on the
        seven ISPRS samples + synthetic terrains (10 leaves samp11's
        terraces and steep streets out: 24.7 % against 13.8 %).
    iteration_distance : float
        Iteration distance (metres).
    threshold, scalar : float
        Final height tolerance around the TIN (metres, metres per unit slope).
    max_iterations : int
        Densification iterations at most.
    outlier_radius, outlier_depth : float
        Low outliers (see :func:`~lidar2city.ground.low_outliers`).

    Returns
    -------
    ndarray of bool, shape (N,)
        True for ground points (low outliers never are).

    Raises
    ------
    InputError
        Wrong shape, NaN coordinates or invalid parameters.

    References
    ----------
    Axelsson, P. (2000). DEM generation from laser scanner data using
    adaptive TIN models. International Archives of Photogrammetry and
    Remote Sensing 33 (B4), 110-117.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> z = 0.5 * g[:, 0] + np.where((abs(g[:, 0] - 30) < 6) & (abs(g[:, 1] - 30) < 6), 8.0, 0.0)
    >>> ground = ptd(np.column_stack([g, z]))
    >>> bool(ground[z - 0.5 * g[:, 0] == 0].all()), bool(ground[z - 0.5 * g[:, 0] == 8].any())
    (True, False)
    """
    xyz = _check_xyz(xyz)
    _check_positive(cell=cell, seed_cell=seed_cell, seed_tolerance=seed_tolerance,
                    iteration_angle=iteration_angle, iteration_distance=iteration_distance,
                    threshold=threshold, outlier_radius=outlier_radius,
                    outlier_depth=outlier_depth)
    if not scalar >= 0:
        raise InputError(f"scalar must be >= 0, got {scalar!r}")
    if not iteration_angle < 90:
        raise InputError(f"iteration_angle must be below 90 degrees, got {iteration_angle!r}")
    if not (isinstance(max_iterations, (int, np.integer)) and max_iterations >= 0):
        raise InputError(f"max_iterations must be an integer >= 0, got {max_iterations!r}")
    n = len(xyz)
    outliers = (low_outliers(xyz, radius=outlier_radius, depth=outlier_depth)
                if n and np.isfinite(outlier_depth) else np.zeros(n, dtype=bool))
    keep = np.flatnonzero(~outliers)
    ground = np.zeros(n, dtype=bool)
    if len(keep) == 0:
        return ground
    # float64 coordinates relative to the lowest corner keep the TIN well conditioned
    origin = xyz[keep].min(axis=0)
    pts = xyz - origin
    lo, hi = pts[keep, :2].min(axis=0), pts[keep, :2].max(axis=0)
    if np.any(hi - lo <= 0):
        # one point or a line: no TIN; the points within threshold of the lowest
        ground[keep] = pts[keep, 2] <= threshold
        return ground
    cand = keep[_lowest_per_cell(pts[keep], cell)]
    seeds = cand[_lowest_per_cell(pts[cand], seed_cell)]
    seeds = _drop_raised_seeds(pts, seeds, seed_tolerance)
    surface, grad = _grown_surface(pts, cand, seeds, lo - cell, hi + cell,
                                   iteration_angle=iteration_angle,
                                   iteration_distance=iteration_distance,
                                   max_iterations=max_iterations)
    ground = np.abs(pts[:, 2] - surface) <= threshold + scalar * grad
    return ground & ~outliers


def _grown_surface(pts, cand, seeds, lo, hi, **densify):
    """Height and gradient at every point of ``pts`` of the TIN grown (:func:`_densify`) from
    ``seeds`` by ``cand`` (indices into ``pts``), virtual corners at ``lo`` - ``hi``."""
    corners = _virtual_corners(pts[seeds], lo, hi)
    in_tin = np.zeros(len(pts), dtype=bool)
    in_tin[seeds] = True
    tri, tin_pts = _densify(pts, cand, in_tin, corners, **densify)
    return _tin_height(tri, tin_pts, pts[:, :2])


def _densify(pts, cand, in_tin, corners, *, iteration_angle, iteration_distance,
             max_iterations):
    """Grow the TIN of ``pts[in_tin]`` + ``corners`` by the candidates ``cand`` (indices into
    ``pts``) as in :func:`ptd`, step 4; ``in_tin`` (N,) is updated in place. Returns the
    final triangulation and its vertices (V, 3)."""
    from scipy.spatial import Delaunay  # here: other methods never import scipy

    sin_max = np.sin(np.radians(iteration_angle))
    for it in range(max_iterations):
        # rebuilt every round: qhull's incremental mode (add_points) was 5x slower here
        tin_pts = np.vstack([pts[in_tin], corners])
        tri = Delaunay(tin_pts[:, :2])
        rest = cand[~in_tin[cand]]
        if len(rest) == 0:
            break
        simplex = _locate(tri.points, tri.simplices, pts[rest, :2])
        inside = simplex >= 0
        rest, simplex = rest[inside], simplex[inside]
        vert = tin_pts[tri.simplices[simplex]]              # (m, 3, 3)
        p = pts[rest]
        normal = np.cross(vert[:, 1] - vert[:, 0], vert[:, 2] - vert[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        dist = np.abs(np.einsum("ij,ij->i", p - vert[:, 0], normal))
        reach = np.linalg.norm(p[:, None, :] - vert, axis=2).min(axis=1)
        ok = (dist <= iteration_distance) & (dist <= sin_max * reach)
        if not ok.any():
            break
        rest, simplex, dist = rest[ok], simplex[ok], dist[ok]
        # one point per facet: the closest to the plane (ties by index: deterministic)
        order = np.lexsort((rest, dist, simplex))
        first = np.ones(len(order), dtype=bool)
        first[1:] = simplex[order][1:] != simplex[order][:-1]
        in_tin[rest[order[first]]] = True
        logger.debug("ptd iteration %d: %d points joined", it, int(first.sum()))
    tin_pts = np.vstack([pts[in_tin], corners])
    return Delaunay(tin_pts[:, :2]), tin_pts


def _lowest_per_cell(xyz, cell):
    """Indices (into ``xyz``) of the lowest point of every occupied ``cell`` cell."""
    spec = grid_spec(xyz[:, :2], cell=cell)
    r, c = cell_of(xyz[:, :2], spec)
    flat = r.astype(np.int64) * spec.shape[1] + c
    order = np.lexsort((xyz[:, 2], flat))
    first = np.ones(len(order), dtype=bool)
    first[1:] = flat[order][1:] != flat[order][:-1]
    return np.sort(order[first])


def _drop_raised_seeds(pts, seeds, tolerance, rounds=3):
    """Seeds without those more than ``tolerance`` above the plane of their Delaunay neighbours.

    The plane (least squares through the neighbours, evaluated at the seed)
    keeps seeds on a uniform slope, hull seeds included.
    """
    from scipy.spatial import Delaunay

    for _ in range(rounds):
        if len(seeds) < 4:
            break
        try:
            tri = Delaunay(pts[seeds, :2])
        except Exception:  # collinear seeds: nothing to compare with
            break
        indptr, nbr = tri.vertex_neighbor_vertices
        p = pts[seeds]
        excess = np.zeros(len(seeds))
        for i in range(len(seeds)):
            near = p[nbr[indptr[i]:indptr[i + 1]]]
            a = np.column_stack([near[:, :2] - p[i, :2], np.ones(len(near))])
            coef, _, rank, _ = np.linalg.lstsq(a, near[:, 2], rcond=None)
            excess[i] = p[i, 2] - (coef[2] if rank == 3 else near[:, 2].mean())
        raised = excess > tolerance
        if not raised.any():
            break
        seeds = seeds[~raised]
    return seeds


def _virtual_corners(seed_pts, lo, hi, k=4):
    """The four corners of ``lo``-``hi`` with heights of a plane through their nearest seeds.

    The plane continues a slope to the corner (a slope rising to the tile
    edge stays inside the TIN's reach).
    """
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [lo[0], hi[1]], [hi[0], hi[1]]])
    out = np.empty((4, 3))
    k = min(k, len(seed_pts))
    for i, xy in enumerate(corners):
        d = np.hypot(*(seed_pts[:, :2] - xy).T)
        near = seed_pts[np.argsort(d, kind="stable")[:k]]
        a = np.column_stack([near[:, :2] - xy, np.ones(k)])
        coef, _, rank, _ = np.linalg.lstsq(a, near[:, 2], rcond=None)
        # collinear nearest seeds give no plane: the nearest seed's height
        out[i] = xy[0], xy[1], coef[2] if rank == 3 else near[0, 2]
    return out


def _tin_height(tri, tin_pts, xy):
    """Height and gradient magnitude of the TIN at ``xy`` (nearest facet outside it)."""
    simplex = _locate(tri.points, tri.simplices, xy)
    outside = simplex < 0
    if outside.any():
        # on the hull edge up to rounding: take the facet of the nearest vertex
        _, nearest = _nearest_vertex(tri, xy[outside])
        simplex[outside] = tri.vertex_to_simplex[nearest]
    vert = tin_pts[tri.simplices[simplex]]
    e1, e2 = vert[:, 1] - vert[:, 0], vert[:, 2] - vert[:, 0]
    normal = np.cross(e1, e2)
    nz = np.where(np.abs(normal[:, 2]) > 1e-12, normal[:, 2], 1e-12)
    gx, gy = -normal[:, 0] / nz, -normal[:, 1] / nz
    d = xy - vert[:, 0, :2]
    z = vert[:, 0, 2] + gx * d[:, 0] + gy * d[:, 1]
    return z, np.hypot(gx, gy)


def _nearest_vertex(tri, xy):
    from scipy.spatial import cKDTree

    return cKDTree(tri.points).query(xy)


def _locate(tri_xy, simplices, xy):
    """The facet of ``simplices`` (T, 3) over vertices ``tri_xy`` (V, 2) holding each point of
    ``xy`` (N, 2); -1 outside every facet.

    Points and facet boxes are bucketed on a grid of about one facet per cell and each
    point is tested (barycentric, a relative tolerance of 1e-9) against the facets whose box
    covers its cell; a point on a shared edge gets the lowest facet index. Unlike
    ``Delaunay.find_simplex``, whose walk falls back to a search of every facet when it
    meets the slivers of gridded points, the cost is linear in the points and the facets'
    box areas.
    """
    n, t = len(xy), len(simplices)
    out = np.full(n, -1, dtype=np.int64)
    if n == 0 or t == 0:
        return out
    v = tri_xy[simplices]                                    # (T, 3, 2)
    lo = np.minimum(v.min(axis=1), xy.min(axis=0))
    origin = lo.min(axis=0)
    span = np.maximum(np.maximum(v.max(axis=(0, 1)), xy.max(axis=0)) - origin, 1e-9)
    size = max(float(np.sqrt(span[0] * span[1] / t)), 1e-6)
    shape = (np.floor(span / size).astype(np.int64) + 1)
    pi = np.minimum(np.floor((xy - origin) / size).astype(np.int64), shape - 1)
    pkey = pi[:, 0] * shape[1] + pi[:, 1]
    porder = np.argsort(pkey, kind="stable")
    start = np.searchsorted(pkey[porder], np.arange(shape[0] * shape[1] + 1))
    b0 = np.clip(np.floor((v.min(axis=1) - origin) / size).astype(np.int64), 0, shape - 1)
    b1 = np.clip(np.floor((v.max(axis=1) - origin) / size).astype(np.int64), 0, shape - 1)
    ext = b1 - b0 + 1
    ncell = ext[:, 0] * ext[:, 1]
    tri_of = np.repeat(np.arange(t), ncell)
    k = np.arange(len(tri_of)) - np.repeat(np.cumsum(ncell) - ncell, ncell)
    ci = b0[tri_of, 0] + k // ext[tri_of, 1]
    cj = b0[tri_of, 1] + k % ext[tri_of, 1]
    key = ci * shape[1] + cj
    cnt = start[key + 1] - start[key]
    tri_of = np.repeat(tri_of, cnt)
    first = np.repeat(start[key], cnt)
    pt = porder[first + np.arange(len(first)) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
    a, b, c = v[tri_of, 0], v[tri_of, 1], v[tri_of, 2]
    p = xy[pt]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]))
    l2 = ((b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (p[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    s = np.where(det < 0, -1.0, 1.0)
    det, l1, l2 = det * s, l1 * s, l2 * s
    eps = -1e-9 * det
    hit = (det > 0) & (l1 >= eps) & (l2 >= eps) & (det - l1 - l2 >= eps)
    pt, tri_of = pt[hit], tri_of[hit]
    order = np.lexsort((tri_of, pt))
    pt, tri_of = pt[order], tri_of[order]
    keep = np.ones(len(pt), dtype=bool)
    keep[1:] = pt[1:] != pt[:-1]
    out[pt[keep]] = tri_of[keep]
    return out


def seeded_tin(xyz, seeds, *, cell: float = 1.0, iteration_angle: float = 20.0,
               iteration_distance: float = 1.5, max_iterations: int = 60, exclude=None):
    """Height and gradient of a TIN densified from given seed points, at every point.

    The TIN starts from the lowest seed point of every ``cell`` cell and
    grows by the lowest points of the other cells as in :func:`ptd`, step 4
    (Axelsson 2000): ground that joins the seeds along connected terrain
    (a terrace bench, ground between buildings on a slope) joins it, a roof
    raised on all sides does not.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    seeds : ndarray of bool, shape (N,)
        Points the TIN starts from (e.g. where several filters agree on ground).
    cell, iteration_angle, iteration_distance, max_iterations
        As in :func:`ptd`.
    exclude : ndarray of bool, shape (N,), optional
        Points never taken into the TIN (low outliers).

    Returns
    -------
    surface, gradient : ndarray, shape (N,)
        The TIN's height and gradient magnitude under each point (NaN for
        both when fewer than three seeds).
    """
    xyz = _check_xyz(xyz)
    seeds = np.asarray(seeds, dtype=bool)
    n = len(xyz)
    if seeds.shape != (n,):
        raise InputError(f"seeds must be a boolean mask of shape ({n},), got {seeds.shape}")
    usable = np.ones(n, dtype=bool) if exclude is None else ~np.asarray(exclude, dtype=bool)
    keep = np.flatnonzero(usable)
    seed_idx = np.flatnonzero(seeds & usable)
    origin = xyz[keep].min(axis=0) if len(keep) else np.zeros(3)
    pts = xyz - origin
    lo, hi = pts[keep, :2].min(axis=0, initial=np.inf), pts[keep, :2].max(axis=0, initial=-np.inf)
    if len(seed_idx) < 3 or np.any(hi - lo <= 0):
        return np.full(n, np.nan), np.full(n, np.nan)
    cand = keep[_lowest_per_cell(pts[keep], cell)]
    first = seed_idx[_lowest_per_cell(pts[seed_idx], cell)]
    surface, grad = _grown_surface(pts, cand, first, lo - cell, hi + cell,
                                   iteration_angle=iteration_angle,
                                   iteration_distance=iteration_distance,
                                   max_iterations=max_iterations)
    return surface + origin[2], grad
