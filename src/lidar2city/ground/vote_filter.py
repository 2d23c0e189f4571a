"""Ground points by a learnt vote over three SMRF surfaces that fail differently."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from ._grid import bilinear_weights, gradient_magnitude, sample_bilinear
from .outliers import _check_positive
from .segment_filter import _segment_surfaces
from .smrf_filter import _checked_outliers

logger = logging.getLogger(__name__)

__all__ = ["VOTE_RULE", "VOTE_SLOPES", "smrf_vote", "vote_features"]

#: SMRF slopes (rise over run) of the candidate surfaces: strict (flat urban ground,
#: low objects cut) and lenient (steep embankments and terrace edges kept).
VOTE_SLOPES = (0.1, 0.3)

#: Thresholds of the decision rule of :func:`smrf_vote` on the three tolerance ratios
#: (``near``, ``steep``, ``plain``). A depth-2 decision tree fitted to minimise the
#: per-sample mean point error over the seven ISPRS reference samples plus the synthetic
#: terrains of :mod:`lidar2city.synthetic_terrain` (their mean counted as one sample),
#: rounded to two decimals; ``benchmarks/bench_ground_vote.py`` refits it (and, leaving
#: each sample out in turn, scores it on the held-out sample) and prints these numbers.
VOTE_RULE = {"near": 1.14, "steep": 0.92, "plain": 1.0}


def vote_features(xyz, *, cell: float = 1.0, window: float = 24.0, scalar: float = 1.25,
                  threshold: float = 0.5, extend: float = 10.0, jump: float = 0.6,
                  raised: float = 0.6, min_cells: int = 4, outlier_radius: float = 5.0,
                  outlier_depth: float = 1.5, slopes=VOTE_SLOPES):
    """The cues of :func:`smrf_vote`: each point's height off three provisional surfaces.

    From one progressive opening (:func:`~lidar2city.ground.smrf_surface`,
    minimum surface continued ``extend`` m across the tile edges) three
    surfaces are built: ``smrf_segments``' surface at the strict slope
    ``slopes[0]`` (object segments that join the terrain smoothly given back,
    :func:`~lidar2city.ground.terrain_segments`), the same at the lenient
    slope ``slopes[1]``, and plain SMRF's at the strict slope (nothing given
    back). For each, a point's ratio is ``|z - S(x, y)| / (threshold + scalar *
    |grad S|)``: SMRF's final test (Pingel et al. 2013, eq. 3) calls it ground
    when the ratio is at most 1.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell, window, scalar, threshold, outlier_radius, outlier_depth : float
        As in :func:`~lidar2city.ground.smrf`.
    extend, jump, raised, min_cells
        As in :func:`~lidar2city.ground.smrf_segments`.
    slopes : tuple of two floats
        Strict and lenient SMRF slope.

    Returns
    -------
    ratios : ndarray, shape (N, 3)
        Tolerance ratios to the strict segment surface, the lenient segment
        surface and plain SMRF's strict surface (inf for low outliers).
    outliers : ndarray of bool, shape (N,)
        Low outliers (:func:`~lidar2city.ground.low_outliers`).

    Raises
    ------
    InputError
        Wrong shape, NaN coordinates or invalid parameters.
    """
    if len(slopes) != 2:
        raise InputError(f"slopes must be two numbers > 0, got {slopes!r}")
    if not (isinstance(raised, (int, float, np.integer, np.floating)) and 0 < raised <= 1):
        raise InputError(f"raised must be in (0, 1], got {raised!r}")
    if not (isinstance(min_cells, (int, np.integer)) and min_cells >= 1):
        raise InputError(f"min_cells must be an integer >= 1, got {min_cells!r}")
    xyz, out = _checked_outliers(xyz, cell=cell, slope=slopes[0], window=window, scalar=scalar,
                                 threshold=threshold, outlier_radius=outlier_radius,
                                 outlier_depth=outlier_depth, jump=jump, lenient=slopes[1])
    n = len(xyz)
    ratios = np.full((n, 3), np.inf)
    if n == 0 or out.all():
        return ratios, out
    surfaces, spec = _segment_surfaces(xyz, out, cell=cell, slope=slopes[0], window=window,
                                       extend=extend, jump=jump, raised=raised,
                                       min_cells=min_cells, also=(slopes[1],))
    weights = bilinear_weights(spec, xyz[:, :2])
    for k, surface in enumerate(surfaces):
        ref = sample_bilinear(surface, spec, weights=weights)
        tol = threshold + scalar * sample_bilinear(gradient_magnitude(surface, spec.cell), spec,
                                                   weights=weights)
        ratios[:, k] = np.abs(xyz[:, 2] - ref) / tol
    ratios[out] = np.inf
    return ratios, out


def vote_rule(ratios, *, near: float, steep: float, plain: float) -> np.ndarray:
    """The decision of :func:`smrf_vote` on the ratios of :func:`vote_features` (N, 3)."""
    r = np.asarray(ratios)
    close = r[:, 0] <= near
    return np.where(close, r[:, 1] <= steep, r[:, 2] <= plain)


def smrf_vote(xyz, *, cell: float = 1.0, window: float = 24.0, scalar: float = 1.25,
              threshold: float = 0.5, extend: float = 10.0, jump: float = 0.6,
              raised: float = 0.6, min_cells: int = 4, outlier_radius: float = 5.0,
              outlier_depth: float = 1.5, near: float = VOTE_RULE["near"],
              steep: float = VOTE_RULE["steep"],
              plain: float = VOTE_RULE["plain"]) -> np.ndarray:
    """Ground points by a vote of three SMRF surfaces, with a rule learnt on labelled samples.

    SMRF's slope decides what its opening cuts: a strict one (0.1) removes low
    objects on flat urban ground but cuts embankments and terrace edges, a
    lenient one (0.3) keeps those but lets low objects through; giving smooth
    object segments back (``smrf_segments``) repairs terraces but sometimes
    gives back a building. No one slope suits every ISPRS sample, so each
    point is judged from its tolerance ratios to three surfaces
    (:func:`vote_features`: strict segments, lenient segments, plain strict
    SMRF) by a depth-2 decision tree:

    * near the strict segment surface (ratio <= ``near``): ground when also
      within ``steep`` of the lenient one (a low object the lenient opening
      kept stands above the strict surface's tolerance on both sides);
    * farther: ground when within ``plain`` of plain strict SMRF's surface
      (the segment step gave back an object region under the point).

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell, window, scalar, threshold, extend, jump, raised, min_cells, outlier_radius, \
outlier_depth
        As in :func:`vote_features`.
    near, steep, plain : float
        Thresholds of the rule on the ratios; defaults :data:`VOTE_RULE`.

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
    The rule was fitted by ``benchmarks/bench_ground_vote.py``, which also
    scores it leaving each ISPRS sample out of the fit in turn, on the
    synthetic terrains and the small edge tile.

    References
    ----------
    Pingel, T. J., Clarke, K. C., McBride, W. A. (2013). An improved simple
    morphological filter for the terrain classification of airborne LIDAR
    data. ISPRS J. Photogramm. Remote Sens. 77, 21-30.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(80.0), np.arange(80.0)), -1).reshape(-1, 2)
    >>> box = (abs(g[:, 0] - 40) < 6) & (abs(g[:, 1] - 40) < 6)
    >>> ground = smrf_vote(np.column_stack([g, np.where(box, 8.0, 0.0)]))
    >>> bool(ground[~box].all()), bool(ground[box].any())
    (True, False)
    """
    _check_positive(near=near, steep=steep, plain=plain)
    ratios, out = vote_features(xyz, cell=cell, window=window, scalar=scalar,
                                threshold=threshold, extend=extend, jump=jump, raised=raised,
                                min_cells=min_cells, outlier_radius=outlier_radius,
                                outlier_depth=outlier_depth)
    ground = vote_rule(ratios, near=near, steep=steep, plain=plain) & ~out
    logger.debug("smrf_vote: %d of %d points ground", int(ground.sum()), len(ground))
    return ground
