"""Planar region growing as connected components of a coplanarity graph.

Region growing with plane fitting (seeded growth accepting a neighbour while
it lies on the seed's plane and its normal agrees) is the transitive closure
of a symmetric "locally coplanar" relation between kNN neighbours. Here the
relation is evaluated for every kNN edge at once, and the regions are the
connected components of the resulting sparse graph
(:func:`scipy.sparse.csgraph.connected_components`), which is order
independent and needs no Python loop. Each region then gets a least-squares
plane (PCA of its points, the total-least-squares form of
``z = a x + b y + c`` that also holds walls), its RMS residual and its area.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .features import LocalShape

logger = logging.getLogger(__name__)

__all__ = ["Regions", "planar_regions", "region_planes"]


@dataclass(frozen=True, eq=False)
class Regions:
    """Planar regions of a point set.

    Attributes
    ----------
    labels : ndarray, shape (N,), int64
        Region of each point, ``-1`` for points in no region (rough points or
        singletons).
    size : ndarray, shape (R,)
        Points per region.
    area : ndarray, shape (R,)
        Horizontal area covered (occupied cells times cell area, m2).
    normal : ndarray, shape (R, 3)
        Unit normal of the region's fitted plane, ``nz >= 0``.
    rms : ndarray, shape (R,)
        RMS distance of the region's points to its plane (m).
    """

    labels: np.ndarray
    size: np.ndarray
    area: np.ndarray
    normal: np.ndarray
    rms: np.ndarray

    def __len__(self) -> int:
        return len(self.size)


def planar_regions(xyz, shape: LocalShape, *, max_residual: float = 0.08,
                   max_angle: float = 20.0, max_distance: float = 0.15,
                   edge_neighbours: int = 12, area_cell: float = 0.5) -> Regions:
    """Grow planar regions over the kNN graph.

    An edge ``(i, j)`` between kNN neighbours is kept when both points are
    locally planar (``residual <= max_residual``), their normals differ by at
    most ``max_angle`` degrees, and each lies within ``max_distance`` of the
    other's tangent plane. Regions are the connected components of kept edges.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Coordinates in metres (the points :func:`local_shape` was run on).
    shape : LocalShape
        Local PCA of ``xyz``.
    max_residual : float
        Largest local plane residual (m) of a point that can join a region.
    max_angle : float
        Largest angle (degrees) between neighbouring normals.
    max_distance : float
        Largest distance (m) of a neighbour to a point's tangent plane.
    edge_neighbours : int
        How many of the nearest neighbours are tested as edges.
    area_cell : float
        Cell (m) used to measure each region's horizontal area.

    Returns
    -------
    Regions

    References
    ----------
    T. Rabbani, F. van den Heuvel, G. Vosselman, "Segmentation of point clouds
    using smoothness constraint", IAPRS 36(5), 2006 (the growing criteria).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    xyz = np.asarray(xyz, dtype=np.float64)
    n = len(xyz)
    if n == 0:
        e = np.zeros(0)
        return Regions(np.zeros(0, np.int64), e, e, np.zeros((0, 3)), e)
    nb = shape.neighbours[:, 1:1 + edge_neighbours]
    m = nb.shape[1]
    ok_point = shape.residual <= max_residual
    src = np.repeat(np.arange(n), m)
    dst = nb.ravel()
    keep = ok_point[src] & ok_point[dst] & (src != dst)
    src, dst = src[keep], dst[keep]
    ni, nj = shape.normal[src], shape.normal[dst]
    cos = np.abs(np.einsum("ij,ij->i", ni, nj))
    d = xyz[dst] - xyz[src]
    di = np.abs(np.einsum("ij,ij->i", ni, d))
    dj = np.abs(np.einsum("ij,ij->i", nj, d))
    keep = (cos >= np.cos(np.radians(max_angle))) & (di <= max_distance) & (dj <= max_distance)
    src, dst = src[keep], dst[keep]
    graph = coo_matrix((np.ones(len(src), np.int8), (src, dst)), shape=(n, n)).tocsr()
    _, comp = connected_components(graph, directed=True, connection="weak")
    # singletons (no kept edge) are no region
    counts = np.bincount(comp)
    in_region = counts[comp] >= 3
    labels = np.full(n, -1, np.int64)
    _, labels[in_region] = np.unique(comp[in_region], return_inverse=True)
    size, area, normal, rms = region_planes(xyz, labels, area_cell=area_cell)
    logger.debug("planar regions: %d regions over %d of %d points", len(size),
                 int(in_region.sum()), n)
    return Regions(labels, size, area, normal, rms)


def region_planes(xyz, labels, *, area_cell: float = 0.5):
    """Point count, horizontal area, plane normal and RMS residual per region.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
    labels : ndarray, shape (N,), int
        Region per point, ``-1`` for none; regions are ``0..R-1``.
    area_cell : float
        Cell (m) for the occupied-area measure.

    Returns
    -------
    size, area, normal, rms : ndarrays of shapes (R,), (R,), (R, 3), (R,)
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    labels = np.asarray(labels)
    sel = labels >= 0
    r = int(labels.max()) + 1 if sel.any() else 0
    if r == 0:
        e = np.zeros(0)
        return e, e, np.zeros((0, 3)), e
    lab = labels[sel]
    p = xyz[sel]
    size = np.bincount(lab, minlength=r).astype(np.float64)
    mean = np.column_stack([np.bincount(lab, p[:, a], minlength=r) for a in range(3)]) / size[:, None]
    q = p - mean[lab]
    cov = np.empty((r, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            s = np.bincount(lab, q[:, a] * q[:, b], minlength=r) / size
            cov[:, a, b] = s
            cov[:, b, a] = s
    w, v = np.linalg.eigh(cov)
    normal = v[:, :, 0]
    normal[normal[:, 2] < 0] *= -1.0
    rms = np.sqrt(np.maximum(w[:, 0], 0.0))
    ij = np.floor(p[:, :2] / area_cell).astype(np.int64)
    ij -= ij.min(axis=0)
    key = (lab * (int(ij[:, 0].max()) + 1) + ij[:, 0]) * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    cells = np.unique(key)
    ncols = int(ij[:, 1].max()) + 1
    nrows = int(ij[:, 0].max()) + 1
    area = np.bincount(cells // (ncols * nrows), minlength=r) * area_cell * area_cell
    return size, area.astype(np.float64), normal, rms
