"""Which points of a raw (self-classified) tile belong to the footprints a user gave."""

from __future__ import annotations

import numpy as np

__all__ = ["claim_footprint_points"]


def claim_footprint_points(xy, classes, footprints, *, building_classes=(6,),
                           excluded=(2, 7), min_points: int = 10, claimable=None) -> np.ndarray:
    """Classes in which footprints without building points get the points inside them.

    A classifier run on a raw tile decides "building" without the footprints:
    a building smaller than its smallest building area (a shed, a garage), or
    with a roof it took for vegetation, gets no building point, although a
    footprint says a building stands there and its points are there. For
    every footprint holding fewer than ``min_points`` building points, the
    points inside it that are not ``excluded`` (ground, noise) become
    building points (the first of ``building_classes``). Footprints the
    classifier found are left as they are, so are all other points.

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        Point coordinates, in the footprints' frame.
    classes : ndarray of int, shape (N,)
        The classifier's classes (not modified).
    footprints : sequence of shapely Polygon / MultiPolygon or None
    building_classes : tuple of int
    excluded : tuple of int
        Classes never claimed (ground, noise, water...).
    min_points : int
        Building points a footprint needs to be left as the classifier made it.
    claimable : tuple of int, optional
        Only points of these classes are claimed (on a classified tile: the
        unclassified and vegetation classes a classifier puts a missed building
        in, never water or a vendor's own classes); None: every class not
        ``excluded``.

    Returns
    -------
    ndarray, shape (N,)
        A new array of classes.

    Examples
    --------
    >>> from shapely.geometry import box
    >>> xy = np.array([[1.0, 1.0], [1.5, 1.5], [5.0, 5.0]])
    >>> claim_footprint_points(xy, np.array([1, 2, 1]), [box(0, 0, 2, 2)], min_points=1)
    array([6, 2, 1])
    """
    import shapely

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    out = np.array(classes, copy=True)
    if len(xy) == 0 or not len(building_classes):
        return out
    order = np.argsort(xy[:, 0], kind="stable")
    xs = xy[order, 0]
    building = np.isin(out, building_classes)
    free = ~np.isin(out, tuple(excluded) + tuple(building_classes))
    if claimable is not None:
        free &= np.isin(out, tuple(claimable))
    for g in footprints:
        if g is None or g.is_empty:
            continue
        x0, y0, x1, y1 = g.bounds
        cand = order[np.searchsorted(xs, x0, "left"):np.searchsorted(xs, x1, "right")]
        cand = cand[(xy[cand, 1] >= y0) & (xy[cand, 1] <= y1)]
        cand = cand[shapely.contains_xy(g, xy[cand, 0], xy[cand, 1])]
        if np.count_nonzero(building[cand]) >= min_points:
            continue
        out[cand[free[cand]]] = building_classes[0]
    return out
