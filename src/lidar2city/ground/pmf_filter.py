"""Progressive Morphological Filter (PMF), Zhang et al. (2003)."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from ._grid import cell_of, grid_spec, inpaint, min_surface, open_square
from .outliers import _check_positive, _check_xyz, low_outliers

logger = logging.getLogger(__name__)

__all__ = ["pmf", "pmf_windows"]


def pmf_windows(*, cell: float = 1.0, max_window: float = 33.0, slope: float = 0.3,
                initial_distance: float = 0.5, max_distance: float = 3.0,
                exponential: bool = True, base: float = 2.0):
    """Window sizes (cells, odd) and height thresholds (metres) of PMF.

    Zhang et al. (2003), eqs. 4-6: ``w_k = 2 b^k + 1`` (exponential) or
    ``w_k = 2 k b + 1`` (linear), k = 1, 2, ... while ``w_k * cell <=
    max_window`` (the first window is 3 cells at least); ``dh_1 = dh_0`` and
    ``dh_k = min(s (w_k - w_{k-1}) c + dh_0, dh_max)``.

    Returns
    -------
    list of (int, float)
        ``(window_cells, threshold_m)`` pairs.
    """
    if not base >= 1:
        raise InputError(f"base must be >= 1, got {base!r}")
    limit = max(max_window / cell, 3.0)
    sizes = []
    k = 1
    while True:
        raw = 2.0 * base ** k + 1.0 if exponential else 2.0 * k * base + 1.0
        size = int(round(raw))
        size += 1 - size % 2  # odd
        if size > limit and sizes:
            break
        if not sizes or size > sizes[-1]:
            sizes.append(max(size, 3))
        if size > limit:
            break
        k += 1
        if k > 64:
            break
    out = []
    for i, size in enumerate(sizes):
        if i == 0:
            dh = initial_distance
        else:
            dh = min(slope * (size - sizes[i - 1]) * cell + initial_distance, max_distance)
        out.append((size, float(dh)))
    return out


def pmf(xyz, *, cell: float = 1.0, max_window: float = 33.0, slope: float = 0.3,
        initial_distance: float = 0.5, max_distance: float = 3.0, exponential: bool = True,
        base: float = 2.0, outlier_radius: float = 5.0, outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by the Progressive Morphological Filter.

    The lowest point per cell forms a surface (empty cells inpainted), opened
    by square windows of growing size (:func:`pmf_windows`). At each step a
    point whose height above the opened surface exceeds the step's threshold
    ``dh_k`` is non-ground; the next step opens the previous opened surface.
    Low outliers (:func:`low_outliers`) are removed first and are non-ground.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell : float
        Grid cell size (metres).
    max_window : float
        Largest window side (metres): objects larger than this survive.
    slope : float
        Terrain slope (rise over run) used to grow the thresholds.
    initial_distance, max_distance : float
        First and largest height thresholds ``dh_0``, ``dh_max`` (metres).
    exponential : bool
        Exponentially (``2 b^k + 1``) or linearly (``2 k b + 1``) growing windows.
    base : float
        ``b`` of the window sequence.
    outlier_radius, outlier_depth : float
        Low-outlier test (:func:`low_outliers`); ``outlier_depth=inf`` disables it.

    Returns
    -------
    ndarray of bool, shape (N,)
        True for ground points.

    References
    ----------
    Zhang, K., Chen, S.-C., Whitman, D., Shyu, M.-L., Yan, J., Zhang, C. (2003).
    A progressive morphological filter for removing nonground measurements
    from airborne LIDAR data. IEEE TGRS 41(4), 872-882.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> z = np.where((abs(g[:, 0] - 30) < 6) & (abs(g[:, 1] - 30) < 6), 8.0, 0.0)
    >>> ground = pmf(np.column_stack([g, z]))
    >>> bool(ground[z == 0].all()), bool(ground[z == 8].any())
    (True, False)
    """
    xyz = _check_xyz(xyz)
    _check_positive(cell=cell, max_window=max_window, slope=slope,
                    initial_distance=initial_distance, max_distance=max_distance,
                    outlier_radius=outlier_radius, outlier_depth=outlier_depth)
    if max_distance < initial_distance:
        raise InputError("max_distance must be >= initial_distance")
    n = len(xyz)
    if n == 0:
        return np.zeros(0, dtype=bool)
    outliers = (low_outliers(xyz, radius=outlier_radius, depth=outlier_depth)
                if np.isfinite(outlier_depth) else np.zeros(n, dtype=bool))
    keep = ~outliers
    if not keep.any():
        return np.zeros(n, dtype=bool)
    pts = xyz[keep]
    spec = grid_spec(pts[:, :2], cell=cell)
    r, c = cell_of(xyz[:, :2], spec)
    flat = r * spec.shape[1] + c
    surface = inpaint(min_surface(pts, spec))
    ground = keep.copy()
    z = xyz[:, 2]
    for size, dh in pmf_windows(cell=cell, max_window=max_window, slope=slope,
                                initial_distance=initial_distance,
                                max_distance=max_distance, exponential=exponential,
                                base=base):
        surface = open_square(surface, size)
        ground &= (z - surface.ravel()[flat]) <= dh
    logger.debug("pmf: %d of %d points ground", int(ground.sum()), n)
    return ground
