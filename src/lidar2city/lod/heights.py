"""Roof and ground heights of a building from its points (LoD1 statistics)."""

from __future__ import annotations

import numpy as np

from .._stats import percentile as _percentile
from ..errors import InputError

__all__ = ["ROOF_STATISTICS", "roof_height", "ground_height"]


def _statistic(z, stat):
    if isinstance(stat, str):
        if stat == "mean":
            return float(np.mean(z))
        if stat == "median":
            return float(np.median(z))
        if stat == "max":
            return float(np.max(z))
        raise InputError(f"roof statistic must be a percentile or one of {', '.join(ROOF_STATISTICS)}, "
                         f"got {stat!r}")
    if not 0 <= float(stat) <= 100:
        raise InputError(f"percentile must be in [0, 100], got {stat}")
    return float(_percentile(z, float(stat)))


#: Names accepted besides a percentile number for the roof height.
ROOF_STATISTICS = ("mean", "median", "max")


def roof_height(z, statistic: float | str = 70.0) -> float:
    """Roof height of an LoD1 block from the heights of its roof points.

    Parameters
    ----------
    z : ndarray, shape (N,)
        Heights (metres) of the building points inside the footprint.
    statistic : float or {"mean", "median", "max"}
        A percentile in [0, 100] (3DBAG uses the 70th, 3dfier's default the
        90th) or a named statistic. The mean minimises the vertical RMSE of a
        flat roof; a high percentile keeps the volume of pitched roofs.

    Raises
    ------
    InputError
        If ``z`` is empty or the statistic unknown.
    """
    z = np.asarray(z, dtype=np.float64)
    if len(z) == 0:
        raise InputError("no roof points")
    return _statistic(z, statistic)


def ground_height(footprint, ground_xyz, *, percentile: float = 10.0, ring_width: float = 3.0,
                  wide_ring_width: float = 10.0, min_points: int = 3,
                  building_z=None, fallback_z=None) -> tuple[float, str]:
    """Ground height of a building: a low percentile of ground points around it.

    The fallback chain, in order: ground points in a ring of ``ring_width``
    metres around the footprint; in a ring of ``wide_ring_width`` metres;
    ground points inside the footprint (courtyards, passages); the lowest of
    the building's own points; ``fallback_z`` (e.g. the area's ground level).

    Parameters
    ----------
    footprint : shapely Polygon or MultiPolygon
    ground_xyz : ndarray, shape (N, 3)
        Ground points near the building (any extent: filtered here).
    percentile : float
        Percentile of the ground heights (3dfier uses the 10th).
    building_z : ndarray, shape (M,), optional
        Heights of the building's points, for the fourth fallback.
    fallback_z : float or callable, optional
        Last resort height (a callable is only called when needed).

    Returns
    -------
    height : float
        NaN when every source is empty.
    source : str
        ``"ring"``, ``"wide ring"``, ``"inside footprint"``,
        ``"lowest building point"``, ``"fallback"`` or ``"none"``.
    """
    import shapely

    g = np.asarray(ground_xyz, dtype=np.float64).reshape(-1, 3)
    if len(g):
        x0, y0, x1, y1 = footprint.bounds
        w = max(ring_width, wide_ring_width)
        near = (g[:, 0] >= x0 - w) & (g[:, 0] <= x1 + w) & (g[:, 1] >= y0 - w) & (g[:, 1] <= y1 + w)
        g = g[near]
    if len(g):
        inside = shapely.contains_xy(footprint, g[:, 0], g[:, 1])
        for width, source in ((ring_width, "ring"), (wide_ring_width, "wide ring")):
            if width <= 0:
                continue
            zone = footprint.buffer(width, quad_segs=4)
            shapely.prepare(zone)
            # only the points in the zone's box can be in it
            zx0, zy0, zx1, zy1 = zone.bounds
            idx = np.flatnonzero((g[:, 0] >= zx0) & (g[:, 0] <= zx1) & (g[:, 1] >= zy0)
                                 & (g[:, 1] <= zy1) & ~inside)
            idx = idx[shapely.contains_xy(zone, g[idx, 0], g[idx, 1])]
            if len(idx) >= min_points:
                return float(_percentile(g[idx, 2], percentile)), source
        if inside.sum() >= min_points:
            return float(_percentile(g[inside, 2], percentile)), "inside footprint"
    if building_z is not None and len(building_z):
        return float(np.min(building_z)), "lowest building point"
    if callable(fallback_z):
        fallback_z = fallback_z()
    if fallback_z is not None and np.isfinite(fallback_z):
        return float(fallback_z), "fallback"
    return float("nan"), "none"
