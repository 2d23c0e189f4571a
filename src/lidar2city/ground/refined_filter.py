"""SMRF with the surface carried across tile edges and a surface-based cleanup."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from ._grid import gradient_magnitude, sample_bilinear
from .dtm import dtm_from_ground
from .outliers import _check_positive, _check_xyz, low_outliers
from .smrf_filter import smrf_surface

logger = logging.getLogger(__name__)

__all__ = ["smrf_refined"]


def _within(xyz, surface, grad, spec, threshold, scalar):
    """Points within ``threshold + scalar * slope`` of ``surface`` (values at cell centres)."""
    ref = sample_bilinear(surface, spec, xyz[:, :2])
    tol = threshold + scalar * sample_bilinear(grad, spec, xyz[:, :2])
    return np.abs(xyz[:, 2] - ref) <= tol


def smrf_refined(xyz, *, cell: float = 1.0, slope: float = 0.15, window: float = 24.0,
                 scalar: float = 1.25, threshold: float = 0.5, extend: float = 10.0,
                 rounds: int = 0, refine_threshold: float = 0.3, outlier_radius: float = 5.0,
                 outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by SMRF with edge extension, then surface-based cleanup rounds.

    1. Low outliers (:func:`low_outliers`) are set aside as non-ground.
    2. SMRF's provisional surface (:func:`smrf_surface`) is built with the
       minimum surface continued ``extend`` metres across the tile edges by
       point reflection, so a slope rising to the edge is not cut down by
       the opening (plain SMRF loses a ring of about ``gradient / slope``
       cells there: 7 m on a 45° slope).
    3. Points within ``threshold + scalar * slope`` of it are ground
       (Pingel et al. 2013, eq. 3).
    4. ``rounds`` times (default none): the terrain is re-interpolated from the ground
       points alone (:func:`dtm_from_ground`: their plane per cell, holes
       filled harmonically) and every point within ``refine_threshold +
       scalar * slope`` of it is ground. This adds back ground points the
       opening flattened (ridges, terrace edges) and drops points the coarse
       surface took in.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell, slope, window, scalar, threshold : float
        As in :func:`~lidar2city.ground.smrf`.
    extend : float
        Metres of surface continued beyond the tile edges (>= 0; 10 m keeps
        slopes up to 1.5 rise per run at the default ``slope``).
    rounds : int
        Cleanup rounds (>= 0; 0 is SMRF with edge extension only).
    refine_threshold : float
        Height tolerance (metres) around the re-interpolated terrain.
    outlier_radius, outlier_depth : float
        Low-outlier detection (see :func:`low_outliers`); ``outlier_depth=inf``
        disables it.

    Returns
    -------
    ndarray of bool, shape (N,)
        True for ground points.

    Raises
    ------
    InputError
        Wrong shape, NaN coordinates or invalid parameters.

    Notes
    -----
    Parameters chosen by leave-one-sample-out over the seven shared ISPRS
    samples together with the synthetic terrains of
    :mod:`lidar2city.synthetic_terrain` (``benchmarks/bench_ground.py --loo``
    prints the held-out errors). The cleanup rounds are off by default: on
    that measure they did not lower the held-out error (one round at
    ``refine_threshold`` 0.3: mean over the seven samples 3.51 % against
    3.58 % without, but leave-one-out 3.93 % against 3.71 %) and they double
    the filter's time.

    References
    ----------
    Pingel, T. J., Clarke, K. C., McBride, W. A. (2013). An improved simple
    morphological filter for the terrain classification of airborne LIDAR
    data. ISPRS J. Photogramm. Remote Sens. 77, 21-30.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> z = g[:, 0] + np.where((abs(g[:, 0] - 30) < 6) & (abs(g[:, 1] - 30) < 6), 8.0, 0.0)
    >>> ground = smrf_refined(np.column_stack([g, z]))
    >>> bool(ground[z - g[:, 0] == 0].all()), bool(ground[z - g[:, 0] == 8].any())
    (True, False)
    """
    xyz = _check_xyz(xyz)
    _check_positive(cell=cell, slope=slope, window=window, threshold=threshold,
                    refine_threshold=refine_threshold, outlier_radius=outlier_radius,
                    outlier_depth=outlier_depth)
    if not scalar >= 0:
        raise InputError(f"scalar must be >= 0, got {scalar!r}")
    if not (isinstance(rounds, (int, np.integer)) and rounds >= 0):
        raise InputError(f"rounds must be an integer >= 0, got {rounds!r}")
    n = len(xyz)
    if n == 0:
        return np.zeros(0, dtype=bool)
    outliers = (low_outliers(xyz, radius=outlier_radius, depth=outlier_depth)
                if np.isfinite(outlier_depth) else np.zeros(n, dtype=bool))
    if outliers.all():
        return np.zeros(n, dtype=bool)
    surface, _, spec = smrf_surface(xyz, cell=cell, slope=slope, window=window,
                                    exclude=outliers, extend=extend)
    ground = _within(xyz, surface, gradient_magnitude(surface, cell), spec, threshold, scalar)
    ground &= ~outliers
    for _ in range(rounds):
        if not ground.any():
            break
        dtm = dtm_from_ground(xyz, ground, cell=cell)
        ground = _within(xyz, dtm.array, gradient_magnitude(dtm.array, cell), dtm.spec,
                         refine_threshold, scalar)
        ground &= ~outliers
    logger.debug("smrf_refined: %d of %d points ground, %d low outliers", int(ground.sum()), n,
                 int(outliers.sum()))
    return ground
