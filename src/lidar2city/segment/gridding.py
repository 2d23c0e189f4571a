"""Point clouds to rasters: aligned grids and per-cell statistics.

Pure numpy functions on coordinate arrays, used by ``lidar2city rasterize``
(:mod:`lidar2city.tools.rasterize`). Grids are north-up (row 0 is the top), as
in GeoTIFFs, and described by :class:`lidar2city.ground._grid.GridSpec`.
"""

from __future__ import annotations

import numpy as np

from ..errors import EmptyInputError, InputError
from ..ground._grid import GridSpec

__all__ = ["aligned_grid", "cell_index", "cell_max", "cell_mean", "fill_nearest"]


def aligned_grid(bounds, *, cell: float) -> GridSpec:
    """The smallest grid whose edges are multiples of ``cell`` covering ``bounds``.

    Parameters
    ----------
    bounds : (xmin, ymin, xmax, ymax)
        Extent to cover, in the units of ``cell`` (e.g. world CRS units).
    cell : float
        Cell size, > 0.

    Returns
    -------
    GridSpec
        A point on the right or top edge falls in the last column or row: the
        grid is ``floor(xmax / cell) - floor(xmin / cell) + 1`` cells wide.

    Examples
    --------
    >>> aligned_grid((10.2, 3.9, 11.0, 5.0), cell=0.5)
    GridSpec(x0=10.0, y_top=5.5, cell=0.5, shape=(4, 3))
    """
    if not (np.isfinite(cell) and cell > 0):
        raise InputError(f"cell must be > 0, got {cell!r}")
    xmin, ymin, xmax, ymax = (float(v) for v in bounds)
    if not (np.isfinite([xmin, ymin, xmax, ymax]).all() and xmax >= xmin and ymax >= ymin):
        raise InputError(f"bounds must be finite (xmin, ymin, xmax, ymax), got {bounds!r}")
    # columns are closed on the left ([x0, x0 + cell)), rows at the top
    # ((y_top - cell, y_top]), as the LiDAR DSMs of this field are gridded
    c0, c1 = np.floor(xmin / cell), np.floor(xmax / cell)
    r1 = np.floor(ymax / cell)
    w, h = int(c1 - c0) + 1, int(r1 + 2 - np.ceil(ymin / cell))
    if h * w > 400_000_000:
        raise InputError(f"a {h} x {w} grid is too large; use a larger cell size")
    return GridSpec(float(c0 * cell), float((r1 + 1) * cell), float(cell), (h, w))


def cell_index(xy, spec: GridSpec) -> np.ndarray:
    """Flat cell index (row * W + col) of each point of ``xy`` (N, 2); -1 outside the grid.

    A cell holds the points with ``k cell <= x < (k + 1) cell`` and
    ``m cell < y <= (m + 1) cell``, the convention of :func:`aligned_grid`.
    """
    xy = np.asarray(xy, dtype=np.float64)
    h, w = spec.shape
    # the rounding of aligned_grid, so a point on an edge falls where it did there
    col = (np.floor(xy[:, 0] / spec.cell) - np.round(spec.x0 / spec.cell)).astype(np.int64)
    row = (np.round(spec.y_top / spec.cell) - np.ceil(xy[:, 1] / spec.cell)).astype(np.int64)
    inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
    return np.where(inside, row * w + col, -1)


def _check(values, flat):
    values = np.asarray(values, dtype=np.float64)
    flat = np.asarray(flat, dtype=np.int64)
    if values.shape[0] != flat.shape[0]:
        raise InputError(f"{values.shape[0]} values for {flat.shape[0]} cell indices")
    keep = flat >= 0
    return values[keep], flat[keep]


def cell_max(values, flat, shape) -> np.ndarray:
    """Largest value per cell (e.g. the highest return: a DSM); NaN in empty cells.

    Parameters
    ----------
    values : ndarray, shape (N,)
    flat : ndarray of int, shape (N,)
        Cell of each value (:func:`cell_index`; -1 is skipped).
    shape : (H, W)

    Returns
    -------
    ndarray, shape (H, W), float64
    """
    v, f = _check(values, flat)
    out = np.full(int(np.prod(shape)), -np.inf)
    np.maximum.at(out, f, v)
    out[np.isneginf(out)] = np.nan
    return out.reshape(shape)


def cell_mean(values, flat, shape) -> np.ndarray:
    """Mean of the values per cell (intensity, colour); NaN in empty cells.

    Parameters
    ----------
    values : ndarray, shape (N,) or (N, K)
    flat : ndarray of int, shape (N,)
    shape : (H, W)

    Returns
    -------
    ndarray, shape (H, W) or (K, H, W), float64
    """
    v, f = _check(values, flat)
    n = int(np.prod(shape))
    cnt = np.bincount(f, minlength=n).astype(np.float64)
    cols = v.reshape(len(v), -1)
    out = np.empty((cols.shape[1], n))
    with np.errstate(invalid="ignore", divide="ignore"):
        for k in range(cols.shape[1]):
            out[k] = np.bincount(f, cols[:, k], minlength=n) / cnt
    out[:, cnt == 0] = np.nan
    out = out.reshape((cols.shape[1],) + tuple(shape))
    return out[0] if v.ndim == 1 else out


def fill_nearest(grid, *, max_distance=None) -> np.ndarray:
    """Empty (NaN) cells take the value of the nearest filled cell.

    Parameters
    ----------
    grid : ndarray, shape (H, W) or (K, H, W)
        NaN marks an empty cell (in any band for a stack).
    max_distance : float, optional
        Only cells at most this many cells from a filled one are filled;
        None fills all.

    Raises
    ------
    EmptyInputError
        If no cell is filled.
    """
    from scipy import ndimage

    g = np.array(grid, dtype=np.float64)
    empty = ~np.isfinite(g) if g.ndim == 2 else ~np.isfinite(g).all(axis=0)
    if empty.all():
        raise EmptyInputError("no cell holds a value")
    if not empty.any():
        return g
    dist, (ir, ic) = ndimage.distance_transform_edt(empty, return_indices=True)
    todo = empty if max_distance is None else empty & (dist <= max_distance)
    g[..., todo] = g[..., ir[todo], ic[todo]]
    return g
