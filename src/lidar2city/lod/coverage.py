"""How much of a footprint its building points cover, in work bounded by the points.

A footprint much larger than its points (a mis-digitised polygon, a whole block
or parcel drawn as one building, a survey ending inside it) would give a model
of its full area from a corner of points. :func:`reach_coverage` measures the
share of the footprint within reach of a building point, the reach a few times
the point spacing measured from those points, so a sparse survey's gaps
between scan lines do not count as uncovered. Its cost grows with the number
of points, never with the footprint's area: the covered cells are the occupied
cells grown by the reach, kept in a set of keys rather than a raster over the
footprint.
"""

from __future__ import annotations

import numpy as np

from .._spacing import point_spacing

__all__ = ["reach_coverage"]


def reach_coverage(footprint, xy, *, reach: float = 3.0, cell: float = 2.0) -> tuple[float, float]:
    """Share of ``footprint``'s area within ``reach`` point spacings of a point of ``xy``.

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
        Local metric coordinates.
    xy : ndarray, shape (N, 2)
        Building points inside the footprint.
    reach : float
        Reach around each point, in measured point spacings (the spacing is
        ``sqrt(occupied area / N)`` over ``cell``-sized squares).
    cell : float
        Squares (m) over which the spacing is measured.

    Returns
    -------
    share : float
        In [0, 1]: the area of the footprint's cells (of half the reach) whose
        centre lies within about ``reach`` spacings of a point, over the
        footprint's area; 0 without points, 1 with fewer than two points in a
        footprint smaller than a cell.
    reach_m : float
        The reach (m) used.

    Examples
    --------
    >>> import numpy as np, shapely
    >>> xy = np.stack(np.meshgrid(np.arange(0.25, 10, 0.5), np.arange(0.25, 10, 0.5)), -1)
    >>> share, r = reach_coverage(shapely.box(0, 0, 100, 10), xy.reshape(-1, 2))
    >>> round(share, 1), r
    (0.1, 1.5)
    """
    import shapely

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    area = float(footprint.area)
    if len(xy) == 0 or not area > 0:
        return 0.0, 0.0
    spacing = point_spacing(xy, cell=cell) if len(xy) >= 2 else np.sqrt(area)
    reach_m = float(reach * spacing)
    step = reach_m / 2.0  # cells of half the reach: a disk of 2 cells around each occupied one
    lo = xy.min(axis=0) - reach_m - step
    ij = np.floor((xy - lo) / step).astype(np.int64)
    cols = int(ij[:, 1].max()) + 4
    occupied = np.unique(ij[:, 0] * cols + ij[:, 1])
    di, dj = np.meshgrid(np.arange(-2, 3), np.arange(-2, 3), indexing="ij")
    disk = (di * di + dj * dj) <= 5  # cells whose centre is within ~reach of the cell's
    offsets = (di[disk] * cols + dj[disk]).astype(np.int64)
    keys = np.unique((occupied[:, None] + offsets[None, :]).ravel())
    i, j = np.divmod(keys, cols)
    cx, cy = lo[0] + (i + 0.5) * step, lo[1] + (j + 0.5) * step
    shapely.prepare(footprint)
    covered = int(shapely.contains_xy(footprint, cx, cy).sum()) * step * step
    return float(min(1.0, covered / area)), reach_m
