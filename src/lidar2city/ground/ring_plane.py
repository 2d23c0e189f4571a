"""The plane of the ground around each object patch: a per-segment ground surface."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ._grid import grid_spec
from .connect_filter import surface_patches

__all__ = ["RING_FIT", "RING_JUMP", "RING_PATCH", "RING_REACH", "RING_RMS", "ring_ratios"]

#: Widths (m) of the neighbourhoods around an object patch whose ground a plane is fitted to.
RING_REACH = (3.0, 6.0, 12.0, 24.0)

#: RMS (m) of a plane fit within which a wider neighbourhood's ground is still one plane.
RING_RMS = 0.3

#: Fewest ground cells a plane is fitted to.
RING_FIT = 6

#: Fewest cells of an object patch.
RING_PATCH = 4

#: Step (m) between two surface patches (per metre of cell above 1 m).
RING_JUMP = 0.6


def _box_sums(table, r0, r1, c0, c1):
    """Sums over rows ``r0 <= i < r1`` and columns ``c0 <= j < c1`` of the grid whose
    summed-area ``table`` (H + 1, W + 1) is given, for arrays of boxes."""
    return table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]


def ring_ratios(xyz, ground_like, *, exclude=None, cell: float | None = None,
                jump: float = RING_JUMP, reaches=RING_REACH, rms: float = RING_RMS,
                threshold: float = 0.5, scalar: float = 1.25) -> np.ndarray:
    """Each point's tolerance ratio to the plane of the ground around its object patch.

    The surface is cut into smooth patches
    (:func:`~lidar2city.ground.surface_patches`: the lowest point of each cell at
    the point spacing, joined across steps of at most ``jump``): a roof, a terrace
    bench, ground running between buildings. A cell is ground when its lowest
    point is ``ground_like`` (e.g. within tolerance of every provisional surface);
    an object patch holds at least :data:`RING_PATCH` cells, fewer than half of
    them ground. Its neighbourhood is chosen per patch: among the boxes of its
    bounding box grown by each of ``reaches`` (m), the patch's own cells left
    out, the widest whose ground cells a
    least-squares plane fits within ``rms`` m RMS (the widest stretch of ground
    around the patch that is one plane: a hillside's ground above and below a
    bench between buildings, not another terrace's), else the narrowest with
    :data:`RING_FIT` ground cells. A point's ratio is ``|z - plane| / (threshold
    + scalar * |grad plane|)``, SMRF's final test on that plane.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3)
        Local metric coordinates.
    ground_like : ndarray of bool, shape (N,)
        Points taken for ground when they are their cell's lowest.
    exclude : ndarray of bool, shape (N,), optional
        Points left out (low outliers): their ratio is inf.
    cell : float or None
        Cell size (m); None: the point spacing (as :func:`surface_patches`).
    jump : float
        As in :func:`surface_patches`.
    reaches : sequence of float
        Neighbourhood widths (m), increasing.
    rms : float
        Plane-fit RMS (m) a wider neighbourhood must keep.
    threshold, scalar : float
        SMRF's tolerance: ``threshold`` m plus ``scalar`` per unit of slope.

    Returns
    -------
    ndarray, shape (N,)
        The ratio; inf for points outside object patches, of patches without a
        plane (too few ground cells around), and excluded points.

    Raises
    ------
    InputError
        Wrong shapes or invalid parameters.

    Examples
    --------
    A flat 6 m bench built up to 2 m out of a 20 % hillside, between two 6 m
    high houses: the bench is off the hillside's plane by its fill only (at most
    2.8 tolerances of 0.75 m), the roofs by their height (8).

    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> row = (g[:, 1] >= 27) & (g[:, 1] < 33)
    >>> bench = row & (g[:, 0] >= 20) & (g[:, 0] < 40)
    >>> house = row & ((abs(g[:, 0] - 14) < 6) | (abs(g[:, 0] - 46) < 6))
    >>> z = np.where(bench, 7.5, 0.2 * g[:, 1]) + np.where(house, 6.0, 0.0)
    >>> r = ring_ratios(np.column_stack([g, z]), ~(bench | house), cell=1.0)
    >>> float(r[bench].max().round(2)), float(r[house].min().round(2))
    (2.8, 8.0)
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError(f"xyz must be an (N, 3) array, got shape {xyz.shape}")
    ground_like = np.asarray(ground_like, dtype=bool)
    if ground_like.shape != (len(xyz),):
        raise InputError(f"ground_like must have shape ({len(xyz)},), got {ground_like.shape}")
    reaches = tuple(float(r) for r in reaches)
    if not reaches or any(not r > 0 for r in reaches) or list(reaches) != sorted(reaches):
        raise InputError(f"reaches must be increasing numbers > 0, got {reaches!r}")
    if not rms > 0:
        raise InputError(f"rms must be > 0, got {rms!r}")
    out = np.zeros(len(xyz), dtype=bool) if exclude is None else np.asarray(exclude, bool)
    ratio = np.full(len(xyz), np.inf)
    if len(xyz) == 0 or out.all():
        return ratio
    p = surface_patches(xyz, exclude=out, cell=cell, jump=jump)
    h, w = p["shape"]
    cell = p["cell"]
    spec = grid_spec(xyz[:, :2], cell=cell)  # the frame surface_patches gridded in
    cells, label = p["cells"], p["label"]
    lab = label[cells]
    n_lab = int(label.max()) + 1
    is_ground = ground_like[p["lowest"]]
    n_cells = np.bincount(lab, minlength=n_lab)
    n_ground = np.bincount(lab[is_ground], minlength=n_lab)
    objects = np.flatnonzero((n_cells >= RING_PATCH) & (2 * n_ground < n_cells))
    if len(objects) == 0 or not is_ground.any():
        return ratio
    rows, cols = cells // w, cells % w
    big = np.iinfo(np.int64).max
    rmin = np.full(n_lab, big)
    cmin = np.full(n_lab, big)
    rmax = np.full(n_lab, -1)
    cmax = np.full(n_lab, -1)
    np.minimum.at(rmin, lab, rows)
    np.minimum.at(cmin, lab, cols)
    np.maximum.at(rmax, lab, rows)
    np.maximum.at(cmax, lab, cols)
    rmin, rmax, cmin, cmax = rmin[objects], rmax[objects], cmin[objects], cmax[objects]
    # moments of the ground cells' lowest points (metres from the grid's top-left corner,
    # heights from their mean), as summed-area tables
    gr, gc = rows[is_ground], cols[is_ground]
    low = p["lowest"][is_ground]
    z0 = float(xyz[low, 2].mean())
    x, y, z = xyz[low, 0] - spec.x0, xyz[low, 1] - spec.y_top, xyz[low, 2] - z0
    tables, own = [], []
    glab = lab[is_ground]
    for v in (np.ones_like(x), x, y, z, x * x, x * y, y * y, x * z, y * z, z * z):
        g = np.zeros((h + 1, w + 1))
        np.add.at(g, (gr + 1, gc + 1), v)
        tables.append(g.cumsum(axis=0).cumsum(axis=1))
        # the patch's own ground cells, left out of its neighbourhood
        own.append(np.bincount(glab, weights=v, minlength=n_lab)[objects])
    n_obj = len(objects)
    chosen = np.zeros((n_obj, 3))
    has = np.zeros(n_obj, dtype=bool)
    done = np.zeros(n_obj, dtype=bool)
    for reach in reaches:
        k = int(np.ceil(reach / cell))
        box = (np.clip(rmin - k, 0, h), np.clip(rmax + k + 1, 0, h),
               np.clip(cmin - k, 0, w), np.clip(cmax + k + 1, 0, w))
        n, sx, sy, sz, sxx, sxy, syy, sxz, syz, szz = (_box_sums(t, *box) - o
                                                       for t, o in zip(tables, own))
        a = np.stack([np.stack([sxx, sxy, sx], -1), np.stack([sxy, syy, sy], -1),
                      np.stack([sx, sy, n], -1)], -2)
        bvec = np.stack([sxz, syz, sz], -1)
        scale = np.maximum(np.abs(a).max(axis=(1, 2)), 1e-300)
        ok = (n >= RING_FIT) & ~done & (np.abs(np.linalg.det(a / scale[:, None, None])) > 1e-9)
        coef = np.zeros((n_obj, 3))
        if ok.any():
            coef[ok] = np.linalg.solve(a[ok], bvec[ok][..., None])[..., 0]
        # residual sum of squares of the plane from the moments
        rss = (szz - 2 * (coef[:, 0] * sxz + coef[:, 1] * syz + coef[:, 2] * sz)
               + np.einsum("ni,nij,nj->n", coef, a, coef))
        fit = np.sqrt(np.maximum(rss, 0.0) / np.maximum(n, 1))
        take = ok & (~has | (fit <= rms))
        chosen[take] = coef[take]
        has |= take
        done |= ok & (fit > rms)
    # each point of an object patch with a plane: its ratio to that plane
    index = np.full(n_lab, -1)
    index[objects[has]] = np.flatnonzero(has)
    point_index = np.where(out, -1, index[label[p["flat"]]])
    pts = np.flatnonzero(point_index >= 0)
    c = chosen[point_index[pts]]
    px, py = xyz[pts, 0] - spec.x0, xyz[pts, 1] - spec.y_top
    plane = c[:, 0] * px + c[:, 1] * py + c[:, 2] + z0
    ratio[pts] = np.abs(xyz[pts, 2] - plane) / (threshold + scalar * np.hypot(c[:, 0], c[:, 1]))
    return ratio
