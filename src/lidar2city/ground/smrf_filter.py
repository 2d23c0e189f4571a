"""Simple Morphological Filter (SMRF), Pingel, Clarke & McBride (2013)."""

from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError
from ._grid import (
    bilinear_weights,
    gradient_magnitude,
    grid_spec,
    _nearest_fill,
    inpaint,
    min_surface,
    open_disk_series,
    sample_bilinear,
)
from .large import LARGE_REACH, large_objects
from .outliers import _check_positive, _check_xyz, low_outliers

logger = logging.getLogger(__name__)

__all__ = ["smrf", "smrf_surface"]

#: The masks of further slopes that :func:`_smrf_grids`' ``large`` objects join: those of
#: slopes below this (the cuts of a terrain surface), not the steeper marks of walls.
LARGE_BELOW = 1.0


def smrf_surface(xyz, *, cell: float = 1.0, slope: float = 0.15, window: float = 24.0,
                 exclude=None, bounds=None, extend: float = 0.0, large: float | None = None):
    """The provisional bare-earth surface of SMRF and the cells judged object.

    Steps 1-3 of Pingel et al. (2013): the minimum surface ``ZImin`` (lowest
    point per cell, empty cells inpainted), a progressive opening by disks of
    radius 1, 2, ... ``window / cell`` cells, a cell being object when one
    opening step lowers it by more than ``slope * radius``, and the
    provisional surface ``ZIpro``: ``ZImin`` without object cells, inpainted.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
    cell, slope, window : float
        See :func:`smrf`.
    exclude : ndarray of bool, shape (N,), optional
        Points left out of the minimum surface (low outliers).
    bounds : tuple, optional
        ``(xmin, ymin, xmax, ymax)`` of the grid; default the points' extent.
    extend : float
        Metres by which the minimum surface is continued beyond the grid
        edges, by point reflection (a slope continues as a plane), before the
        opening; beyond that the outside is left out. With 0 (Pingel's
        scheme) a slope of gradient ``g`` rising to the tile edge loses a
        ring of about ``g / slope`` cells to the opening; ``extend`` of that
        many cells keeps it.
    large : float or None
        Radius (m) up to which objects wider than ``window`` are looked for on
        a coarse grid (:func:`~lidar2city.ground.large.large_objects`: large
        roofs the opening cannot remove) and judged object; None (default):
        Pingel's scheme, such roofs stay in the surface.

    Returns
    -------
    surface : ndarray, shape (H, W)
        ``ZIpro`` in metres.
    objects : ndarray of bool, shape (H, W)
        Cells judged object by the progressive opening.
    spec : GridSpec
        The grid.
    """
    surface, objects, spec, _ = _smrf_grids(xyz, cell=cell, slope=slope, window=window,
                                            exclude=exclude, bounds=bounds, extend=extend,
                                            large=large)
    return surface, objects, spec


def _minimum_grid(pts, *, cell, bounds=None):
    """The grid over ``pts`` (N, 3), the lowest height ``base`` and SMRF's minimum surface
    ``ZImin`` (float32 heights above ``base``, NaN where empty)."""
    if len(pts) == 0:
        raise InputError("no points to build a surface from")
    spec = grid_spec(pts[:, :2], cell=cell, bounds=bounds)
    # float32 heights relative to the lowest point: exact to well below 1 mm
    base = float(np.min(pts[:, 2]))
    return spec, base, min_surface(pts, spec, base=base, dtype=np.float32)


def _point_spacing(zmin, cell, n):
    """The point spacing (m) of ``n`` points whose minimum surface on cells of ``cell`` m is
    ``zmin`` (NaN where empty): ``1 / sqrt(density)`` over the occupied cells of a grid of
    about 5 m (a sparse survey's empty cells between points do not count, its gaps do)."""
    coarse = max(1, int(round(5.0 / cell)))
    filled = ~np.isnan(zmin)
    if coarse == 1:
        occupied = np.count_nonzero(filled)
    else:
        h, w = filled.shape
        hc, wc = -(-h // coarse), -(-w // coarse)
        padded = np.zeros((hc * coarse, wc * coarse), dtype=bool)
        padded[:h, :w] = filled
        occupied = np.count_nonzero(padded.reshape(hc, coarse, wc, coarse).any(axis=(1, 3)))
    return float(np.sqrt(occupied * (coarse * cell) ** 2 / n))


#: where the ``fill`` of :func:`_smrf_grids` applies: the opening's input ("o"), the final
#: (provisional) surfaces ("f"), or both ("of").
FILL_WHERE = ("o", "f", "of")


def _check_fill(fill):
    """``fill`` (a share of the point spacing, or None) validated."""
    if fill is not None and not (
            isinstance(fill, (int, float, np.integer, np.floating)) and not isinstance(fill, bool)
            and np.isfinite(fill) and fill >= 0):
        raise InputError(f"fill must be a finite number >= 0 or None, got {fill!r}")


def _opening_marks(zfilled, *, cell, window, extend, shape, slopes):
    """The cells SMRF's progressive opening of ``zfilled`` (the inpainted minimum surface,
    continued ``extend`` m across the edges) judges object at each slope of ``slopes``, and
    the last opening; cropped to ``shape``."""
    max_radius = max(int(np.ceil(window / cell)), 1)
    pad = min(int(np.ceil(extend / cell)), *(n - 1 for n in shape))
    if pad > 0:
        zfilled = np.pad(zfilled, pad, mode="reflect", reflect_type="odd")
    masks = [np.zeros(zfilled.shape, dtype=bool) for _ in slopes]
    last = zfilled
    for radius, opened in open_disk_series(zfilled, range(1, max_radius + 1)):
        step = last - opened
        for mask, s in zip(masks, slopes):
            mask |= step > np.float32(s * radius * cell)
        last = opened
    if pad > 0:
        last = last[pad:-pad, pad:-pad]
        masks = [mask[pad:-pad, pad:-pad] for mask in masks]
    return masks, last


#: the heights :func:`_filled` gives the empty cells near points: the nearest point's
#: cell's ("nearest"), or the higher ("max") or lower ("min") of that and the harmonic
#: inpainting's, or the nearest cell's height continued by its slope-limited gradient
#: ("limited").
FILL_VALUES = ("nearest", "max", "min", "limited", "gated")

#: "gated" of :data:`FILL_VALUES`: only the cells whose nearest height is more than this
#: (m) off the harmonic inpainting's take it (a step, not the staircase of a slope), the
#: others are left to the inpainting (``bench_ground_vote.py --fill-value gated
#: --fill-gate``: no better than the plain nearest fill, ``benchmarks/HISTORY.md``).
FILL_GATE = 0.25


def _minmod(a, b):
    """The smaller in magnitude of ``a`` and ``b`` where they have the same sign, else 0."""
    return np.where(a * b > 0, np.where(np.abs(a) < np.abs(b), a, b), 0).astype(a.dtype)


def _limited_gradient(smooth, step):
    """Per cell of ``smooth`` (H, W), its gradient along rows and columns (height per cell)
    as the minmod of its one-sided differences over ``step`` cells (edges: the one side):
    the slope of a plane, 0 at a crest or a foot where the two sides disagree."""
    out = []
    for axis in (0, 1):
        n = smooth.shape[axis]
        k = max(1, min(int(step), n - 1)) if n > 1 else 0
        if k == 0:
            out.append(np.zeros_like(smooth))
            continue
        s = np.moveaxis(smooth, axis, 0)
        diff = (s[k:] - s[:-k]) / np.float32(k)  # diff[i] = (s[i + k] - s[i]) / k
        fwd = np.empty_like(s)
        bwd = np.empty_like(s)
        fwd[:-k], fwd[-k:] = diff, diff[-1]
        bwd[k:], bwd[:k] = diff, diff[0]
        out.append(np.moveaxis(_minmod(fwd, bwd), 0, axis))
    return out


def _filled(grid, radius, where=None, value="nearest", step=1.0):
    """``grid`` with its empty cells (of ``where``) within ``radius`` cells of a known cell
    filled as ``value`` of :data:`FILL_VALUES` says
    (:func:`~lidar2city.ground._grid.nearest_fill`); ``step``: the point spacing in cells
    (the reach of the one-sided differences of "limited")."""
    near, drs, dcs = _nearest_fill(grid, radius, where)
    if value == "nearest":
        return near
    new = np.isnan(grid) & ~np.isnan(near)
    smooth = inpaint(grid)
    if value == "limited":
        grow, gcol = _limited_gradient(smooth, int(round(step)))
        r, c = np.nonzero(new)
        sr, sc = r + drs[r, c], c + dcs[r, c]
        out = grid.copy()
        out[r, c] = grid[sr, sc] - grow[sr, sc] * drs[r, c] - gcol[sr, sc] * dcs[r, c]
        return out
    if value == "gated":
        take = new & (np.abs(near - smooth) > np.float32(FILL_GATE))
        return np.where(take, near, grid).astype(grid.dtype)
    op = np.fmax if value == "max" else np.fmin
    return np.where(new, op(near, smooth), grid).astype(grid.dtype)


def _smrf_grids(xyz, *, cell, slope, window, exclude=None, bounds=None, extend=0.0,
                more=(), minimum=None, lazy=False, fill_radius=0.0, fill_where="o",
                fill_value="nearest", unfilled_more=0, fill_step=1.0, large=None):
    """:func:`smrf_surface` and, from the same opening series, the cells judged object
    at each slope of ``more`` (a list of masks). ``minimum``: :func:`_minimum_grid` of the
    points (those not excluded), when the caller holds it. With ``lazy`` the surface is
    a function of no argument that computes it (its inpainting left to the caller, e.g.
    to run beside others'). With ``fill_radius`` (cells) of 1 or more, the empty cells of
    the minimum surface within that radius of a filled one take the nearest one's height
    (:func:`~lidar2city.ground._grid.nearest_fill`; or as ``fill_value`` of
    :data:`FILL_VALUES` says) before the inpainting of the opening's input (``fill_where``
    holds "o") and of the provisional surface (it holds "f"); then the first
    ``unfilled_more`` masks of ``more`` come from an opening of the minimum surface
    inpainted without the fill (a second opening series). With ``large`` (m), the objects
    wider than the window (:func:`~lidar2city.ground.large.large_objects` up to that
    radius) are object too, at ``slope`` and at every slope of ``more`` below
    :data:`LARGE_BELOW`."""
    xyz = _check_xyz(xyz)
    _check_positive(cell=cell, slope=slope, window=window)
    if not (isinstance(extend, (int, float, np.integer, np.floating)) and extend >= 0):
        raise InputError(f"extend must be a number >= 0, got {extend!r}")
    if minimum is None:
        pts = xyz if exclude is None else xyz[~np.asarray(exclude, dtype=bool)]
        minimum = _minimum_grid(pts, cell=cell, bounds=bounds)
    if fill_where not in FILL_WHERE:
        raise InputError(f"fill_where must be one of {', '.join(FILL_WHERE)}, got {fill_where!r}")
    if fill_value not in FILL_VALUES:
        raise InputError(f"fill_value must be one of {', '.join(FILL_VALUES)}, "
                         f"got {fill_value!r}")
    spec, base, zmin = minimum
    empty = np.isnan(zmin)
    filling = fill_radius >= 1
    opening_filled = filling and "o" in fill_where
    series = dict(cell=cell, window=window, extend=extend, shape=spec.shape)
    if opening_filled:
        zfilled = inpaint(_filled(zmin, fill_radius, value=fill_value, step=fill_step))
        (objects, *extra), last = _opening_marks(zfilled, slopes=(slope, *more), **series)
        if unfilled_more:
            extra[:unfilled_more] = _opening_marks(inpaint(zmin), slopes=more[:unfilled_more],
                                                   **series)[0]
    else:
        (objects, *extra), last = _opening_marks(inpaint(zmin), slopes=(slope, *more), **series)
    if large is not None and np.isfinite(large):  # inf: off
        big = large_objects(zmin, cell=cell, window=window, reach=large)
        if big.any():
            logger.debug("SMRF: %d cells of objects wider than the window", int(big.sum()))
            objects |= big
            extra = [mask | big if s < LARGE_BELOW else mask for mask, s in zip(extra, more)]
    provisional = np.where(objects | empty, np.float32(np.nan), zmin)
    if filling and "f" in fill_where:
        provisional = _filled(provisional, fill_radius, empty, fill_value, fill_step)
    if np.isnan(provisional).all():
        # every cell judged object (pathological input): fall back to the opening
        logger.warning("SMRF judged every cell object; using the opened surface")

        def surface():
            return last.astype(np.float64) + base
    else:
        def surface():
            return inpaint(provisional).astype(np.float64) + base
    return surface if lazy else surface(), objects, spec, extra


def smrf(xyz, *, cell: float = 1.0, slope: float = 0.15, window: float = 24.0,
         scalar: float = 1.25, threshold: float = 0.5, outlier_radius: float = 5.0,
         outlier_depth: float = 1.5, large: float | None = LARGE_REACH) -> np.ndarray:
    """Ground points by the Simple Morphological Filter.

    1. Low outliers (:func:`low_outliers`) are set aside as non-ground.
    2. :func:`smrf_surface` builds the provisional bare-earth surface ``ZIpro``.
    3. A point is ground when ``|z - ZIpro(x, y)| <= threshold + scalar *
       slope(x, y)``, with ``ZIpro`` and its slope (gradient magnitude)
       interpolated bilinearly at the point (Pingel et al. 2013, eq. 3).

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell : float
        Grid cell size in metres.
    slope : float
        Maximum terrain slope (rise over run) kept by the progressive opening.
    window : float
        Largest opening radius in metres: objects wider than about twice
        this are not removed.
    scalar : float
        Extra height tolerance per unit of surface slope (metres).
    threshold : float
        Height tolerance (metres) around the provisional surface.
    outlier_radius, outlier_depth : float
        Low-outlier detection (see :func:`low_outliers`); ``outlier_depth=inf``
        disables it.
    large : float or None
        Radius (m) up to which objects wider than twice ``window`` are looked
        for (:func:`smrf_surface`): large roofs, which the opening leaves in
        the terrain. Default :data:`~lidar2city.ground.large.LARGE_REACH`
        (session 17; the seven ISPRS samples and the Delft tile are unchanged,
        the ISPRS sites CSite2 and CSite4 lose 2,241 and 5,755 roof points
        from the ground); None or inf: Pingel's scheme.

    Returns
    -------
    ndarray of bool, shape (N,)
        True for ground points.

    Raises
    ------
    InputError
        Wrong shape, NaN coordinates or non-positive parameters.

    Notes
    -----
    The disks are octagons built from 3 x 3 square and cross steps (axial and
    diagonal radii within 3 %). Pingel's progressive scheme opens the previous
    opening; for this family of structuring elements that equals opening the
    minimum surface by each radius directly (granulometry), so the erosions
    are shared and one pass costs O(window^2 / cell^2) grid operations. The
    grid is padded with +inf (outside ignored): an object cut by the tile edge
    needs about twice its in-tile depth as radius, so low objects touching the
    edge may stay ground; process tiles with a buffer to avoid that.

    Defaults: Pingel's, except ``window`` 24 m instead of 18 m: the mean
    ISPRS total error is flat for windows of 24-40 m on the seven reference
    samples (3.56 % vs 3.64 % at 18 m) and larger windows remove buildings up
    to about 48 m across; wider roofs are found by ``large`` on a coarse grid
    instead (not in Pingel's scheme). With these defaults: mean total error
    3.56 %, mean kappa 89.3 % over samp11, 12, 21, 31, 41, 51, 61.

    References
    ----------
    Pingel, T. J., Clarke, K. C., McBride, W. A. (2013). An improved simple
    morphological filter for the terrain classification of airborne LIDAR
    data. ISPRS J. Photogramm. Remote Sens. 77, 21-30.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> z = np.where((abs(g[:, 0] - 30) < 6) & (abs(g[:, 1] - 30) < 6), 8.0, 0.0)
    >>> ground = smrf(np.column_stack([g, z]))
    >>> bool(ground[z == 0].all()), bool(ground[z == 8].any())
    (True, False)
    """
    if large is not None and np.isinf(large):
        large = None
    ground, _ = _smrf(xyz, cell=cell, slope=slope, window=window, scalar=scalar,
                      threshold=threshold, outlier_radius=outlier_radius,
                      outlier_depth=outlier_depth, large=large)
    return ground


def _near_surface(xyz, surface, spec, *, threshold, scalar):
    """Points within ``threshold + scalar * slope`` of ``surface`` (Pingel et al. 2013, eq. 3).

    ``surface`` (values at cell centres of ``spec``) and its slope are
    interpolated bilinearly at the points.
    """
    grad = gradient_magnitude(surface, spec.cell)
    weights = bilinear_weights(spec, xyz[:, :2])
    ref = sample_bilinear(surface, spec, weights=weights)
    tol = threshold + scalar * sample_bilinear(grad, spec, weights=weights)
    return np.abs(xyz[:, 2] - ref) <= tol


def _checked_outliers(xyz, *, cell, slope, window, scalar, threshold, outlier_radius,
                      outlier_depth, **extra):
    """Validated ``xyz`` and its low-outlier mask, for the SMRF-based filters.

    ``extra`` holds further positive parameters of the caller to validate with these.
    """
    xyz = _check_xyz(xyz)
    _check_positive(cell=cell, slope=slope, window=window, threshold=threshold,
                    outlier_radius=outlier_radius, outlier_depth=outlier_depth, **extra)
    if not scalar >= 0:
        raise InputError(f"scalar must be >= 0, got {scalar!r}")
    n = len(xyz)
    outliers = (low_outliers(xyz, radius=outlier_radius, depth=outlier_depth)
                if n and np.isfinite(outlier_depth) else np.zeros(n, dtype=bool))
    return xyz, outliers


def _smrf(xyz, *, cell, slope, window, scalar, threshold, outlier_radius, outlier_depth,
          extend=0.0, large=None, **extra):
    """SMRF's ground mask and low-outlier mask; ``extend`` and ``large`` as in
    :func:`smrf_surface`.

    ``extra`` holds further positive parameters of the caller to validate with these.
    """
    xyz, outliers = _checked_outliers(xyz, cell=cell, slope=slope, window=window, scalar=scalar,
                                      threshold=threshold, outlier_radius=outlier_radius,
                                      outlier_depth=outlier_depth,
                                      **extra, **({} if large is None else {"large": large}))
    n = len(xyz)
    if n == 0 or outliers.all():
        return np.zeros(n, dtype=bool), outliers
    surface, _, spec = smrf_surface(xyz, cell=cell, slope=slope, window=window,
                                    exclude=outliers, extend=extend, large=large)
    ground = _near_surface(xyz, surface, spec, threshold=threshold, scalar=scalar)
    ground &= ~outliers
    logger.debug("smrf: %d of %d points ground, %d low outliers", int(ground.sum()), n,
                 int(outliers.sum()))
    return ground, outliers
