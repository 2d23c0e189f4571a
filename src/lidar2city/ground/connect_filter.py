"""Segment connectivity: a ground mask revised per smooth surface patch, not per point."""

from __future__ import annotations

import logging

import numpy as np

from .._components import component_labels
from ..errors import InputError
from ._grid import cell_of, grid_spec

logger = logging.getLogger(__name__)

__all__ = ["CONNECT_LOWER", "connect_ground", "surface_patches"]

#: ``lower`` of :func:`connect_ground` (its only rule on by default): the setting
#: ``benchmarks/bench_ground_connect.py`` fits on the seven ISPRS samples + synthetic
#: terrains after ``smrf_vote`` (among shares 0.6, 0.8, 0.95 or off, with the other rules).
CONNECT_LOWER = 0.95

#: 8-neighbour offsets (row, column) of a cell, one of each pair.
_OFFSETS = ((0, 1), (1, 0), (1, 1), (1, -1))

#: cell size (m) of the grid the point spacing is measured on.
_SPACING_GRID = 5.0


def surface_patches(xyz, *, exclude=None, cell: float | None = None, jump: float = 0.3,
                    step_slope: float = 0.0):
    """Smooth surface patches on the lowest point of each cell of a 2.5-D grid.

    Each cell holds its lowest point (points of ``exclude`` left out); two
    8-neighbour filled cells are joined when their lowest points differ by at
    most ``jump * max(cell, 1) + step_slope * d`` (``d`` the distance of the
    cell centres, m). A patch is a connected set of joined cells: a roof, a
    terrace bench, ground running between buildings; walls and risers are
    steps between patches.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    exclude : ndarray of bool, shape (N,), optional
        Points left out (low outliers).
    cell : float or None
        Cell size (m); None: the measured point spacing (``1 / sqrt(density)``
        over the occupied cells of a 5 m grid), rounded, at least 1 m, so that
        most cells hold a point.
    jump : float
        Step (m per metre of cell, at least 1 m) that separates two patches.
    step_slope : float
        Further rise allowed per metre between the cells (rise / run).

    Returns
    -------
    dict
        ``cell`` (m), ``shape`` (H, W), ``flat`` (N,) each point's flat cell
        index, ``lowest`` (C,) the point index of each filled cell's lowest
        point and ``cells`` (C,) that cell's flat index, ``label`` (H * W,)
        each cell's patch, ``a``, ``b`` (E,) the flat cells of the 8-neighbour
        edges between two filled cells of different patches and ``dz`` (E,)
        the height of ``a`` minus that of ``b``.

    Raises
    ------
    InputError
        Wrong shape or invalid parameters.

    Examples
    --------
    A 10 m x 10 m flat ground with a 4 m x 4 m box 3 m up: two patches.

    >>> g = np.stack(np.meshgrid(np.arange(10.0), np.arange(10.0)), -1).reshape(-1, 2)
    >>> box = (g[:, 0] >= 3) & (g[:, 0] < 7) & (g[:, 1] >= 3) & (g[:, 1] < 7)
    >>> p = surface_patches(np.column_stack([g, np.where(box, 3.0, 0.0)]), cell=1.0)
    >>> len(np.unique(p["label"][p["cells"]]))
    2
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or len(xyz) == 0:
        raise InputError(f"xyz must be a non-empty (N, 3) array, got shape {xyz.shape}")
    for name, value in (("jump", jump), ("step_slope", step_slope)):
        if not (isinstance(value, (int, float, np.integer, np.floating)) and value >= 0):
            raise InputError(f"{name} must be a number >= 0, got {value!r}")
    keep = np.ones(len(xyz), dtype=bool) if exclude is None else ~np.asarray(exclude, bool)
    if not keep.any():
        raise InputError("every point is excluded: no surface to cut into patches")
    if cell is None:
        cell = max(1.0, float(np.floor(_spacing(xyz[keep]) + 0.5)))
    elif not cell > 0:
        raise InputError(f"cell must be > 0 or None, got {cell!r}")
    spec = grid_spec(xyz[:, :2], cell=cell)
    h, w = spec.shape
    r, c = cell_of(xyz[:, :2], spec)
    flat = r * w + c
    kept = np.flatnonzero(keep)
    # each cell's lowest point (the first in index order among equally low ones), without
    # sorting the points: the least height per cell, then the least index at that height
    fk, zk = flat[kept], xyz[kept, 2]
    zmin = np.full(h * w, np.inf)
    np.minimum.at(zmin, fk, zk)
    low = kept[zk == zmin[fk]]
    first = np.full(h * w, len(xyz))
    np.minimum.at(first, flat[low], low)
    cells = np.flatnonzero(first < len(xyz))
    lowest = first[cells]
    zmin = np.full(h * w, np.nan)
    zmin[cells] = xyz[lowest, 2]
    idx = np.arange(h * w).reshape(h, w)
    aa, bb, dd = [], [], []
    for di, dj in _OFFSETS:
        aa.append(idx[:h - di, max(-dj, 0):w - max(dj, 0)].ravel())
        bb.append(idx[di:, max(dj, 0):w + min(dj, 0)].ravel())
        dd.append(np.full(aa[-1].size, cell * np.hypot(di, dj)))
    a, b, d = np.concatenate(aa), np.concatenate(bb), np.concatenate(dd)
    both = ~np.isnan(zmin[a]) & ~np.isnan(zmin[b])
    a, b, d = a[both], b[both], d[both]
    dz = zmin[a] - zmin[b]
    join = np.abs(dz) <= jump * max(cell, 1.0) + step_slope * d
    label = component_labels(h * w, a[join], b[join])
    cross = ~join
    return {"cell": float(cell), "shape": (h, w), "flat": flat, "lowest": lowest,
            "cells": cells, "label": label, "a": a[cross], "b": b[cross], "dz": dz[cross],
            "zmin": zmin}


def _spacing(xyz):
    """Point spacing (m): ``1 / sqrt(density)`` over the occupied cells of a 5 m grid."""
    spec = grid_spec(xyz[:, :2], cell=_SPACING_GRID)
    r, c = cell_of(xyz[:, :2], spec)
    occupied = int(np.count_nonzero(np.bincount(r * spec.shape[1] + c,
                                                minlength=spec.shape[0] * spec.shape[1])))
    return float(np.sqrt(occupied * _SPACING_GRID ** 2 / len(xyz)))


def connect_ground(xyz, ground, *, exclude=None, cell: float | None = None, jump: float = 0.3,
                   step_slope: float = 0.0, share: float | None = None,
                   lower: float | None = CONNECT_LOWER, raised: float | None = None,
                   pit: int = 0, tolerance: float = 0.3,
                   rounds: int = 3, patches=None) -> np.ndarray:
    """A ground mask revised per smooth surface patch (:func:`surface_patches`).

    Each round, a patch is ground when the lowest points of at least half its
    cells are ground in the current mask, and then:

    * a patch whose cells' lowest points are at least ``share`` ground (it
      runs on from accepted ground without a step) gives its other points
      within ``tolerance`` of their cell's lowest point to the ground;
    * an object patch that touches ground and lies lower than the patches
      around it along at least ``lower`` of its boundary (a bench below a
      riser, ground between buildings on a slope, stepped down from the
      ground above it) gives likewise its points near the lowest to the
      ground;
    * a ground patch raised above the patches around it along at least
      ``raised`` of its boundary (a roof the mask took for ground) is
      object, as is a ground patch of at most ``pit`` cells lower than the
      patches around it on every side (a pit, a low outlier).

    Rounds repeat, from the revised mask, until nothing changes or ``rounds``
    have run.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    ground : ndarray of bool, shape (N,)
        The mask to revise (e.g. :func:`~lidar2city.ground.smrf_vote`'s).
    exclude : ndarray of bool, shape (N,), optional
        Points never ground (low outliers).
    cell, jump, step_slope
        As in :func:`surface_patches`.
    share, lower, raised : float or None
        Shares in (0, 1] of the rules above; None turns a rule off. The
        defaults are the setting ``benchmarks/bench_ground_connect.py`` fits
        on the seven ISPRS samples + synthetic terrains after ``smrf_vote``:
        ``lower`` :data:`CONNECT_LOWER` alone.
    pit : int
        Largest pit (cells); 0 (default) turns the rule off.
    tolerance : float
        Height (m per metre of cell, at least 1 m) above its cell's lowest
        point within which a point is given to the ground with its patch.
    rounds : int
        Most rounds.
    patches : dict, optional
        :func:`surface_patches` of ``xyz`` already computed (the other
        patch parameters are then ignored).

    Returns
    -------
    ndarray of bool, shape (N,)
        The revised mask (``exclude`` never ground).

    Raises
    ------
    InputError
        Wrong shapes or invalid parameters.

    Notes
    -----
    Measured (off by default) by ``benchmarks/bench_ground_connect.py``.

    Examples
    --------
    A box 3 m up that a mask took for ground is taken back (``raised``):

    >>> g = np.stack(np.meshgrid(np.arange(20.0), np.arange(20.0)), -1).reshape(-1, 2)
    >>> box = (abs(g[:, 0] - 10) < 4) & (abs(g[:, 1] - 10) < 4)
    >>> xyz = np.column_stack([g, np.where(box, 3.0, 0.0)])
    >>> every = np.ones(len(xyz), dtype=bool)
    >>> bool((connect_ground(xyz, every, cell=1.0, raised=0.9) == ~box).all())
    True
    """
    ground = np.asarray(ground, dtype=bool)
    if ground.shape != (len(xyz),):
        raise InputError(f"ground must be a mask of the {len(xyz)} points, got {ground.shape}")
    for name, value in (("share", share), ("lower", lower), ("raised", raised)):
        if value is not None and not (
                isinstance(value, (int, float, np.integer, np.floating)) and 0 < value <= 1):
            raise InputError(f"{name} must be a number in (0, 1] or None, got {value!r}")
    if not (isinstance(tolerance, (int, float, np.integer, np.floating)) and tolerance > 0):
        raise InputError(f"tolerance must be a number > 0, got {tolerance!r}")
    for name, value in (("pit", pit), ("rounds", rounds)):
        if not (isinstance(value, (int, np.integer)) and value >= 0):
            raise InputError(f"{name} must be an integer >= 0, got {value!r}")
    out = np.zeros(len(ground), bool) if exclude is None else np.asarray(exclude, bool)
    ground = ground & ~out
    if rounds == 0 or out.all():
        return ground
    p = patches if patches is not None else surface_patches(
        xyz, exclude=out, cell=cell, jump=jump, step_slope=step_slope)
    label, a, b, dz = p["label"], p["a"], p["b"], p["dz"]
    n = label.size
    size = np.bincount(label[p["cells"]], minlength=n)
    point_patch = label[p["flat"]]
    near = (np.asarray(xyz)[:, 2] - p["zmin"][p["flat"]]) <= tolerance * max(p["cell"], 1.0)
    near &= ~out
    # boundary edges of each patch, each counted from both sides: lies lower or higher
    side, other = np.concatenate([label[a], label[b]]), np.concatenate([b, a])
    is_lower = np.concatenate([dz < 0, dz > 0])
    edges = np.bincount(side, minlength=n)
    lower_edges = np.bincount(side, weights=is_lower, minlength=n)
    for k in range(rounds):
        low_ground = np.zeros(n, dtype=bool)
        low_ground[p["cells"]] = ground[p["lowest"]]
        ground_cells = np.bincount(label[p["cells"]], weights=low_ground[p["cells"]],
                                   minlength=n)
        is_ground = ground_cells >= 0.5 * np.maximum(size, 1)
        touches = np.bincount(side, weights=low_ground[other], minlength=n) > 0
        bounded = edges > 0
        give = np.zeros(n, dtype=bool)
        if share is not None:
            give |= (ground_cells >= share * np.maximum(size, 1)) & (size > 0)
        if lower is not None:
            give |= ~is_ground & touches & bounded & (lower_edges >= lower * edges)
        take = np.zeros(n, dtype=bool)
        if raised is not None:
            take |= is_ground & bounded & (edges - lower_edges >= raised * edges) & (size >= 2)
        if pit:
            take |= is_ground & bounded & (lower_edges == edges) & (size <= pit)
        revised = (ground | (give[point_patch] & near)) & ~take[point_patch]
        if np.array_equal(revised, ground):
            break
        logger.debug("connect_ground round %d: %d points to ground, %d to object", k + 1,
                     int((revised & ~ground).sum()), int((ground & ~revised).sum()))
        ground = revised
    return ground
