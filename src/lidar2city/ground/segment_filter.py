"""SMRF whose cut-away terrain is given back segment by segment (terrace tops, embankments)."""

from __future__ import annotations

import logging

import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ._grid import inpaint, min_surface
from .outliers import _check_xyz
from .smrf_filter import _near_surface, _smrf_setup, smrf_surface

logger = logging.getLogger(__name__)

__all__ = ["smrf_segments", "restore_segments"]


def _pairs(shape):
    """Flat indices of the 4-neighbour cell pairs (right, down) of a grid."""
    idx = np.arange(shape[0] * shape[1]).reshape(shape)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    return a, b


def restore_segments(zmin, objects, *, jump: float, raised: float, rounds: int = 1,
                     min_cells: int = 4) -> np.ndarray:
    """Object cells of a morphological filter that belong to the terrain after all.

    The cells judged object are cut into smooth segments: 4-neighbours whose
    lowest points differ by less than ``jump`` are joined (empty cells take
    the height of the nearest filled cell, so a wall stays a step); building
    walls and canopy edges break a segment. Along each segment's boundary
    with the terrain cells (both cells holding points), an edge is *raised*
    when the segment is at least ``jump`` above the terrain there. A
    building or a tree is raised along most of its boundary (walls all
    round; even uphill a roof edge stands above the slope); a terrace top or
    an embankment the opening cut away joins the terrain continuously along
    much of it. A segment of at least ``min_cells`` filled cells raised along
    less than a fraction ``raised`` of its boundary is given back to the
    terrain; ``rounds`` times, each judged against the terrain of the pass
    before.

    Parameters
    ----------
    zmin : ndarray, shape (H, W)
        Lowest point per cell, NaN where empty.
    objects : ndarray of bool, shape (H, W)
        Cells the filter judged object.
    jump : float
        Height step (metres) between neighbouring cells that breaks a segment.
    raised : float
        A segment raised along less than this fraction of its boundary is terrain.
    rounds : int
        Passes.
    min_cells : int
        Fewest filled cells of a segment given back (smaller fragments,
        mostly vegetation, stay object).

    Returns
    -------
    ndarray of bool, shape (H, W)
        ``objects`` without the cells given back.
    """
    shape = zmin.shape
    empty = np.isnan(zmin)
    if empty.all() or not objects.any():
        return objects.copy()
    nearest = distance_transform_edt(empty, return_distances=False, return_indices=True)
    z = zmin[tuple(nearest)].ravel()
    filled = ~empty.ravel()
    a, b = _pairs(shape)
    dz = z[a] - z[b]
    smooth = np.abs(dz) < jump
    measured = filled[a] & filled[b]
    obj = objects.ravel().copy()
    n = z.size
    for _ in range(rounds):
        join = smooth & obj[a] & obj[b]
        graph = coo_matrix((np.ones(int(join.sum()), dtype=np.int8), (a[join], b[join])),
                           shape=(n, n))
        _, label = connected_components(graph, directed=False)
        edges = np.zeros(n)
        high = np.zeros(n)
        for side, other, sign in ((a, b, 1.0), (b, a, -1.0)):
            m = obj[side] & ~obj[other] & measured
            lab = label[side[m]]
            edges += np.bincount(lab, minlength=n)
            high += np.bincount(lab, weights=sign * dz[m] >= jump, minlength=n)
        cells = np.bincount(label[obj & filled], minlength=n)
        terrain = (edges > 0) & (high < raised * edges) & (cells >= min_cells)
        give = obj & terrain[label]
        if not give.any():
            break
        obj &= ~give
    return obj.reshape(shape)


def smrf_segments(xyz, *, cell: float = 1.0, slope: float = 0.15, window: float = 24.0,
                  scalar: float = 1.25, threshold: float = 0.5, extend: float = 10.0,
                  jump: float = 0.6, raised: float = 0.6, min_cells: int = 4,
                  seg_rounds: int = 1, outlier_radius: float = 5.0,
                  outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by SMRF with the terrain segments the opening cut away given back.

    1. Low outliers are set aside; SMRF's object cells are found on the
       minimum surface continued ``extend`` metres across the tile edges (as
       in :func:`~lidar2city.ground.smrf_refined`).
    2. :func:`restore_segments` gives back to the terrain the object cells
       forming smooth segments that are not raised above the terrain along
       most of their boundary: terrace tops and embankments on steep slopes,
       which the progressive opening cuts away like buildings.
    3. The provisional surface is inpainted from the terrain cells and SMRF's
       final test (Pingel et al. 2013, eq. 3) is run against it.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell, slope, window, scalar, threshold, extend, outlier_radius, outlier_depth : float
        As in :func:`~lidar2city.ground.smrf_refined`.
    jump : float
        Height step (metres per metre of ``cell``, at least one metre's worth)
        between neighbouring cells that breaks a segment and makes a boundary
        edge raised.
    raised : float
        A segment raised along less than this fraction of its boundary with
        the terrain is terrain (in (0, 1]).
    min_cells : int
        Fewest filled cells of a segment given back.
    seg_rounds : int
        Passes of :func:`restore_segments` (0: SMRF with edge extension).

    Returns
    -------
    ndarray of bool, shape (N,)
        True for ground points (low outliers never are).

    Raises
    ------
    InputError
        Wrong shape, NaN coordinates or invalid parameters.

    Notes
    -----
    Like ``smrf_refined`` it continues the surface across the tile edges, so
    a building at the edge of a small tile is reflected into a pit: not the
    default. Parameters chosen and checked by leave-one-sample-out
    (``benchmarks/bench_ground.py --loo``).

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> z = g[:, 0] + np.where((abs(g[:, 0] - 30) < 6) & (abs(g[:, 1] - 30) < 6), 8.0, 0.0)
    >>> ground = smrf_segments(np.column_stack([g, z]))
    >>> bool(ground[z - g[:, 0] == 0].all()), bool(ground[z - g[:, 0] == 8].any())
    (True, False)
    """
    if not (isinstance(raised, (int, float, np.integer, np.floating)) and 0 < raised <= 1):
        raise InputError(f"raised must be in (0, 1], got {raised!r}")
    for name, value in (("seg_rounds", seg_rounds), ("min_cells", min_cells)):
        if not (isinstance(value, (int, np.integer)) and value >= 0):
            raise InputError(f"{name} must be an integer >= 0, got {value!r}")
    if not (isinstance(extend, (int, float, np.integer, np.floating)) and extend >= 0):
        raise InputError(f"extend must be a number >= 0, got {extend!r}")
    xyz = _check_xyz(xyz)
    outliers = _smrf_setup(xyz, cell=cell, slope=slope, window=window, scalar=scalar,
                           threshold=threshold, outlier_radius=outlier_radius,
                           outlier_depth=outlier_depth, jump=jump)
    if outliers is None:
        return np.zeros(len(xyz), dtype=bool)
    pts = xyz[~outliers]
    surface, objects, spec = smrf_surface(xyz, cell=cell, slope=slope, window=window,
                                          exclude=outliers, extend=extend)
    if seg_rounds > 0:
        base = float(np.min(pts[:, 2]))
        zmin = min_surface(pts, spec, base=base, dtype=np.float32)
        kept = restore_segments(zmin, objects, jump=jump * max(cell, 1.0), raised=raised,
                                rounds=seg_rounds, min_cells=min_cells)
        given = int((objects & ~kept & ~np.isnan(zmin)).sum())
        logger.debug("smrf_segments: %d object cells given back to the terrain", given)
        if given:
            provisional = np.where(kept | np.isnan(zmin), np.float32(np.nan), zmin)
            surface = inpaint(provisional).astype(np.float64) + base
    ground = _near_surface(xyz, surface, spec, threshold=threshold, scalar=scalar)
    return ground & ~outliers
