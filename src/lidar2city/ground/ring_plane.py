"""The plane of the ground around each object patch: a per-segment ground surface."""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ._grid import grid_spec
from .connect_filter import surface_patches

__all__ = ["RING_FIT", "RING_JUMP", "RING_NEIGHBOURHOODS", "RING_PATCH", "RING_REACH", "RING_RMS",
           "ring_ratios"]

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

#: The neighbourhoods :func:`ring_ratios` can take around a patch: ``"box"``, its bounding
#: box grown by the reach; ``"dilation"``, the cells within the reach of its own cells.
RING_NEIGHBOURHOODS = ("box", "dilation")


def _box_sums(table, r0, r1, c0, c1):
    """Sums over rows ``r0 <= i < r1`` and columns ``c0 <= j < c1`` of the grid whose
    summed-area ``table`` (H + 1, W + 1) is given, for arrays of boxes."""
    return table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0]


def ring_ratios(xyz, ground_like, *, exclude=None, cell: float | None = None,
                jump: float = RING_JUMP, reaches=RING_REACH, rms: float = RING_RMS,
                threshold: float = 0.5, scalar: float = 1.25,
                neighbourhood: str = "box", wanted=None) -> np.ndarray:
    """Each point's tolerance ratio to the plane of the ground around its object patch.

    The surface is cut into smooth patches
    (:func:`~lidar2city.ground.surface_patches`: the lowest point of each cell at
    the point spacing, joined across steps of at most ``jump``): a roof, a terrace
    bench, ground running between buildings. A cell is ground when its lowest
    point is ``ground_like`` (e.g. within tolerance of every provisional surface);
    an object patch holds at least :data:`RING_PATCH` cells, fewer than half of
    them ground. Its neighbourhood is chosen per patch: among the boxes of its
    bounding box grown by each of ``reaches`` (m) (with ``neighbourhood``
    ``"dilation"``: the cells within each reach of the patch's own cells, in
    the Chebyshev distance of the grid), the patch's own cells left
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
    neighbourhood : {"box", "dilation"}
        ``"box"`` (default): the grown bounding box, the ground cells' lowest
        points for x, y, z (summed-area tables; a patch's box reaches past
        the ground next to an L- or ring-shaped patch into other terraces);
        ``"dilation"``: the ground cells within the reach of the patch's own
        cells, their centres for x, y and lowest points for z (the exact ring
        of session 13's ``bench_ground_vote.py --ring``, without its loop over
        the patches: each reach is summed only for the patches still widening,
        stacked by box size, a summed-area table of the patch's cells telling
        which ground cells lie within the reach).
    wanted : ndarray of bool, shape (N,), optional
        The points whose ratio is needed: patches holding none of them are
        skipped (their points' ratio is inf). Default: every point.

    Returns
    -------
    ndarray, shape (N,)
        The ratio; inf for points outside object patches, of patches without a
        plane (too few ground cells around), of patches without a ``wanted``
        point, and excluded points.

    Raises
    ------
    InputError
        Wrong shapes or invalid parameters.

    Examples
    --------
    A flat 6 m bench built up to 2 m out of a 20 % hillside, between two 6 m
    high houses: the bench is off the hillside's plane by its fill only (at most
    2.8 tolerances of 0.75 m), the roofs by their height (8); with the cells
    within reach, the plane through the cell centres lies 0.1 m lower (the
    points sit on the cells' corners, the hillside rises 0.2 per metre).

    >>> g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    >>> row = (g[:, 1] >= 27) & (g[:, 1] < 33)
    >>> bench = row & (g[:, 0] >= 20) & (g[:, 0] < 40)
    >>> house = row & ((abs(g[:, 0] - 14) < 6) | (abs(g[:, 0] - 46) < 6))
    >>> z = np.where(bench, 7.5, 0.2 * g[:, 1]) + np.where(house, 6.0, 0.0)
    >>> r = ring_ratios(np.column_stack([g, z]), ~(bench | house), cell=1.0)
    >>> float(r[bench].max().round(2)), float(r[house].min().round(2))
    (2.8, 8.0)
    >>> r = ring_ratios(np.column_stack([g, z]), ~(bench | house), cell=1.0,
    ...                 neighbourhood="dilation")
    >>> float(r[bench].max().round(2)), float(r[house].min().round(2))
    (2.67, 7.87)
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
    if neighbourhood not in RING_NEIGHBOURHOODS:
        raise InputError(f"neighbourhood must be one of {', '.join(RING_NEIGHBOURHOODS)}, "
                         f"got {neighbourhood!r}")
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
    candidate = (n_cells >= RING_PATCH) & (2 * n_ground < n_cells)
    if wanted is not None:
        wanted = np.asarray(wanted, dtype=bool)
        if wanted.shape != (len(xyz),):
            raise InputError(f"wanted must have shape ({len(xyz)},), got {wanted.shape}")
        candidate &= np.bincount(label[p["flat"][wanted & ~out]], minlength=n_lab) > 0
    objects = np.flatnonzero(candidate)
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
    n_obj = len(objects)
    chosen = np.zeros((n_obj, 3))
    has = np.zeros(n_obj, dtype=bool)
    done = np.zeros(n_obj, dtype=bool)  # a wider reach's plane no longer fits: stop
    if neighbourhood == "box":
        moments, origin, z0 = _box_moments(xyz, p, spec, is_ground, lab, objects,
                                           (rmin, rmax, cmin, cmax), reaches)
    else:
        moments, origin, z0 = _dilation_moments(p, is_ground, lab, objects,
                                                (rmin, rmax, cmin, cmax), reaches, done)
    for n, sx, sy, sz, sxx, sxy, syy, sxz, syz, szz in moments:
        a = np.stack([np.stack([sxx, sxy, sx], -1), np.stack([sxy, syy, sy], -1),
                      np.stack([sx, sy, n], -1)], -2)
        bvec = np.stack([sxz, syz, sz], -1)
        if neighbourhood == "box":
            scale = np.maximum(np.abs(a).max(axis=(1, 2)), 1e-300)
            full = np.abs(np.linalg.det(a / scale[:, None, None])) > 1e-9
        else:  # the cells' spread about their centroid: not fooled by a far frame origin
            m = np.maximum(n, 1)
            cxx, cxy, cyy = sxx - sx * sx / m, sxy - sx * sy / m, syy - sy * sy / m
            full = cxx * cyy - cxy * cxy > 1e-9 * np.maximum(cxx + cyy, 1e-300) ** 2
        ok = (n >= RING_FIT) & ~done & full
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
    which = point_index[pts]
    c = chosen[which]
    px = xyz[pts, 0] - spec.x0 - origin[which, 0]
    py = xyz[pts, 1] - spec.y_top - origin[which, 1]
    plane = c[:, 0] * px + c[:, 1] * py + c[:, 2] + z0
    ratio[pts] = np.abs(xyz[pts, 2] - plane) / (threshold + scalar * np.hypot(c[:, 0], c[:, 1]))
    return ratio


def _box_moments(xyz, p, spec, is_ground, lab, objects, bounds, reaches):
    """Per reach, the ten plane-fit moments (n, x, y, z, xx, xy, yy, xz, yz, zz) of the
    ground cells' lowest points (metres from the grid's top-left corner, heights from their
    mean ``z0``) in each object patch's bounding box grown by the reach, its own cells left
    out (summed-area tables). Returns the moments (a generator), each patch's origin
    (zeros, (n_obj, 2)) and ``z0``."""
    h, w = p["shape"]
    cell = p["cell"]
    rmin, rmax, cmin, cmax = bounds
    cells = p["cells"]
    gr, gc = cells[is_ground] // w, cells[is_ground] % w
    low = p["lowest"][is_ground]
    z0 = float(xyz[low, 2].mean())
    x, y, z = xyz[low, 0] - spec.x0, xyz[low, 1] - spec.y_top, xyz[low, 2] - z0
    tables, own = [], []
    glab = lab[is_ground]
    n_lab = int(p["label"].max()) + 1
    for v in (np.ones_like(x), x, y, z, x * x, x * y, y * y, x * z, y * z, z * z):
        g = np.zeros((h + 1, w + 1))
        np.add.at(g, (gr + 1, gc + 1), v)
        tables.append(g.cumsum(axis=0).cumsum(axis=1))
        # the patch's own ground cells, left out of its neighbourhood
        own.append(np.bincount(glab, weights=v, minlength=n_lab)[objects])

    def moments():
        for reach in reaches:
            k = int(np.ceil(reach / cell))
            box = (np.clip(rmin - k, 0, h), np.clip(rmax + k + 1, 0, h),
                   np.clip(cmin - k, 0, w), np.clip(cmax + k + 1, 0, w))
            yield tuple(_box_sums(t, *box) - o for t, o in zip(tables, own))

    return moments(), np.zeros((len(objects), 2)), z0


#: Side (cells) the boxes of :func:`_dilation_moments` are rounded up to, so that patches of
#: about the same size are stacked into one array.
_BOX_ROUND = 16


def _dilation_moments(p, is_ground, lab, objects, bounds, reaches, done):
    """As :func:`_box_moments`, over the ground cells within each reach (Chebyshev distance,
    in cells) of the patch's own cells, with the cell centres for x, y and each cell's lowest
    point for z, in a frame per patch (its origin returned: the top-left corner of the
    patch's bounding box grown by the widest reach, metres from the grid's).

    The moments of a reach are summed only for the patches not ``done`` when the generator
    gets to it (the caller marks them between reaches; the others get zeros). Those patches
    are stacked by the size of their bounding box grown by the reach (rounded up to
    :data:`_BOX_ROUND` cells) into arrays; a summed-area table of each box's own cells tells
    which ground cells lie within the reach, and the moments are summed per patch by
    ``bincount``: no loop runs over the patches."""
    h, w = p["shape"]
    cell = p["cell"]
    rmin, rmax, cmin, cmax = bounds
    steps = [int(np.ceil(r / cell)) for r in reaches]
    big = steps[-1]
    zmin = p["zmin"]
    cells = p["cells"]
    z0 = float(zmin[cells[is_ground]].mean())
    # the grids padded by the widest reach before and by it plus the rounding after
    pad = ((big, big + _BOX_ROUND), (big, big + _BOX_ROUND))
    height = np.zeros(h * w)
    ground = np.zeros(h * w, dtype=bool)
    ground[cells[is_ground]] = True
    height[ground] = zmin[ground] - z0
    height = np.pad(height.reshape(h, w), pad)
    ground = np.pad(ground.reshape(h, w), pad)
    n_obj = len(objects)
    # the object patches' own cells: patch, row and column
    index = np.full(len(p["label"]), -1)
    index[objects] = np.arange(n_obj)
    own_patch = index[lab]
    mine = own_patch >= 0
    own_patch = own_patch[mine]
    own_order = np.argsort(own_patch, kind="stable")
    own_patch = own_patch[own_order]
    own_r = (cells[mine] // w)[own_order]
    own_c = (cells[mine] % w)[own_order]
    own_start = np.searchsorted(own_patch, np.arange(n_obj + 1))

    def moments():
        for k in steps:
            out = np.zeros((10, n_obj))
            alive = np.flatnonzero(~done)
            r0, c0 = rmin[alive] - k, cmin[alive] - k
            hh = -(-(rmax[alive] + k + 1 - r0) // _BOX_ROUND) * _BOX_ROUND
            ww = -(-(cmax[alive] + k + 1 - c0) // _BOX_ROUND) * _BOX_ROUND
            key = hh * (int(ww.max(initial=0)) + 1) + ww
            for size in np.unique(key):
                sel = np.flatnonzero(key == size)
                which = alive[sel]
                nb, sh, sw = len(which), int(hh[sel[0]]), int(ww[sel[0]])
                br, bc = r0[sel], c0[sel]
                # own cells of these patches, in box coordinates
                counts = own_start[which + 1] - own_start[which]
                o = np.repeat(own_start[which] - np.cumsum(counts) + counts, counts) \
                    + np.arange(int(counts.sum()))
                slot = np.repeat(np.arange(nb), counts)
                own = np.zeros((nb, sh, sw), dtype=bool)
                own[slot, own_r[o] - br[slot], own_c[o] - bc[slot]] = True
                # summed-area table of each box's own cells: a cell is within k of the
                # patch when the (2k + 1)-square around it holds one
                table = np.zeros((nb, sh + 1, sw + 1), dtype=np.int32)
                np.cumsum(own, axis=1, dtype=np.int32, out=table[:, 1:, 1:])
                np.cumsum(table[:, 1:, 1:], axis=2, out=table[:, 1:, 1:])
                table = table.ravel()
                ii = (br + big)[:, None, None] + np.arange(sh)[None, :, None]
                jj = (bc + big)[:, None, None] + np.arange(sw)[None, None, :]
                q, a, b = np.nonzero(ground[ii, jj] & ~own)
                base = q * ((sh + 1) * (sw + 1))
                a0, a1 = np.clip(a - k, 0, sh) * (sw + 1), np.clip(a + k + 1, 0, sh) * (sw + 1)
                b0, b1 = np.clip(b - k, 0, sw), np.clip(b + k + 1, 0, sw)
                near = (table[base + a1 + b1] - table[base + a0 + b1] - table[base + a1 + b0]
                        + table[base + a0 + b0]) > 0
                q, a, b = q[near], a[near], b[near]
                z = height[br[q] + big + a, bc[q] + big + b]
                # cell centres in the patch's frame (its box grown by the widest reach)
                x, y = (b + big - k + 0.5) * cell, -(a + big - k + 0.5) * cell
                for v, value in enumerate((None, x, y, z, x * x, x * y, y * y, x * z, y * z,
                                           z * z)):
                    out[v, which] = np.bincount(q, weights=value, minlength=nb)
            yield tuple(out)

    origin = np.column_stack([(cmin - big) * cell, -(rmin - big) * cell]).astype(np.float64)
    return moments(), origin, z0
