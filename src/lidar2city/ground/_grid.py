"""Grid kernels shared by the ground filters: rasterising, morphology, inpainting, sampling.

Pure numpy (no scipy import: the ``ground`` command must start fast). Grids are
north-up: row 0 is the top (largest y), as in GeoTIFFs. A grid is described by
:class:`GridSpec` in local metric coordinates.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = [
    "GridSpec",
    "grid_spec",
    "cell_of",
    "min_surface",
    "centre_surface",
    "inpaint",
    "nearest_fill",
    "running_extreme",
    "erode_square",
    "dilate_square",
    "open_square",
    "open_disk",
    "open_disk_series",
    "thread_map",
    "bilinear_weights",
    "sample_bilinear",
    "gradient_magnitude",
]


@dataclass(frozen=True)
class GridSpec:
    """A north-up grid in local metric coordinates.

    Parameters
    ----------
    x0 : float
        x of the left edge of column 0 (metres).
    y_top : float
        y of the top edge of row 0 (metres).
    cell : float
        Square cell size (metres).
    shape : tuple of int
        ``(rows, cols)``.
    """

    x0: float
    y_top: float
    cell: float
    shape: tuple[int, int]

    def centers(self) -> tuple[np.ndarray, np.ndarray]:
        """x of column centres (W,) and y of row centres (H,)."""
        h, w = self.shape
        return (self.x0 + (np.arange(w) + 0.5) * self.cell,
                self.y_top - (np.arange(h) + 0.5) * self.cell)


def grid_spec(xy, *, cell: float, bounds=None) -> GridSpec:
    """The grid covering ``xy`` (N, 2) or ``bounds`` = (xmin, ymin, xmax, ymax).

    The edges are multiples of ``cell`` so grids of one frame line up.
    """
    if not cell > 0:
        raise InputError(f"cell must be > 0, got {cell!r}")
    if bounds is None:
        xy = np.asarray(xy, dtype=np.float64)
        if len(xy) == 0:
            raise InputError("cannot grid an empty point set")
        # 1-D reductions of the columns: much faster than axis=0 on an (N, 3) view
        xmin, xmax = float(np.min(xy[:, 0])), float(np.max(xy[:, 0]))
        ymin, ymax = float(np.min(xy[:, 1])), float(np.max(xy[:, 1]))
    else:
        xmin, ymin, xmax, ymax = (float(v) for v in bounds)
        if not (xmax >= xmin and ymax >= ymin):
            raise InputError(f"bounds must be (xmin, ymin, xmax, ymax), got {bounds!r}")
    x0 = np.floor(xmin / cell) * cell
    y0 = np.floor(ymin / cell) * cell
    w = int(np.floor((xmax - x0) / cell)) + 1
    h = int(np.floor((ymax - y0) / cell)) + 1
    if h * w > 400_000_000:
        raise InputError(f"a {h} x {w} grid is too large; use a larger cell size")
    return GridSpec(float(x0), float(y0 + h * cell), float(cell), (h, w))


def cell_of(xy, spec: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Row and column (int64, clipped to the grid) of each point of ``xy`` (N, 2)."""
    xy = np.asarray(xy, dtype=np.float64)
    h, w = spec.shape
    col = np.floor((xy[:, 0] - spec.x0) / spec.cell).astype(np.int64)
    row = np.floor((spec.y_top - xy[:, 1]) / spec.cell).astype(np.int64)
    np.clip(col, 0, w - 1, out=col)
    np.clip(row, 0, h - 1, out=row)
    return row, col


def min_surface(xyz, spec: GridSpec, *, flat_index=None, base: float = 0.0,
                dtype=np.float64) -> np.ndarray:
    """Lowest z per cell, shape ``spec.shape``; NaN where a cell holds no point.

    ``base`` is subtracted from the heights first (use it with ``dtype=float32``
    to keep precision while halving memory traffic).
    """
    if flat_index is None:
        r, c = cell_of(xyz[:, :2], spec)
        flat_index = r * spec.shape[1] + c
    grid = np.full(spec.shape[0] * spec.shape[1], np.inf, dtype=dtype)
    z = np.asarray(xyz[:, 2], dtype=np.float64)
    if base:
        z = z - base
    np.minimum.at(grid, flat_index, z.astype(dtype, copy=False))
    grid[np.isinf(grid)] = np.nan
    return grid.reshape(spec.shape)


def centre_surface(xyz, spec: GridSpec) -> np.ndarray:
    """Height at each cell centre from the points in the cell; NaN where a cell holds none.

    A cell whose points span it in both directions takes their least-squares
    plane evaluated at its centre, so a slope sampled unevenly within a cell is
    not biased by up to slope x cell / 2 as a plain mean would be; other cells
    take the mean height.
    """
    r, c = cell_of(xyz[:, :2], spec)
    flat = r * spec.shape[1] + c
    size = spec.shape[0] * spec.shape[1]
    cx = spec.x0 + (c + 0.5) * spec.cell
    cy = spec.y_top - (r + 0.5) * spec.cell
    # moments about the cell centre, per cell
    dx, dy, z = xyz[:, 0] - cx, xyz[:, 1] - cy, xyz[:, 2]
    m = [np.bincount(flat, weights=w, minlength=size)
         for w in (np.ones_like(z), dx, dy, z, dx * dx, dx * dy, dy * dy, dx * z, dy * z)]
    n, sx, sy, sz, sxx, sxy, syy, sxz, syz = m
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = sz / n
        # centred second moments and the plane's gradient
        vxx, vxy, vyy = sxx - sx * sx / n, sxy - sx * sy / n, syy - sy * sy / n
        vxz, vyz = sxz - sx * sz / n, syz - sy * sz / n
        det = vxx * vyy - vxy * vxy
        gx = (vxz * vyy - vyz * vxy) / det
        gy = (vyz * vxx - vxz * vxy) / det
        # plane value at the centre (dx = dy = 0): mean - g . (mean offset)
        at_centre = mean - gx * sx / n - gy * sy / n
    # well spread: both axes covered by at least a third of a cell (std), 3+ points
    spread = (n >= 3) & (vxx > n * (spec.cell / 6) ** 2) & (vyy > n * (spec.cell / 6) ** 2) \
        & (det > 0.25 * vxx * vyy)
    out = np.where(spread, at_centre, mean)
    return out.reshape(spec.shape)


def nearest_fill(grid, radius: float, where=None) -> np.ndarray:
    """``grid`` with each NaN cell within ``radius`` cells of a known cell given the value of
    the nearest known cell (a Voronoi fill of the near empty cells).

    Distances are Euclidean between cell centres; a cell equally near several
    known cells takes the first of its offsets in the order (squared
    distance, row offset, column offset), so the result is deterministic.
    Only cells of ``where`` (all NaN cells when None) are filled; the values
    spread are those of the known cells of ``grid`` only (never of cells
    filled here). On a grid finer than the point spacing this keeps a step
    in the terrain a step for an inpainting that follows (empty cells beside
    a wall take the height of the side they are on), instead of a ramp from
    the last low point to the first high one.

    Parameters
    ----------
    grid : ndarray, shape (H, W), float
    radius : float
        Farthest fill, in cells (>= 0; below 1 nothing is filled).
    where : ndarray of bool, shape (H, W), optional
        The empty cells that may be filled.

    Returns
    -------
    ndarray, shape (H, W)
        A new array of the same dtype.

    Raises
    ------
    InputError
        Negative or non-finite ``radius``, or ``where`` of another shape.
    """
    return _nearest_fill(grid, radius, where)[0]


def _nearest_fill(grid, radius, where=None):
    """:func:`nearest_fill` and, per cell, the row and column offsets (int8 arrays) from it
    to the known cell its value comes from (0 where nothing was filled)."""
    if not (isinstance(radius, (int, float, np.integer, np.floating)) and np.isfinite(radius)
            and radius >= 0):
        raise InputError(f"radius must be a finite number >= 0, got {radius!r}")
    grid = np.asarray(grid)
    out = grid.copy()
    known = np.isfinite(grid)
    todo = ~known
    if where is not None:
        where = np.asarray(where, dtype=bool)
        if where.shape != grid.shape:
            raise InputError(f"where has shape {where.shape}, the grid {grid.shape}")
        todo &= where
    reach = int(np.floor(radius))
    drs = np.zeros(grid.shape, dtype=np.int8)
    dcs = np.zeros(grid.shape, dtype=np.int8)
    if reach < 1 or not todo.any() or not known.any():
        return out, drs, dcs
    if reach > 127:
        raise InputError(f"radius must be below 128 cells, got {radius!r}")
    h, w = grid.shape
    offsets = sorted((dr * dr + dc * dc, dr, dc) for dr in range(-reach, reach + 1)
                     for dc in range(-reach, reach + 1)
                     if 0 < dr * dr + dc * dc <= radius * radius)
    for _, dr, dc in offsets:
        # target cells [r0:r1, c0:c1] take the source cells shifted by (dr, dc)
        r0, r1 = max(0, -dr), min(h, h - dr)
        c0, c1 = max(0, -dc), min(w, w - dc)
        if r0 >= r1 or c0 >= c1:
            continue
        t = todo[r0:r1, c0:c1]
        take = t & known[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
        if not take.any():
            continue
        np.copyto(out[r0:r1, c0:c1], grid[r0 + dr:r1 + dr, c0 + dc:c1 + dc], where=take)
        drs[r0:r1, c0:c1][take] = dr
        dcs[r0:r1, c0:c1][take] = dc
        t &= ~take  # a view of todo: these cells are done
        if not todo.any():
            break
    return out, drs, dcs


def _every_other(start: int, n: int) -> slice:
    """``n`` indices from ``start`` in steps of 2."""
    return slice(start, start + 2 * n, 2)


def _relax(values, unknown, iterations, omega=1.6):
    """Red-black SOR relaxation of Laplace's equation on ``unknown`` cells (known fixed).

    Outside the grid the values are replicated from the edge (zero-gradient
    boundary), so holes touching the border are filled smoothly too.
    """
    h, w = values.shape
    if not unknown.any():
        return values
    # restrict the work to the bounding box of the unknown cells plus one cell
    rows = np.flatnonzero(unknown.any(axis=1))
    cols = np.flatnonzero(unknown.any(axis=0))
    r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, h)
    c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, w)
    u = unknown[r0:r1, c0:c1]
    hh, ww = u.shape
    p = np.empty((hh + 2, ww + 2), dtype=values.dtype)
    v = p[1:-1, 1:-1]  # a view: updates land in the padded array directly
    v[...] = values[r0:r1, c0:c1]
    quarter = values.dtype.type(omega / 4.0)
    keep = values.dtype.type(1.0 - omega)
    # each colour is two strided blocks (rows of one parity, every other column): only
    # its own cells are computed; their neighbours are all of the other colour, so the
    # values are those of a whole-grid sweep
    sweeps = []
    for colour in (0, 1):
        blocks = []
        for ri in (0, 1):
            cj = (colour - ri - r0 - c0) % 2
            if ri >= hh or cj >= ww or not u[ri::2, cj::2].any():
                continue
            nr, nc = len(range(ri, hh, 2)), len(range(cj, ww, 2))
            mid_r, mid_c = _every_other(ri + 1, nr), _every_other(cj + 1, nc)
            blocks.append((v[ri::2, cj::2], u[ri::2, cj::2],
                           (p[_every_other(ri, nr), mid_c], p[_every_other(ri + 2, nr), mid_c],
                            p[mid_r, _every_other(cj, nc)], p[mid_r, _every_other(cj + 2, nc)]),
                           np.empty((nr, nc), dtype=values.dtype),
                           np.empty((nr, nc), dtype=values.dtype)))
        sweeps.append(blocks)
    for _ in range(iterations):
        for blocks in sweeps:
            p[0, 1:-1] = v[0]
            p[-1, 1:-1] = v[-1]
            p[1:-1, 0] = v[:, 0]
            p[1:-1, -1] = v[:, -1]
            # the same arithmetic as ((up + down + left + right) * quarter + keep * cells),
            # into buffers allocated once
            for cells, mask, (up, down, left, right), new, kept in blocks:
                np.add(up, down, out=new)
                new += left
                new += right
                new *= quarter
                np.multiply(keep, cells, out=kept)
                new += kept
                np.copyto(cells, new, where=mask)
    values[r0:r1, c0:c1] = v
    return values


def inpaint(grid, *, iterations: int = 10) -> np.ndarray:
    """Fill NaN cells of ``grid`` with a smooth (approximately harmonic) surface.

    Known cells are kept exactly. The unknown cells solve Laplace's equation
    approximately by a coarse-to-fine (multigrid-like) scheme: the grid is
    averaged into 2 x 2 blocks until everything is known, and at each finer
    level the unknown cells start from the coarser solution and are relaxed by
    Jacobi iterations. Cost is linear in the number of cells.

    Parameters
    ----------
    grid : ndarray, shape (H, W), float
    iterations : int
        Jacobi sweeps per level.

    Returns
    -------
    ndarray, shape (H, W)
        A new array without NaN (all NaN input raises); float32 input stays
        float32, anything else becomes float64.

    Raises
    ------
    InputError
        If every cell is NaN.

    References
    ----------
    D'Errico, J. (2004). inpaint_nans (the "springs"/Laplacian method used by
    Pingel et al. 2013 for SMRF).
    """
    grid = np.asarray(grid)
    if grid.dtype not in (np.float32, np.float64):
        grid = grid.astype(np.float64)
    known = np.isfinite(grid)
    if known.all():
        return grid.copy()
    if not known.any():
        raise InputError("cannot inpaint a grid without any known cell")
    return _inpaint(grid, known, iterations)


def _upsample2(coarse, h, w):
    """Bilinear upsampling of a grid of 2 x 2 blocks back to (h, w) cells."""
    ch, cw = coarse.shape

    def axis(n, m):
        f = np.clip((np.arange(n) - 0.5) / 2.0, 0.0, m - 1)
        i0 = np.minimum(f.astype(np.int64), max(m - 2, 0))
        return i0, np.minimum(i0 + 1, m - 1), (f - i0).astype(coarse.dtype)

    r0, r1, ty = axis(h, ch)
    c0, c1, tx = axis(w, cw)
    top = coarse[r0]
    bottom = coarse[r1]
    rows = top + (bottom - top) * ty[:, None]
    return rows[:, c0] + (rows[:, c1] - rows[:, c0]) * tx[None, :]


def _inpaint(grid, known, iterations):
    h, w = grid.shape
    out = np.where(known, grid, 0.0)
    if known.all():
        return out
    if h <= 2 and w <= 2:
        out[~known] = grid[known].mean()
        return out
    # 2 x 2 block means of the known cells
    hp, wp = h + (h % 2), w + (w % 2)
    vals = np.zeros((hp, wp), dtype=out.dtype)
    cnt = np.zeros((hp, wp), dtype=out.dtype)
    vals[:h, :w] = out
    cnt[:h, :w] = known
    vs = vals.reshape(hp // 2, 2, wp // 2, 2).sum(axis=(1, 3))
    cs = cnt.reshape(hp // 2, 2, wp // 2, 2).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        coarse = np.where(cs > 0, vs / np.maximum(cs, 1), np.nan)
    coarse_filled = _inpaint(coarse, cs > 0, iterations)
    up = _upsample2(coarse_filled, h, w)
    unknown = ~known
    out[unknown] = up[unknown]
    return _relax(out, unknown, iterations)


def running_extreme(a, size: int, axis: int, *, maximum: bool = False) -> np.ndarray:
    """Centred running minimum (or maximum) of odd width ``size`` along ``axis``.

    Out-of-grid samples are ignored (padding with +inf / -inf). The van Herk /
    Gil-Werman algorithm: three passes whatever the width.

    References
    ----------
    van Herk, M. (1992). A fast algorithm for local minimum and maximum filters
    on rectangular and octagonal kernels. Pattern Recognition Letters 13, 517-521.
    """
    if size < 1 or size % 2 == 0:
        raise InputError(f"size must be a positive odd integer, got {size!r}")
    a = np.asarray(a)
    if size == 1:
        return a.copy()
    a = np.moveaxis(a, axis, -1)
    n = a.shape[-1]
    half = size // 2
    fill = -np.inf if maximum else np.inf
    acc = np.maximum.accumulate if maximum else np.minimum.accumulate
    op = np.maximum if maximum else np.minimum
    nblocks = -(-(n + 2 * half) // size)
    total = nblocks * size
    padded = np.full(a.shape[:-1] + (total,), fill, dtype=a.dtype)
    padded[..., half:half + n] = a
    blocks = padded.reshape(a.shape[:-1] + (nblocks, size))
    g = acc(blocks, axis=-1).reshape(padded.shape)
    hh = acc(blocks[..., ::-1], axis=-1)[..., ::-1].reshape(padded.shape)
    # window [i, i + size - 1] of the padded signal = output i
    out = op(hh[..., :n], g[..., size - 1:size - 1 + n])
    return np.moveaxis(out, -1, axis)


def erode_square(a, size: int) -> np.ndarray:
    """Grey erosion with a ``size`` x ``size`` square (odd size)."""
    return running_extreme(running_extreme(a, size, 0), size, 1)


def dilate_square(a, size: int) -> np.ndarray:
    """Grey dilation with a ``size`` x ``size`` square (odd size)."""
    return running_extreme(running_extreme(a, size, 0, maximum=True), size, 1, maximum=True)


def open_square(a, size: int) -> np.ndarray:
    """Grey opening (erosion then dilation) with a square window."""
    return dilate_square(erode_square(a, size), size)


def _triple(a, axis, op):
    """Extreme of each cell and its two neighbours along ``axis`` (edges: the two present)."""
    a = np.moveaxis(a, axis, 0)
    out = np.empty_like(a)
    if a.shape[0] == 1:
        out[...] = a
        return np.moveaxis(out, 0, axis)
    pair = op(a[:-1], a[1:])
    op(pair[:-1], pair[1:], out=out[1:-1])
    out[0] = pair[0]
    out[-1] = pair[-1]
    return np.moveaxis(out, 0, axis)


def _unit_step(a, square: bool, maximum: bool) -> np.ndarray:
    """One 3 x 3 square or cross (4-neighbour) erosion / dilation step."""
    op = np.maximum if maximum else np.minimum
    b = _triple(a, 0, op)
    if square:
        return _triple(b, 1, op)
    op(b[:, 1:], a[:, :-1], out=b[:, 1:])
    op(b[:, :-1], a[:, 1:], out=b[:, :-1])
    return b


#: fraction of 3 x 3 square steps in an octagon approximating a disk: an octagon
#: diamond(k) + square(m) with m / (k + m) = sqrt(2) - 1 has equal axial and
#: diagonal Euclidean radii.
_SQUARE_FRACTION = np.sqrt(2.0) - 1.0


def _is_square_step(i: int) -> bool:
    """Whether unit step ``i`` (1-based) of a disk chain is a square (else a cross)."""
    return int(np.floor(i * _SQUARE_FRACTION + 0.5)) > int(np.floor((i - 1) * _SQUARE_FRACTION + 0.5))


def _disk_chain(a, radius: int, maximum: bool) -> np.ndarray:
    """``radius`` unit steps (square or cross, :func:`_is_square_step`) from ``a``: a new
    array (``a`` itself when ``radius`` is 0)."""
    if radius < 1:
        return a
    if a.ndim != 2 or min(a.shape) < 2:
        for i in range(1, radius + 1):
            a = _unit_step(a, _is_square_step(i), maximum)
        return a
    # the steps of _unit_step, into buffers allocated once for the chain (same values)
    op = np.maximum if maximum else np.minimum
    h, w = a.shape
    bufs = (np.empty_like(a), np.empty_like(a))
    tmp = np.empty_like(a)
    down = np.empty((h - 1, w), dtype=a.dtype)
    across = np.empty((h, w - 1), dtype=a.dtype)

    def triple0(src, out):
        op(src[:-1], src[1:], out=down)
        op(down[:-1], down[1:], out=out[1:-1])
        out[0] = down[0]
        out[-1] = down[-1]

    def triple1(src, out):
        op(src[:, :-1], src[:, 1:], out=across)
        op(across[:, :-1], across[:, 1:], out=out[:, 1:-1])
        out[:, 0] = across[:, 0]
        out[:, -1] = across[:, -1]

    src = a
    for i in range(1, radius + 1):
        out = bufs[i % 2]
        if _is_square_step(i):
            triple0(src, tmp)
            triple1(tmp, out)
        else:
            triple0(src, out)
            op(out[:, 1:], src[:, :-1], out=out[:, 1:])
            op(out[:, :-1], src[:, 1:], out=out[:, :-1])
        src = out
    return src


def open_disk(a, radius: int) -> np.ndarray:
    """Grey opening with an octagonal approximation of a disk of ``radius`` cells.

    The octagon is a chain of 3 x 3 square and cross steps (axial radius =
    ``radius``, diagonal radius within 3 %), so the cost is linear in the
    radius and the family is additive: erosion by radius r+1 = one step on
    erosion by radius r.
    """
    if radius < 1:
        return np.array(a, copy=True)
    return _disk_chain(_disk_chain(a, radius, False), radius, True)


#: grids of at least this many cells have their independent passes run on threads
#: (:func:`thread_map`); smaller ones cost less than starting the threads
THREADED_CELLS = 50_000


def _thread_count() -> int:
    """Threads for :func:`thread_map`: the cores this process may use that other processes
    leave idle (by the 1-minute load average, this process counted in it), at least 1 and
    at most 4.

    On a busy machine (more runnable processes than cores: other jobs, or the workers of
    a ``--workers`` run) the passes stay on one thread: two threads of one process then
    wait on each other and on the interpreter lock, and took more time, not less. The
    environment variable ``LIDAR2CITY_THREADS`` (an integer >= 1) sets the count instead
    (e.g. to compare one thread with two on a quiet machine).
    """
    forced = os.environ.get("LIDAR2CITY_THREADS", "").strip()
    if forced.isdigit() and int(forced) >= 1:
        return int(forced)
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    try:
        idle = cores - os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average: use the cores
        idle = cores
    return max(1, min(cores, 4, 1 + int(idle + 0.5)))


def thread_map(fn, items, *, cells: int = THREADED_CELLS) -> list:
    """``[fn(x) for x in items]``, on threads when the grids are large (``cells`` at least
    :data:`THREADED_CELLS`) and the process may use more than one core.

    For independent passes over grids (an inpainting, an opening, a sampling):
    numpy releases the GIL in its array loops, so they overlap; each result is
    the same as computed alone, whatever the scheduling (same bytes).
    """
    items = list(items)
    n = min(_thread_count(), len(items))
    if n <= 1 or cells < THREADED_CELLS:
        return [fn(x) for x in items]
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(n) as pool:
        return list(pool.map(fn, items))


def open_disk_series(a, radii):
    """Openings of ``a`` by disks of increasing ``radii``, reusing the erosions.

    Yields ``(radius, opened)``. Erosion by a radius-r octagon is the erosion by
    the previous radius followed by the missing unit steps (Minkowski
    additivity of the octagon family), so only the dilations cost O(r). On a
    large grid the dilations (independent of each other) run on threads, a
    few radii ahead of the one yielded (:func:`thread_map`).
    """
    eroded = np.asarray(a)
    n = _thread_count()
    if n > 1 and eroded.size >= THREADED_CELLS:
        yield from _open_disk_series_threaded(eroded, radii, n)
        return
    done = 0
    for radius in radii:
        radius = int(radius)
        for i in range(done + 1, radius + 1):
            eroded = _unit_step(eroded, _is_square_step(i), False)
        done = max(done, radius)
        yield radius, _disk_chain(eroded, radius, True)


def _open_disk_series_threaded(eroded, radii, threads, ahead: int = 2):
    """:func:`open_disk_series` with each dilation a task of a pool of ``threads``; at most
    ``ahead`` tasks per thread wait beyond the one yielded (memory: a few grids)."""
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    pending = deque()
    done = 0
    with ThreadPoolExecutor(threads) as pool:
        for radius in radii:
            radius = int(radius)
            for i in range(done + 1, radius + 1):
                eroded = _unit_step(eroded, _is_square_step(i), False)
            done = max(done, radius)
            pending.append((radius, pool.submit(_disk_chain, eroded, radius, True)))
            while len(pending) > ahead * threads:
                r, opened = pending.popleft()
                yield r, opened.result()
        while pending:
            r, opened = pending.popleft()
            yield r, opened.result()


def bilinear_weights(spec: GridSpec, xy):
    """Flat indices and weights (each four arrays (N,), corners in the order 00, 01, 10, 11)
    of bilinear interpolation at ``xy`` (N, 2).

    Values live at cell centres; points beyond the outer centres are clamped.
    Reuse the result to sample several grids of the same ``spec``.
    """
    xy = np.asarray(xy, dtype=np.float64)
    h, w = spec.shape
    fx = (xy[:, 0] - spec.x0) * (1.0 / spec.cell) - 0.5
    fy = (spec.y_top - xy[:, 1]) * (1.0 / spec.cell) - 0.5
    np.clip(fx, 0.0, w - 1, out=fx)
    np.clip(fy, 0.0, h - 1, out=fy)
    c0 = np.minimum(fx.astype(np.int64), max(w - 2, 0))
    r0 = np.minimum(fy.astype(np.int64), max(h - 2, 0))
    tx = fx - c0
    ty = fy - r0
    dc = 1 if w > 1 else 0
    dr = w if h > 1 else 0
    i00 = r0 * w + c0
    # tuples, not stacked (4, N) arrays: the copy cost more than the sampling
    i10 = i00 + dr
    sx, sy = 1 - tx, 1 - ty
    index = (i00, i00 + dc, i10, i10 + dc)
    weights = (sx * sy, tx * sy, sx * ty, tx * ty)
    return index, weights


def sample_bilinear(grid, spec: GridSpec, xy=None, *, weights=None) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (values at cell centres) at points ``xy`` (N, 2).

    Points beyond the outer cell centres take the edge values (clamped).
    ``weights`` from :func:`bilinear_weights` may be given instead of ``xy``.
    """
    index, wts = weights if weights is not None else bilinear_weights(spec, xy)
    g = np.asarray(grid, dtype=np.float64).ravel()
    out = g[index[0]] * wts[0]
    for k in (1, 2, 3):
        out += g[index[k]] * wts[k]
    return out


def gradient_magnitude(grid, cell: float) -> np.ndarray:
    """Slope (rise over run, dimensionless) of a grid by central differences."""
    g = np.asarray(grid, dtype=np.float64)
    if min(g.shape) < 2:
        return np.zeros_like(g)
    gy, gx = np.gradient(g, cell)
    return np.hypot(gx, gy)
