"""Objects wider than SMRF's window: large buildings found on a coarse grid."""

from __future__ import annotations

import numpy as np

from .._components import component_labels
from ..errors import InputError
from ._grid import inpaint, open_disk_series

__all__ = ["LARGE_CELL", "LARGE_REACH", "LARGE_SHARE", "large_objects"]

#: Radius (m) up to which :func:`large_objects` opens the surface: roofs up to twice as
#: wide (a station hall, a warehouse, a shopping centre) are found.
LARGE_REACH = 100.0

#: Side (m) of the coarse cells :func:`large_objects` opens the surface on.
LARGE_CELL = 4.0

#: Least share of a large object's boundary stepping down by more than a coarse cell (a
#: roof stands above its surroundings all round; a terrain spur joins the slope behind it).
LARGE_SHARE = 0.75


def large_objects(zmin, *, cell: float, window: float, reach: float = LARGE_REACH,
                  coarse: float = LARGE_CELL, share: float = LARGE_SHARE,
                  jump: float = 0.6) -> np.ndarray:
    """Cells of objects too wide for an opening of radius ``window``: large roofs.

    SMRF's progressive opening removes an object only once its window is
    wider than the object, so a roof wider than twice the largest window
    (24 m by default) stays in the terrain: a station hall or a large
    department store is then called ground. Opening with larger windows on
    the fine grid costs time in proportion to the radius squared; here the
    lowest height of each ``coarse`` x ``coarse`` block is opened by disks
    from about the window up to ``reach`` (the surface continued beyond the
    edges by point reflection, as SMRF's own edge extension does), and a
    coarse cell whose opening drops by more than one coarse cell between two
    successive radii (a step steeper than 45 degrees: a wall, not a slope of
    any steepness terrain has over a coarse cell) is flagged. Flags are then
    judged by smooth segment of the coarse grid (neighbours joined when
    their heights differ by less than a coarse cell): a segment is a large
    object when it holds a flag, does not touch the grid's edge (a plateau
    running out of the tile may be terrain), covers at least ``window``
    squared, and steps down by more than a coarse cell along at least
    ``share`` of its boundary (a roof stands clear all round; a terrace or a
    spur joins the slope behind it). Its fine cells standing more than a
    coarse cell above the widest opening (courtyards are not) are marked,
    and the mark grows into neighbouring fine cells that join them within
    ``jump`` and stand as high (the roof's rim, in coarse blocks the wall
    crosses).

    Parameters
    ----------
    zmin : ndarray, shape (H, W)
        Lowest height per cell (m), NaN where a cell holds no point.
    cell : float
        Cell side of ``zmin`` (m).
    window : float
        Largest radius (m) of the fine opening (SMRF's ``window``).
    reach : float
        Largest radius (m) of the coarse opening.
    coarse : float
        Coarse cell side (m); at least two fine cells.
    share : float
        Least share of a segment's boundary that must step down.
    jump : float
        Largest step (m) between fine cells the mark grows across.

    Returns
    -------
    ndarray of bool, shape (H, W)
        The cells of large objects (empty cells never).

    Raises
    ------
    InputError
        Non-positive sizes, or ``share`` outside (0, 1].
    """
    for name, value in (("cell", cell), ("window", window), ("reach", reach),
                        ("coarse", coarse), ("jump", jump)):
        if not value > 0:
            raise InputError(f"{name} must be > 0, got {value!r}")
    if not 0 < share <= 1:
        raise InputError(f"share must be in (0, 1], got {share!r}")
    zmin = np.asarray(zmin)
    h, w = zmin.shape
    out = np.zeros((h, w), dtype=bool)
    k = max(2, int(round(coarse / cell)))
    side = k * cell
    first = max(1, int(np.floor(window / side)) - 2)  # overlap the fine series' last radii
    last = int(np.ceil(reach / side))
    hc, wc = -(-h // k), -(-w // k)
    if last <= first or min(hc, wc) < 3 or np.isnan(zmin).all():
        return out
    blocks = np.full((hc * k, wc * k), np.inf, dtype=zmin.dtype)
    blocks[:h, :w] = np.where(np.isnan(zmin), np.inf, zmin)
    zc = blocks.reshape(hc, k, wc, k).min(axis=(1, 3))
    zc = inpaint(np.where(np.isinf(zc), np.nan, zc).astype(np.float32))
    pad = min(last, hc - 1, wc - 1)
    padded = np.pad(zc, pad, mode="reflect", reflect_type="odd")
    flags = np.zeros(padded.shape, dtype=bool)
    step = np.float32(side)  # a drop of more than one coarse cell per coarse radius
    previous = None
    for _, opened in open_disk_series(padded, range(first, last + 1)):
        if previous is not None:
            flags |= (previous - opened) > step
        previous = opened
    flags = flags[pad:-pad, pad:-pad]
    widest = previous[pad:-pad, pad:-pad]
    if not flags.any():
        return out
    kept = _standing_segments(zc, flags, step=float(side), share=share,
                              min_cells=int(np.ceil((window / side) ** 2)))
    if not kept.any():
        return out
    fine = np.repeat(np.repeat(kept, k, axis=0), k, axis=1)[:h, :w]
    high = (zmin - np.repeat(np.repeat(widest, k, axis=0), k, axis=1)[:h, :w]) > side
    out = fine & high  # NaN compares False: empty cells stay out
    for _ in range(k + 1):  # the rim: cells of blocks the wall crosses
        grown = _grow_once(out, zmin, high, jump)
        if not (grown & ~out).any():
            break
        out = grown
    return out


def _standing_segments(zc, flags, *, step, share, min_cells):
    """Coarse cells of the smooth segments (4-neighbours within ``step``) of ``zc`` that hold
    a flag, keep off the edge, have ``min_cells`` cells and step down by ``step`` or more
    along at least ``share`` of their boundary."""
    h, w = zc.shape
    idx = np.arange(h * w).reshape(h, w)
    pairs = [(idx[:, :-1], idx[:, 1:], zc[:, :-1], zc[:, 1:]),
             (idx[:-1], idx[1:], zc[:-1], zc[1:])]
    a = np.concatenate([p[0][np.abs(p[2] - p[3]) < step] for p in pairs])
    b = np.concatenate([p[1][np.abs(p[2] - p[3]) < step] for p in pairs])
    label = component_labels(h * w, a, b).reshape(h, w)
    n = int(label.max()) + 1
    flagged = np.bincount(label[flags], minlength=n) > 0
    edge = np.zeros(n, dtype=bool)
    edge[np.concatenate([label[0], label[-1], label[:, 0], label[:, -1]])] = True
    cells = np.bincount(label.ravel(), minlength=n)
    edges, down = np.zeros(n), np.zeros(n)
    for ia, ib, za, zb in pairs:
        la, lb = label.ravel()[ia], label.ravel()[ib]
        for l1, l2, z1, z2 in ((la, lb, za, zb), (lb, la, zb, za)):
            m = l1 != l2
            edges += np.bincount(l1[m], minlength=n)
            down += np.bincount(l1[m], weights=(z1[m] - z2[m]) >= step, minlength=n)
    keep = flagged & ~edge & (cells >= min_cells) & (edges > 0) & (down >= share * edges)
    return keep[label]


def _grow_once(mask, z, allowed, jump):
    """``mask`` with the ``allowed`` 4-neighbours of its cells within ``jump`` of them."""
    out = mask.copy()
    for dst, src in (((slice(None), slice(1, None)), (slice(None), slice(None, -1))),
                     ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
                     ((slice(1, None), slice(None)), (slice(None, -1), slice(None))),
                     ((slice(None, -1), slice(None)), (slice(1, None), slice(None)))):
        out[dst] |= mask[src] & allowed[dst] & (np.abs(z[dst] - z[src]) < jump)
    return out
