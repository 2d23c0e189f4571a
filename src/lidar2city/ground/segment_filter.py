"""SMRF whose object cells are cut into smooth segments and the terrain-like ones given back."""

from __future__ import annotations

import functools
import logging

import numpy as np

from .._components import component_labels
from ..errors import InputError
from ._grid import inpaint, thread_map
from .smrf_filter import (
    _checked_outliers,
    _filled,
    _minimum_grid,
    _near_surface,
    _point_spacing,
    _smrf_grids,
)

logger = logging.getLogger(__name__)

__all__ = ["anchored_objects", "smrf_segments", "terrain_segments"]


def _block_lowest(zmin, objects, block):
    """``zmin`` and ``objects`` on cells ``block`` times larger: the lowest height of each
    block and the object flag of the fine cell that holds it."""
    h, w = zmin.shape
    hc, wc = -(-h // block), -(-w // block)
    z = np.full((hc * block, wc * block), np.inf, dtype=np.float32)
    z[:h, :w] = np.where(np.isnan(zmin), np.inf, zmin)
    o = np.zeros(z.shape, dtype=bool)
    o[:h, :w] = objects

    def blocks(a):
        return a.reshape(hc, block, wc, block).transpose(0, 2, 1, 3).reshape(hc, wc, -1)

    zb, ob = blocks(z), blocks(o)
    low = np.argmin(zb, axis=2)[..., None]
    zc = np.take_along_axis(zb, low, 2)[..., 0]
    oc = np.take_along_axis(ob, low, 2)[..., 0]
    empty = np.isinf(zc)
    return np.where(empty, np.float32(np.nan), zc), oc & ~empty


def _fill_from_neighbours(grid):
    """``grid`` with each NaN cell given the lowest value of the 4-neighbour cells filled one
    ring before it (a breadth-first fill from the filled cells: walls stay steps)."""
    z = grid.copy()
    empty = np.isnan(z)
    while empty.any():
        padded = np.pad(np.where(empty, np.inf, z), 1, constant_values=np.inf)
        lowest = np.minimum.reduce([padded[:-2, 1:-1], padded[2:, 1:-1],
                                    padded[1:-1, :-2], padded[1:-1, 2:]])
        now = empty & np.isfinite(lowest)
        if not now.any():
            break
        z[now] = lowest[now]
        empty &= ~now
    return z


def _grid_labels(hjoin, vjoin):
    """A component id (< H * W) of every cell of a grid whose 4-neighbour cells are joined
    where ``hjoin`` (H, W-1: a cell and the one east of it) and ``vjoin`` (H-1, W: a cell
    and the one south of it) are True.

    Each row is cut into runs of horizontally joined cells first, so
    :func:`component_labels` only joins runs (several times fewer nodes, and
    no steps along a run).
    """
    h, w = vjoin.shape[0] + 1, hjoin.shape[1] + 1
    start = np.ones((h, w), dtype=bool)
    start[:, 1:] = ~hjoin
    run = np.cumsum(start.ravel()) - 1
    down = vjoin.ravel()
    return component_labels(int(run[-1]) + 1, run[:-w][down], run[w:][down])[run]


def anchored_objects(objects, strong) -> np.ndarray:
    """Object cells 4-connected (through object cells) to a ``strong`` object cell.

    Hysteresis on SMRF's slope: a cell judged object only by a strict slope
    threshold stays object when its object region also holds a cell judged
    object at a lenient one (a wall, a crown edge); a region cut only by the
    strict threshold (a hilltop, a terrace edge, the convex top of a steep
    slope) is terrain.

    Parameters
    ----------
    objects, strong : ndarray of bool, shape (H, W)

    Returns
    -------
    ndarray of bool, shape (H, W)
        The cells of ``objects`` whose component holds a cell of ``objects & strong``.
    """
    h, w = objects.shape
    o = objects.ravel()
    label = _grid_labels(objects[:, :-1] & objects[:, 1:], objects[:-1, :] & objects[1:, :]).ravel()
    anchored = np.zeros(h * w, dtype=bool)
    anchored[label[o & strong.ravel()]] = True
    return (o & anchored[label]).reshape(h, w)


def terrain_segments(zmin, objects, *, jump: float = 0.6, raised: float = 0.6,
                     min_cells: int = 4, block: int = 1) -> np.ndarray:
    """Object cells that stay objects once smooth terrain-like segments are given back.

    The object cells are cut into smooth segments: 4-neighbour cells whose
    lowest points differ by less than ``jump`` are joined (empty cells take
    the lowest height of the filled cells next to them, ring by ring, so walls
    stay steps). A segment of at least ``min_cells`` filled cells that is
    raised by ``jump`` or more above the neighbouring terrain cells along less
    than a fraction ``raised`` of their common boundary (edges between two
    filled cells) is terrain: a building or a tree stands above the terrain all round, a
    terrace top, an embankment or ground between buildings on a slope joins
    the terrain smoothly along much of its boundary.

    With ``block`` > 1 the segments are cut on cells ``block`` times larger
    (each holding the lowest height of its block and the object flag of the
    fine cell it comes from), so that sparse points (spacing of several fine
    cells) still form connected surfaces; a block given back gives back all
    its fine object cells.

    Parameters
    ----------
    zmin : ndarray, shape (H, W)
        Lowest height per cell, NaN where empty.
    objects : ndarray of bool, shape (H, W)
        Cells judged object (e.g. by SMRF's progressive opening).
    jump : float
        Height step (m) that separates segments and makes a boundary edge raised.
    raised : float
        Largest raised share of a terrain segment's boundary with the terrain.
    min_cells : int
        Fewest filled cells of a segment given back.
    block : int
        Cells per side of a segmentation cell.

    Returns
    -------
    ndarray of bool, shape (H, W)
        ``objects`` without the cells given back.
    """
    return _terrain_segments(zmin, [objects], jump=jump, raised=raised, min_cells=min_cells,
                             block=block)[0]


def _terrain_segments(zmin, masks, *, jump, raised, min_cells, block=1):
    """:func:`terrain_segments` of each object mask of ``masks`` on the same ``zmin`` (its
    filled heights and their steps computed once)."""
    if not (isinstance(block, (int, np.integer)) and block >= 1):
        raise InputError(f"block must be an integer >= 1, got {block!r}")
    h, w = zmin.shape
    if block > 1:
        coarse = [_block_lowest(zmin, objects, block) for objects in masks]
        kept = _terrain_segments(coarse[0][0], [oc for _, oc in coarse], jump=jump,
                                 raised=raised, min_cells=min_cells)
        out = []
        for objects, (_, oc), k in zip(masks, coarse, kept):
            back = np.repeat(np.repeat(oc & ~k, block, axis=0), block, axis=1)
            out.append(objects & ~back[:h, :w])
        return out
    empty = np.isnan(zmin)
    if empty.all() or not any(objects.any() for objects in masks):
        return [objects.copy() for objects in masks]
    z = _fill_from_neighbours(zmin).ravel()
    filled = ~empty.ravel()
    idx = np.arange(z.size).reshape(zmin.shape)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    dz = z[a] - z[b]
    smooth = np.abs(dz) < jump
    both = filled[a] & filled[b]
    n = z.size

    def kept(objects):
        obj = objects.ravel()
        join = smooth & obj[a] & obj[b]
        label = _grid_labels(join[:h * (w - 1)].reshape(h, w - 1),
                             join[h * (w - 1):].reshape(h - 1, w)).ravel()
        edges, high = np.zeros(n), np.zeros(n)
        for side, other, sign in ((a, b, 1.0), (b, a, -1.0)):
            m = obj[side] & ~obj[other] & both
            edges += np.bincount(label[side[m]], minlength=n)
            high += np.bincount(label[side[m]], weights=sign * dz[m] >= jump, minlength=n)
        cells = np.bincount(label[obj & filled], minlength=n)
        terrain = (edges > 0) & (high < raised * edges) & (cells >= min_cells)
        return (obj & ~terrain[label]).reshape(zmin.shape)

    return thread_map(kept, masks, cells=n)  # the masks are independent


def smrf_segments(xyz, *, cell: float = 1.0, slope: float = 0.15, window: float = 24.0,
                  scalar: float = 1.25, threshold: float = 0.5, extend: float = 10.0,
                  jump: float = 0.6, raised: float = 0.6, min_cells: int = 4,
                  strong_slope: float | None = None, outlier_radius: float = 5.0,
                  outlier_depth: float = 1.5) -> np.ndarray:
    """Ground points by SMRF with terrain-like object segments given back to the surface.

    1. Low outliers (:func:`~lidar2city.ground.low_outliers`) are set aside as non-ground.
    2. SMRF's progressive opening (:func:`~lidar2city.ground.smrf_surface`,
       minimum surface continued ``extend`` metres across the tile edges as
       in :func:`~lidar2city.ground.smrf_refined`) judges cells object.
    3. :func:`terrain_segments` gives back the object segments that join the
       terrain smoothly (terrace tops, embankments, ground between buildings
       on a slope, which an opening cuts like buildings), on segmentation
       cells of about the measured point spacing (``block`` = spacing / cell,
       rounded, at least 1; the spacing is ``1 / sqrt(density)`` over the
       occupied cells of a grid of about 5 m), with ``jump`` scaled by that
       cell size when it exceeds 1 m.
    4. With ``strong_slope`` (hysteresis on SMRF's slope, off by default),
       :func:`anchored_objects` gives back too every remaining object region
       (4-connected object cells) without a cell that the same opening
       series judges object at ``strong_slope``: a wall or a crown edge is cut
       at any slope, a hilltop, a terrace edge or a bridge ramp only at a
       strict one, so a strict ``slope`` (0.1, which flat urban samples want)
       no longer cuts steep terrain.
    5. The provisional surface is the minimum surface of the remaining
       terrain cells, inpainted, and points within ``threshold + scalar *
       slope`` of it are ground (Pingel et al. 2013, eq. 3).

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    cell, slope, window, scalar, threshold, outlier_radius, outlier_depth : float
        As in :func:`~lidar2city.ground.smrf`.
    extend : float
        As in :func:`~lidar2city.ground.smrf_refined`.
    jump, raised, min_cells
        As in :func:`terrain_segments`.
    strong_slope : float or None
        Slope (rise over run) at which an object region must hold a cell cut
        by the opening to stay object; None (default) leaves step 4 out.
        Measured by ``benchmarks/bench_ground_segments.py`` (``hysteresis``:
        slope 0.1, strong_slope 0.4).

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
    Measured against ``smrf_refined`` by ``benchmarks/bench_ground_segments.py``
    (the seven ISPRS samples, leave-one-sample-out and the synthetic
    terrains). Like ``smrf_refined`` it reflects the surface across the tile
    edges, which turns objects near an edge into pits; when that leaves less
    than half the terrain cells plain SMRF leaves (a tile not much larger than
    a building in it), the surface is not extended.

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
    >>> ground = smrf_segments(np.column_stack([g, np.where(box, 8.0, 0.0)]))
    >>> bool(ground[~box].all()), bool(ground[box].any())
    (True, False)
    """
    _check_segment_params(raised=raised, min_cells=min_cells)
    if strong_slope is not None and not (
            isinstance(strong_slope, (int, float, np.integer, np.floating)) and strong_slope > 0):
        raise InputError(f"strong_slope must be a number > 0 or None, got {strong_slope!r}")
    xyz, out = _checked_outliers(xyz, cell=cell, slope=slope, window=window, scalar=scalar,
                                 threshold=threshold, outlier_radius=outlier_radius,
                                 outlier_depth=outlier_depth, jump=jump)
    n = len(xyz)
    if n == 0 or out.all():
        return np.zeros(n, dtype=bool)
    surfaces, spec = _segment_surfaces(xyz, out, cell=cell, slope=slope, window=window,
                                       extend=extend, jump=jump, raised=raised,
                                       min_cells=min_cells, strong_slope=strong_slope)
    ground = _near_surface(xyz, surfaces[0], spec, threshold=threshold, scalar=scalar) & ~out
    logger.debug("smrf_segments: %d of %d points ground", int(ground.sum()), n)
    return ground


def _check_segment_params(*, raised, min_cells):
    if not (isinstance(raised, (int, float, np.integer, np.floating)) and 0 < raised <= 1):
        raise InputError(f"raised must be in (0, 1], got {raised!r}")
    if not (isinstance(min_cells, (int, np.integer)) and min_cells >= 1):
        raise InputError(f"min_cells must be an integer >= 1, got {min_cells!r}")


def _segment_surfaces(xyz, out, *, cell, slope, window, extend, jump, raised, min_cells,
                      strong_slope=None, also=(), marks=(), then=None, fill=None,
                      fill_where="o", fill_value="nearest", fill_marks=False, large=None):
    """Steps 2-4 of :func:`smrf_segments` from one opening series: the provisional surface
    at ``slope`` (with ``strong_slope`` hysteresis when given) followed by, for each slope of
    ``also``, the surface with the object cells at that slope given back likewise and then
    SMRF's own surface at ``slope`` (no segments given back); the grid; and, when ``marks``
    are given, the cells judged object at each of those slopes (a list of masks) and the
    minimum surface (float32 heights above ``base``, NaN where empty) with ``base``.

    With ``then``, a function of the grid returning a function of a surface, each
    surface is replaced by ``then(spec)(surface)``, computed right after it. The
    surfaces (their inpainting and ``then``) are computed on threads
    (:func:`~lidar2city.ground._grid.thread_map`).

    With ``fill`` (a share of the point spacing), the empty cells of the minimum surface
    within ``fill`` spacings of a filled cell take the nearest one's height before the
    inpainting of the opening's input (``fill_where`` "o", the default) and/or of every
    surface ("f"; "of": both); ``fill_value`` as in
    :func:`~lidar2city.ground.smrf_filter._smrf_grids`. The ``marks`` come from the
    opening of the minimum surface inpainted without the fill (a second opening series)
    unless ``fill_marks``. ``large``: as in
    :func:`~lidar2city.ground.smrf_filter._smrf_grids` (objects wider than the window)."""
    pts = xyz[~out]
    more = (*marks, *also) if strong_slope is None else (*marks, strong_slope, *also)
    minimum = _minimum_grid(pts, cell=cell)  # one minimum surface for every step
    _, base, zmin = minimum
    # point spacing: 1 / sqrt(density) over the occupied cells of a grid of about 5 m
    spacing = _point_spacing(zmin, cell, len(pts))
    radius = 0.0 if fill is None else fill * spacing / cell
    fills = {"fill_radius": radius, "fill_where": fill_where, "fill_value": fill_value,
             "fill_step": spacing / cell,
             "unfilled_more": 0 if fill_marks else len(marks)}
    surface, objects, spec, extra = _smrf_grids(xyz, cell=cell, slope=slope, window=window,
                                                exclude=out, extend=extend, more=more,
                                                minimum=minimum, lazy=True, large=large,
                                                **fills)
    filled = ~np.isnan(zmin)
    terrain_share = float((filled & ~objects).sum() / filled.sum())
    if extend > 0 and terrain_share < 0.5:
        # the reflection turns objects near the edges into pits; on a tile not much
        # larger than them that can make the whole tile object: keep SMRF's own edges
        # when they leave more than twice as much terrain
        plain = _smrf_grids(xyz, cell=cell, slope=slope, window=window, exclude=out,
                            more=more, minimum=minimum, lazy=True, large=large, **fills)
        if terrain_share < 0.5 * float((filled & ~plain[1]).sum() / filled.sum()):
            logger.debug("smrf_segments: edge extension left %.0f %% terrain; not extended",
                         100 * terrain_share)
            surface, objects, _, extra = plain
    marked, extra = extra[:len(marks)], extra[len(marks):]
    strong = None if strong_slope is None else extra.pop(0)
    block = max(1, int(np.floor(spacing / cell + 0.5)))
    final = (radius if "f" in fill_where else 0.0, fill_value, spacing / cell)
    surface = functools.cache(surface)  # plain SMRF's: needed twice when nothing is given back
    tasks = []  # a function of no argument per surface
    masks = [objects, *extra]
    kept_all = _terrain_segments(zmin, masks, jump=jump * max(cell * block, 1.0), raised=raised,
                                 min_cells=min_cells, block=block)
    for k, (obj, kept) in enumerate(zip(masks, kept_all)):
        if k == 0 and strong is not None:
            kept = anchored_objects(kept, strong)
        given = obj & ~kept & filled
        logger.debug("smrf_segments: %d of %d object cells given back (segmentation cell %g m)",
                     int(given.sum()), int(obj.sum()), cell * block)
        if given.any():
            tasks.append(functools.partial(_inpainted, zmin, kept | ~filled, base, *final))
        else:
            tasks.append(surface if k == 0 else functools.partial(_inpainted, zmin, obj, base,
                                                                  *final))
    if also:
        tasks.append(surface)
    after = (lambda s: s) if then is None else then(spec)
    surfaces = thread_map(lambda task: after(task()), tasks, cells=zmin.size)
    return (surfaces, spec, marked, (zmin, base)) if marks else (surfaces, spec)


def _inpainted(zmin, objects, base, fill_radius=0.0, fill_value="nearest", fill_step=1.0):
    """The minimum surface without ``objects``, inpainted, in metres (SMRF's ``ZIpro``); with
    ``fill_radius`` (cells) of 1 or more its empty cells within that radius of a kept cell
    are filled first (:func:`~lidar2city.ground.smrf_filter._filled`)."""
    grid = np.where(objects, np.float32(np.nan), zmin)
    if fill_radius >= 1:
        grid = _filled(grid, fill_radius, np.isnan(zmin), fill_value, fill_step)
    return inpaint(grid).astype(np.float64) + base
