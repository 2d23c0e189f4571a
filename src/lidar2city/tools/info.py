"""``info``: a summary of a LAS/LAZ file."""

from __future__ import annotations

import numpy as np

from ..io.las import read_las

__all__ = ["las_info", "point_density"]


def point_density(xy, *, cell=None) -> float:
    """Points per square metre over the occupied area.

    The area is the number of occupied grid cells times the cell area, with a
    cell of twice the mean spacing (so gaps such as water or shadows do not
    count, but sparse coverage is not split into empty cells).

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        Local metric coordinates.
    """
    xy = np.asarray(xy, dtype=np.float64)
    n = len(xy)
    if n < 2:
        return 0.0
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    bbox_area = float(np.prod(np.maximum(hi - lo, 1e-6)))
    if cell is None:
        cell = max(2.0 * np.sqrt(bbox_area / n), 0.05)
    ij = np.floor((xy - lo) / cell).astype(np.int64)
    keys = ij[:, 0] * (ij[:, 1].max() + 1) + ij[:, 1]
    occupied = len(np.unique(keys))
    return n / (occupied * cell * cell)


def las_info(path, *, crs=None) -> dict:
    """Points, bounds, CRS, units, density, classes and returns of a LAS/LAZ file.

    A file in a geographic CRS (degrees), which the other commands refuse, is
    described too: bounds in degrees, no units or density, and ``note`` says why.
    """
    from ..crs import unit_factors
    from ..errors import CRSError
    from ..io.las import LasTile

    tile = read_las(path, crs=crs)
    las = tile.data
    header = las.header
    note = None
    try:
        unit_factors(tile.crs)
    except CRSError as exc:  # degrees: described in its own units, not used
        note = str(exc)
    cloud = (tile if note is None else LasTile(tile.path, las, None)).point_cloud()
    n = len(cloud)
    out = {
        "path": tile.path,
        "version": str(header.version),
        "point_format": int(header.point_format.id),
        "points": n,
        "crs": tile.crs.to_string() if tile.crs is not None else None,
        "crs_name": tile.crs.name if tile.crs is not None else None,
        "xy_unit_m": cloud.xy_unit,
        "z_unit_m": cloud.z_unit,
        "bounds": None,
        "density_pts_m2": 0.0,
        "classes": {},
        "returns": {},
    }
    if note is not None:
        out.update(xy_unit_m=None, z_unit_m=None, density_pts_m2=None, note=note)
    if n:
        world = cloud.to_world(cloud.bounds.reshape(2, 3))
        out["bounds"] = [float(v) for v in world.ravel()]
        if note is None:  # over the survey, not over its stray returns' extent
            from ..classify.outliers import far_points

            xy = cloud.xyz[:, :2]
            far = far_points(xy)
            out["density_pts_m2"] = round(point_density(xy[~far] if far.any() else xy), 3)
            if far.any():
                out["far_points"] = int(far.sum())
        cls = cloud.get("classification")
        if cls is not None:
            values, counts = np.unique(cls, return_counts=True)
            out["classes"] = {int(v): int(c) for v, c in zip(values, counts, strict=True)}
        nr = cloud.get("number_of_returns")
        if nr is not None:
            values, counts = np.unique(nr, return_counts=True)
            out["returns"] = {int(v): int(c) for v, c in zip(values, counts, strict=True)}
    return out
