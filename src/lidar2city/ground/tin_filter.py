"""Progressive TIN densification (Axelsson 2000), vectorised per iteration."""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import Delaunay

from ..errors import InputError
from ._grid import cell_of, grid_spec
from .outliers import _check_positive, _check_xyz, low_outliers

logger = logging.getLogger(__name__)

__all__ = ["ptd"]


def ptd(xyz, *, cell: float = 1.0, seed_cell: float = 20.0, seed_tolerance: float = 3.0,
        iteration_angle: float = 10.0, iteration_distance: float = 1.5, threshold: float = 0.5,
        scalar: float = 1.25, max_iterations: int = 60, outlier_radius: float = 5.0,
        outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by progressive TIN densification.

    1. Low outliers (:func:`~lidar2city.ground.low_outliers`) are set aside.
    2. The candidates are the lowest point of every ``cell`` x ``cell`` cell.
    3. Seeds: the lowest candidate of every ``seed_cell`` cell (the largest
       building should fit in one). A seed more than ``seed_tolerance``
       metres above the mean of its Delaunay neighbours (a roof filling a
       whole seed cell) is dropped, three rounds. Four virtual corner points
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
        Iteration angle (degrees).
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
                    iteration_angle=iteration_angle, iteration_distance=iteration_distance, threshold=threshold,
                    outlier_radius=outlier_radius, outlier_depth=outlier_depth)
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
    if len(keep) < 3:
        return np.zeros(n, dtype=bool)
    # float64 coordinates relative to the first kept point keep the TIN well conditioned
    origin = xyz[keep].min(axis=0)
    pts = xyz - origin
    cand = keep[_lowest_per_cell(pts[keep], cell)]
    # Delaunay.find_simplex walks from the last simplex found: spatially
    # ordered queries make the walks short
    cand = cand[_walk_order(pts[cand, :2], seed_cell)]
    seeds = cand[_lowest_per_cell(pts[cand], seed_cell)]
    seeds = _drop_raised_seeds(pts, seeds, seed_tolerance)
    lo, hi = pts[keep, :2].min(axis=0), pts[keep, :2].max(axis=0)
    if len(seeds) < 3 or np.any(hi - lo <= 0):
        return np.zeros(n, dtype=bool)
    corners = _virtual_corners(pts[seeds], lo - cell, hi + cell)
    in_tin = np.zeros(n, dtype=bool)
    in_tin[seeds] = True
    sin_max = np.sin(np.radians(iteration_angle))
    for it in range(max_iterations):
        tin_pts = np.vstack([pts[in_tin], corners])
        tri = Delaunay(tin_pts[:, :2])
        rest = cand[~in_tin[cand]]
        if len(rest) == 0:
            break
        simplex = tri.find_simplex(pts[rest, :2])
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
    tri = Delaunay(tin_pts[:, :2])
    surface, grad = _tin_height(tri, tin_pts, pts[:, :2])
    ground = np.abs(pts[:, 2] - surface) <= threshold + scalar * grad
    ground &= ~outliers
    return ground


def _walk_order(xy, band):
    """Order of ``xy`` (N, 2) along serpentine bands ``band`` metres high."""
    row = np.floor((xy[:, 1] - xy[:, 1].min()) / band).astype(np.int64)
    x = np.where(row % 2 == 0, xy[:, 0], -xy[:, 0])
    return np.lexsort((x, row))


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
    order = _walk_order(xy, 5.0)
    simplex = np.empty(len(xy), dtype=np.int64)
    simplex[order] = tri.find_simplex(xy[order])
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
