"""The mean point spacing of a survey over the area its points occupy.

Kept apart from :mod:`lidar2city.footprints` (which re-exports it from
:mod:`lidar2city.footprints.grid`): LoD1's coverage test measures it for every
building, and importing that package imports the footprint extraction, the
classification and the ground filters, which a run with given footprints does not use.
"""

from __future__ import annotations

import numpy as np

from .errors import EmptyInputError, InputError

__all__ = ["point_spacing"]


def point_spacing(xy, *, cell: float | None = None, distinct: int | None = None) -> float:
    """Mean point spacing (m) over the occupied area: ``sqrt(occupied area / N)``.

    The area is the number of ``cell``-sized squares holding at least one point
    times their area, so gaps (streets, courtyards) do not count.

    Parameters
    ----------
    xy : ndarray, shape (N, 2)
        Local metric coordinates.
    cell : float, optional
        Size of the squares (m); a few times the expected spacing. By default
        2 m, grown to twice the spacing while the spacing measured exceeds half
        of it (on squares that hold one point or none the area, and so the
        spacing, comes out too small: ISPRS CSite1's points 4 m apart measured
        1.4 m on 2 m squares), and ``N`` counts distinct positions when more
        than 1 % of the points repeat one (a first/last-pulse survey stores a
        one-echo pulse twice at the same x, y).
    distinct : int, optional
        How many distinct positions ``xy`` holds, when the caller has them
        (they are counted otherwise).

    Raises
    ------
    EmptyInputError
        With fewer than two points.

    Examples
    --------
    >>> xx, yy = np.meshgrid(np.arange(0, 100, 4.0), np.arange(0, 100, 4.0))
    >>> round(point_spacing(np.column_stack([xx.ravel(), yy.ravel()])), 1)
    4.0
    """
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 2:
        raise EmptyInputError("need at least two points to estimate the point spacing")
    if cell is not None:
        if not cell > 0:
            raise InputError(f"cell must be > 0, got {cell}")
        return _spacing_on(xy, float(cell), len(xy))
    n = len(xy)
    if distinct is None:
        from .classify.features import distinct_positions

        distinct = len(distinct_positions(xy))
    if n - distinct > 0.01 * n:  # first/last pulse pairs: one position, two records
        n = distinct
    cell = 2.0
    spacing = _spacing_on(xy, cell, n)
    for _ in range(8):  # a fixed point of cell = 2 x spacing; a few steps reach it
        if not spacing > 0.5 * cell * 1.0001:
            break
        cell = 2.0 * spacing
        spacing = _spacing_on(xy, cell, n)
    return spacing


def _spacing_on(xy, cell: float, n: int) -> float:
    """``sqrt(occupied area / n)`` with the area counted on squares of ``cell`` metres."""
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    keys = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    occupied = len(np.unique(keys))
    return float(np.sqrt(occupied * cell * cell / n))
