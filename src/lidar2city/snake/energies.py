"""Candidate states and energies of the building-topology snake (Yan et al. 2015, eqs. 4–6).

Everything here works in the *building frame* (rotated so that the dominant
direction is the x axis, see :mod:`lidar2city.regularize.direction`) and in
*grid units*: coordinates divided by the cell size, so that free vertices sit
on integer grid positions and an edge is exactly horizontal / vertical when
its two endpoints share a grid row / column.

Energies, per edge ``(u, v)`` and candidate positions ``p_i`` of ``u`` and
``q_j`` of ``v`` (all ``d_u x d_v`` pairs at once):

``E_Dir`` (eq. 4)
    With ``dx = |q_j - p_i|_x`` and ``dy = |q_j - p_i|_y`` (metres) and
    ``m = min(dx, dy)``: the edge is *aligned* when ``m == 0`` (energy 0);
    *oblique* when ``m > T`` (it stays oblique: energy 0); otherwise it is
    *adjustable but not adjusted* and pays its length ``hypot(dx, dy)`` in
    metres. So an edge within ``T`` of an axis is pulled onto it, and a wall
    clearly oblique to the building axes is left as it is.

``E_Dis`` (eq. 5)
    The chessboard distance transform (``scipy.ndimage.distance_transform_cdt``)
    of the rasterised original topology, summed along the candidate edge:
    the segment is sampled every raster cell, each sample reads the
    distance of its raster cell, and the sum is weighted by the sample
    spacing, giving ``integral of distance ds`` in square metres — the paper's
    sum over the cells of the rasterised edge, times the cell area, made
    independent of how the edge crosses the grid. The raster may be finer
    than the candidate grid (``subdivide``), see :func:`distance_raster`.

``E_Short`` (not in the paper, optional)
    A constant for every candidate edge shorter than a length, but not of
    length zero: removes the small jogs noise leaves (see
    :func:`short_edge_energy`).

``E`` (eq. 6)
    ``C_Dir * E_Dir + C_Dis * E_Dis (+ C_Short * E_Short)``. With the
    defaults of :mod:`lidar2city.regularize.snake` (``T = 2 cell``,
    ``C_Dis = 1``, ``C_Dir = T`` metres, ``C_Short = 2 cell**2`` below
    ``2 cell``) aligning an adjustable edge of length ``L`` costs at most
    about ``L * T / 4`` of deviation and saves ``L * T``, so adjustable edges
    are aligned whenever the window lets them; and turning a jog into a
    longer slanted edge to escape ``E_Short`` costs at least
    ``C_Dir * 2 cell = C_Short``, so it does not pay.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import ndimage

from ..errors import InputError

#: Largest distance raster (cells) before ``subdivide`` is reduced.
_RASTER_BUDGET = 8_000_000
#: Largest number of samples (candidate pairs x points) read at once.
_SAMPLE_BUDGET = 1_000_000
# edges whose direction / jog tables are computed in one array operation
_EDGE_BATCH = 64
#: Samples (candidate pairs x points) of the edges sampled together on a shared window.
_CHUNK = 1 << 18

__all__ = [
    "window_offsets",
    "candidate_positions",
    "DistanceRaster",
    "distance_raster",
    "direction_energy",
    "deviation_energy",
    "short_edge_energy",
    "edge_energy_tables",
    "vertex_energy_tables",
]


def window_offsets(window: int) -> np.ndarray:
    """Grid offsets of a ``(2w+1) x (2w+1)`` window, the centre first.

    Returns
    -------
    ndarray of int, shape ((2w+1)**2, 2)
    """
    if int(window) != window or window < 0:
        raise InputError(f"window must be a non-negative integer, got {window}")
    w = int(window)
    r = np.arange(-w, w + 1)
    off = np.stack(np.meshgrid(r, r, indexing="ij"), axis=-1).reshape(-1, 2)
    order = np.argsort(np.abs(off).max(axis=1) * 1000 + np.abs(off).sum(axis=1), kind="stable")
    return off[order]


def candidate_positions(grid_xy, window: int, *, fixed=None) -> list[np.ndarray]:
    """Candidate positions (grid units) of every vertex.

    Parameters
    ----------
    grid_xy : array, shape (n, 2)
        Vertex positions in grid units (free vertices are rounded to the grid).
    window : int
        Half-width ``w`` of the window: ``(2w+1)**2`` candidates per free vertex.
    fixed : array of bool, shape (n,), optional
        Vertices that must not move: one candidate, their exact position.

    Returns
    -------
    list of ndarray, each shape (d_v, 2)
        Candidate 0 is the vertex's own (snapped) position.
    """
    g = np.asarray(grid_xy, dtype=np.float64)
    if g.ndim != 2 or g.shape[1] != 2:
        raise InputError(f"grid_xy must have shape (n, 2), got {g.shape}")
    fixed = np.zeros(len(g), dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
    if fixed.shape != (len(g),):
        raise InputError(f"fixed must have shape ({len(g)},), got {fixed.shape}")
    off = window_offsets(window).astype(np.float64)
    snapped = np.round(g)
    return [g[i : i + 1].copy() if fixed[i] else snapped[i] + off for i in range(len(g))]


def _sample(p0, p1, step):
    """Points every <= ``step`` along segments p0 -> p1 (broadcast), and the spacing."""
    d = p1 - p0
    length = np.hypot(d[..., 0], d[..., 1])
    n = max(int(np.ceil(float(length.max(initial=0.0)) / step)), 1) + 1
    t = np.linspace(0.0, 1.0, n)
    pts = p0[..., None, :] + t[:, None] * d[..., None, :]
    return pts, length, n


class DistanceRaster(NamedTuple):
    """Chessboard distance transform of the rasterised original topology."""

    dt: np.ndarray  #: distance in raster cells, shape (H, W)
    origin: np.ndarray  #: raster index (int, shape (2,)) of ``dt[0, 0]``
    scale: int  #: raster cells per grid unit


def distance_raster(segments_grid, *, margin: int, subdivide: int = 4) -> DistanceRaster:
    """Chessboard distance to the rasterised original topology.

    Parameters
    ----------
    segments_grid : array, shape (m, 2, 2)
        Original edges in grid units.
    margin : int
        Grid units added around the segments' bounding box (at least the window).
    subdivide : int
        Raster cells per grid unit. The paper rasterises at the grid itself
        (1); a finer raster (default 4) keeps a noisy traced outline from
        filling a band of whole cells where every candidate reads distance 0,
        so the deviation energy still prefers the middle of the noise.
        Halved (down to 1) while the raster would exceed 8e6 cells.

    Returns
    -------
    DistanceRaster
        ``dt[i, j]``: chessboard distance (raster cells) of raster cell
        ``origin + (i, j)`` to the nearest cell crossed by an original edge.
    """
    seg = np.asarray(segments_grid, dtype=np.float64)
    if seg.ndim != 3 or seg.shape[1:] != (2, 2) or len(seg) == 0:
        raise InputError(f"segments_grid must have shape (m, 2, 2) with m > 0, got {seg.shape}")
    if int(subdivide) != subdivide or subdivide < 1:
        raise InputError(f"subdivide must be a positive integer, got {subdivide}")
    extent = np.ptp(seg.reshape(-1, 2), axis=0) + 2 * margin + 1
    scale = int(subdivide)
    while scale > 1 and float(np.prod(extent * scale)) > _RASTER_BUDGET:
        scale //= 2  # very large outlines: a coarser raster, bounded memory
    seg = seg * scale
    margin = int(margin) * scale
    step = 0.25
    lo = np.floor(seg.reshape(-1, 2).min(axis=0)).astype(np.int64) - margin
    hi = np.ceil(seg.reshape(-1, 2).max(axis=0)).astype(np.int64) + margin
    shape = tuple((hi - lo + 1).tolist())
    mask = np.zeros(shape, dtype=bool)
    # Each segment gets its own number of samples (long and short edges mixed).
    d = seg[:, 1] - seg[:, 0]
    counts = np.ceil(np.hypot(d[:, 0], d[:, 1]) / step).astype(np.int64) + 1
    which = np.repeat(np.arange(len(seg)), counts)
    first = np.cumsum(counts) - counts
    t = (np.arange(counts.sum()) - first[which]) / np.maximum(counts[which] - 1, 1)
    pts = seg[which, 0] + t[:, None] * d[which]
    ij = np.round(pts).astype(np.int64) - lo
    mask[ij[:, 0], ij[:, 1]] = True
    dt = ndimage.distance_transform_cdt(~mask, metric="chessboard").astype(np.int32)
    return DistanceRaster(dt, lo, scale)


def direction_energy(p_u, p_v, *, cell: float, t_adjust: float) -> np.ndarray:
    """E_Dir of every candidate pair (eq. 4), see the module docstring.

    Parameters
    ----------
    p_u, p_v : ndarray, shapes (..., d_u, 2), (..., d_v, 2)
        Candidate positions (grid units, building frame); leading dimensions
        (e.g. one per edge) broadcast.
    cell : float
        Cell size (m).
    t_adjust : float
        Threshold ``T`` (m) on the smaller extent below which an edge is
        adjustable.

    Returns
    -------
    ndarray, shape (..., d_u, d_v)
        Penalty in metres (the edge length) or 0.
    """
    return _direction(*_pair_extents(p_u, p_v, cell), cell=cell, t_adjust=t_adjust)


def _pair_extents(p_u, p_v, cell):
    """x and y extents (m) and length of every candidate pair."""
    d = (np.asarray(p_v)[..., None, :, :] - np.asarray(p_u)[..., :, None, :]) * cell
    return d[..., 0], d[..., 1], np.hypot(d[..., 0], d[..., 1])


def _direction(dx, dy, length, *, cell, t_adjust):
    m = np.minimum(np.abs(dx), np.abs(dy))  # the smaller extent
    aligned = m <= 1e-9 * cell
    adjustable = m <= t_adjust
    return np.where(adjustable & ~aligned, length, 0.0)


def _short(length, *, cell, short_length):
    return ((length > 1e-9 * cell) & (length < short_length)).astype(np.float64)


def short_edge_energy(p_u, p_v, *, cell: float, short_length: float) -> np.ndarray:
    """1 for a candidate edge of length in ``(0, short_length)`` metres, else 0.

    Not in the paper: a small jog left by noise costs this constant, so the
    snake prefers to collapse it (both ends on one position, the edge then
    vanishes) unless the data hold it with more deviation energy than that
    — a long wall offset by a real step does.
    """
    return _short(_pair_extents(p_u, p_v, cell)[2], cell=cell, short_length=short_length)


class _Ends(NamedTuple):
    """Candidate positions of one vertex in raster coordinates, with their distinct
    x (and y) values and the index of each position's x (y) among them."""

    q: np.ndarray
    ux: np.ndarray
    ix: np.ndarray
    uy: np.ndarray
    iy: np.ndarray


def _ends(p, raster: DistanceRaster) -> _Ends:
    q = np.asarray(p, dtype=np.float64) * raster.scale - raster.origin  # raster coordinates
    ux, ix = np.unique(q[:, 0], return_inverse=True)
    uy, iy = np.unique(q[:, 1], return_inverse=True)
    return _Ends(q, ux, ix.ravel(), uy, iy.ravel())


def _axis_cells(u0, u1, i0, i1, t, size, stride=1):
    """``floor(a0 + 0.5 + t (a1 - a0))`` clipped to ``[0, size)``, times ``stride``,
    shape (d_u, d_v, len(t)).

    Computed once per pair of distinct values ``u0 x u1`` and looked up by the
    indices ``i0``, ``i1`` of every candidate's value among them.
    """
    d = u1[None, :] - u0[:, None]
    c = np.floor(u0[:, None, None] + 0.5 + t * d[..., None]).astype(np.intp)
    np.clip(c, 0, size - 1, out=c)
    c *= stride
    return np.take(c.reshape(-1, len(t)), i0[:, None] * len(u1) + i1[None, :], axis=0)


def _trapezoid_weights(n: int) -> np.ndarray:
    """Weights 1, 2, ..., 2, 1 of the trapezoid rule over ``n`` samples, times ``2 (n - 1)``."""
    w = np.full(n, 2.0)
    w[[0, -1]] = 1.0
    return w


def _trapezoid(dist, n: int):
    """Mean of the samples ``dist`` (..., n) by the trapezoid rule (unit interval).

    The samples are whole raster distances: their weighted sum with the integer
    weights of :func:`_trapezoid_weights` is an exact integer in any order of
    addition (BLAS kernel, blocking, which rows are summed together), and is
    rounded once, by the division. So a pair's value does not depend on how many
    pairs are summed with it, nor on the machine's BLAS kernels.
    """
    return (dist @ _trapezoid_weights(n)) / (2 * (n - 1))


def deviation_energy(p_u, p_v, raster: DistanceRaster, *, cell: float, step: float = 1.0) -> np.ndarray:
    """E_Dis of every candidate pair (eq. 5), in square metres.

    Parameters
    ----------
    p_u, p_v : ndarray, shapes (d_u, 2), (d_v, 2)
        Candidate positions (grid units).
    raster : DistanceRaster
        From :func:`distance_raster`; samples outside it read its border
        (make its margin cover the candidate windows).
    cell : float
        Cell size (m).
    step : float
        Sampling step along the edge (raster cells).

    Returns
    -------
    ndarray, shape (d_u, d_v)
    """
    return _deviation(p_u, p_v, _ends(p_u, raster), _ends(p_v, raster), raster, cell=cell, step=step)


def _deviation(p_u, p_v, e0: _Ends, e1: _Ends, raster: DistanceRaster, *, cell, step=1.0):
    """:func:`deviation_energy` with the candidates' :func:`_ends` given."""
    dt, origin, scale = raster
    p0, p1 = e0.q, e1.q
    d = p1[None, :, :] - p0[:, None, :]  # (d_u, d_v, 2)
    length = np.hypot(d[..., 0], d[..., 1])
    n = max(int(np.ceil(float(length.max(initial=0.0)) / step)), 1) + 1
    rows = max(1, _SAMPLE_BUDGET // (n * len(p1)))
    if rows < len(p0):  # long edges: bound memory by chunks of candidates of u
        return np.concatenate([
            deviation_energy(p_u[i : i + rows], p_v, raster, cell=cell, step=step)
            for i in range(0, len(p0), rows)
        ])
    t = np.linspace(0.0, 1.0, n)
    h, w = dt.shape
    # Nearest raster cell of every sample: floor(x + 0.5), clipped to the raster. A
    # sample's row depends only on the x of its two ends (its column on their y), so
    # it is computed once per pair of distinct x (a 7 x 7 window has 7 distinct x per
    # vertex: 49 rows of samples, not 49 x 49) and looked up: the same double
    # arithmetic per sample as sampling every pair, a third of the passes.
    ix = _axis_cells(e0.ux, e1.ux, e0.ix, e1.ix, t, h, stride=w)
    ix += _axis_cells(e0.uy, e1.uy, e0.iy, e1.iy, t, w)
    dist = np.take(dt.ravel(), ix)  # (d_u, d_v, n), raster cells
    # Trapezoid rule along the segment: integral of distance ds.
    return _trapezoid(dist, n) * length * (cell / scale) ** 2


def edge_energy_tables(
    candidates,
    edges,
    raster: DistanceRaster,
    *,
    cell: float,
    t_adjust: float,
    c_dir,
    c_dis: float,
    c_short: float = 0.0,
    short_length: float = 0.0,
    step: float = 1.0,
    bound: bool = False,
):
    """``C_Dir E_Dir + C_Dis E_Dis`` (eq. 6) for every edge: the solver's edge tables.

    Parameters
    ----------
    candidates : list of ndarray (d_v, 2)
        From :func:`candidate_positions`.
    edges : array of int, shape (m, 2)
    raster : DistanceRaster
        From :func:`distance_raster`.
    cell, t_adjust, c_dis : float
        Cell size (m), adjustability threshold ``T`` (m), deviation weight.
    c_dir : float or array of float, shape (m,)
        Direction weight, one for all edges or one per edge (0 switches the
        direction energy off for an edge, e.g. the hip edges of a roof).
    c_short, short_length : float
        Weight (m^2) and length (m) of :func:`short_edge_energy` (0 = off).
    step : float
        Spacing (raster cells) of the deviation's samples along a candidate edge
        (:func:`deviation_energy`); 1 reads every raster cell the edge crosses.
    bound : bool
        Also return which entries are lower bounds: where the direction energy
        of a pair is positive (an adjustable edge left off the axes, weight > 0),
        its deviation is not sampled and counts 0 (``E_Dis >= 0``), so the entry
        is ``C_Dir E_Dir (+ C_Short E_Short)``, at most the true energy. Every other
        entry is the same double as without ``bound``. A minimum of these tables
        that uses no bounded entry is a minimum of the true energy (every
        labelling's energy can only have been lowered, and its own is exact): see
        :func:`lidar2city.regularize.snake.adjust_planar_graph`, which solves
        again with the true tables of the edges whose bounded entry the minimum
        used. Only for candidates on one shared window (no fixed vertex): the
        masks are all False otherwise.

    Returns
    -------
    list of ndarray, shape (d_u, d_v) each
        The tables; with ``bound``, a pair ``(tables, bounded)``, ``bounded`` a
        list of bool arrays of the same shapes (True: the entry is a lower bound).
    """
    if not (np.isfinite(step) and step > 0):
        raise InputError(f"step must be a positive number of raster cells, got {step}")
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    kwargs = dict(cell=cell, t_adjust=t_adjust, c_dir=c_dir, c_dis=c_dis, c_short=c_short,
                  short_length=short_length, step=step)
    layout = _window_layout(candidates, raster)
    if layout is None or not len(edges):
        tables = _edge_tables_general(candidates, edges, raster, **kwargs)
        return (tables, [np.zeros(t.shape, dtype=bool) for t in tables]) if bound else tables
    return _window_edge_tables(layout, candidates, edges, raster, bound=bound, **kwargs)


def _edge_tables_general(candidates, edges, raster: DistanceRaster, *, cell, t_adjust, c_dir, c_dis,
                         c_short=0.0, short_length=0.0, step=1.0) -> list[np.ndarray]:
    """Edge tables edge by edge (any candidate sets): see :func:`edge_energy_tables`."""
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    weights = np.broadcast_to(np.asarray(c_dir, dtype=np.float64), (len(edges),))
    if raster.dt.size <= _SAMPLE_BUDGET:
        # the integer distances read as doubles once per raster, not once per sample
        # (a large raster stays int32: bounded memory, the same sums)
        raster = raster._replace(dt=raster.dt.astype(np.float64))
    # every vertex with the same number of candidates: the small energies of up to
    # _EDGE_BATCH edges in one array operation each (the same arithmetic per element)
    pos = np.stack(candidates) if len(edges) and len({len(c) for c in candidates}) == 1 else None
    ends = [_ends(c, raster) for c in candidates]  # once per vertex, not per edge end
    out = []
    for k, ((u, v), wd) in enumerate(zip(edges, weights, strict=True)):
        j = k % _EDGE_BATCH
        if pos is not None and j == 0:
            batch = edges[k:k + _EDGE_BATCH]
            dx, dy, length = _pair_extents(pos[batch[:, 0]], pos[batch[:, 1]], cell)
            dirs = _direction(dx, dy, length, cell=cell, t_adjust=t_adjust) if np.any(weights) else None
            shorts = _short(length, cell=cell, short_length=short_length) if c_short else None
        pu, pv = candidates[u], candidates[v]
        e = c_dis * _deviation(pu, pv, ends[u], ends[v], raster, cell=cell, step=step)
        if wd:
            e = e + wd * (dirs[j] if pos is not None else
                          direction_energy(pu, pv, cell=cell, t_adjust=t_adjust))
        if c_short:
            e = e + c_short * (shorts[j] if pos is not None else
                               short_edge_energy(pu, pv, cell=cell, short_length=short_length))
        out.append(e)
    return out


class _Window(NamedTuple):
    """Candidates that are the same window of integer grid offsets around every vertex.

    ``q`` are the candidates in raster coordinates (exact integers); ``ix`` / ``iy``
    the index of each candidate's x / y offset among the distinct ones ``ox`` /
    ``oy`` (ascending), and ``ux`` / ``uy`` the raster x / y of those per vertex.
    """

    pos: np.ndarray  #: (V, d, 2) grid units
    q: np.ndarray  #: (V, d, 2) raster coordinates
    ix: np.ndarray  #: (d,)
    iy: np.ndarray  #: (d,)
    ux: np.ndarray  #: (V, nx)
    uy: np.ndarray  #: (V, ny)
    ox: np.ndarray  #: (nx,) grid units
    oy: np.ndarray  #: (ny,) grid units


#: Integer coordinates below this magnitude: their sums and differences are exact doubles.
_EXACT = 2.0 ** 40


def _window_layout(candidates, raster: DistanceRaster) -> _Window | None:
    """The shared window of every vertex's candidates, or None (e.g. a fixed vertex)."""
    if not len(candidates) or len({len(c) for c in candidates}) != 1:
        return None
    pos = np.stack([np.asarray(c, dtype=np.float64) for c in candidates])
    off = pos - pos[:, :1]
    if not (np.all(off == off[:1]) and np.all(pos == np.floor(pos)) and np.abs(pos).max() < _EXACT):
        return None
    q = pos * raster.scale - raster.origin  # as _ends computes it
    if np.abs(q).max() >= _EXACT:
        return None
    ox, fx, ix = np.unique(off[0, :, 0], return_index=True, return_inverse=True)
    oy, fy, iy = np.unique(off[0, :, 1], return_index=True, return_inverse=True)
    # a vertex's candidate x (y) values are its candidate 0's plus the offsets, exactly:
    # its distinct values are in the offsets' order
    ix, iy = ix.ravel(), iy.ravel()
    if len(ox) * len(oy) != pos.shape[1] or len(np.unique(ix * len(oy) + iy)) != pos.shape[1]:
        return None  # not a whole rectangular window
    return _Window(pos, q, ix, iy, q[:, fx, 0], q[:, fy, 1], ox, oy)


def _window_edge_tables(lay: _Window, candidates, edges, raster: DistanceRaster, *, cell, t_adjust,
                        c_dir, c_dis, c_short, short_length, step=1.0, bound=False):
    """:func:`edge_energy_tables` when every vertex has the same window of grid offsets.

    The same IEEE double operations per element as edge by edge
    (:func:`_edge_tables_general`), with the work shared: a candidate pair's x
    and y extents are the edge's base extent plus a difference of two window
    offsets (exact integers), so its length, direction and jog energies are
    computed once per difference (13 x 13 for a 7 x 7 window, not 49 x 49) and
    looked up; edges with the same number of samples have their deviation
    sampled together, the candidates of ``u`` in window order, and their
    results are then put back in ``u``'s candidate order (the sums along the
    samples are exact integers, whatever is summed together: :func:`_trapezoid`).

    ``bound``: the pairs of positive direction energy (weight > 0) are not
    sampled (deviation 0, a lower bound); returns ``(tables, bounded)``.
    """
    weights = np.broadcast_to(np.asarray(c_dir, dtype=np.float64), (len(edges),))
    if raster.dt.size <= _SAMPLE_BUDGET:
        raster = raster._replace(dt=raster.dt.astype(np.float64))
    scale = raster.scale
    d = lay.pos.shape[1]
    # (offset of b - offset of a) per axis, as an index among the distinct differences
    dox, kx = np.unique(lay.ox[None, :] - lay.ox[:, None], return_inverse=True)
    doy, ky = np.unique(lay.oy[None, :] - lay.oy[:, None], return_inverse=True)
    kx, ky = kx.reshape(len(lay.ox), -1), ky.reshape(len(lay.oy), -1)
    pair = (kx[lay.ix[:, None], lay.ix[None, :]] * len(doy) + ky[lay.iy[:, None], lay.iy[None, :]]).ravel()
    use_dir = bool(np.any(weights))
    scratch = _Scratch()  # the samples' buffers, reused by every block of this call
    out, bounded = [], []
    for b0 in range(0, len(edges), _EDGE_BATCH):
        e_ = edges[b0:b0 + _EDGE_BATCH]
        u_, v_ = e_[:, 0], e_[:, 1]
        w_ = weights[b0:b0 + _EDGE_BATCH, None, None]

        def per_pair(table):  # (k, ndx, ndy) -> (k, d, d)
            return np.take(table.reshape(len(e_), -1), pair, axis=1).reshape(len(e_), d, d)

        # extents (grid units, then raster cells) of every distinct offset difference:
        # the edge's candidates 0 plus the difference, exact integers as edge by edge
        rx = (lay.q[v_, 0, 0] - lay.q[u_, 0, 0])[:, None] + dox * scale
        ry = (lay.q[v_, 0, 1] - lay.q[u_, 0, 1])[:, None] + doy * scale
        length = per_pair(np.hypot(rx[:, :, None], ry[:, None, :]))
        if use_dir or c_short:
            dx = ((lay.pos[v_, 0, 0] - lay.pos[u_, 0, 0])[:, None] + dox)[:, :, None] * cell
            dy = ((lay.pos[v_, 0, 1] - lay.pos[u_, 0, 1])[:, None] + doy)[:, None, :] * cell
            metres = np.hypot(dx, dy)
        if use_dir:
            dirs = per_pair(_direction(dx, dy, metres, cell=cell, t_adjust=t_adjust))
        # the pairs whose deviation is left at its lower bound 0 (bound=True)
        skip = (dirs > 0.0) & (w_ > 0.0) if bound and use_dir else None
        e = _window_deviation(lay, candidates, e_, raster, length, scratch, cell=cell, step=step, skip=skip)
        e *= c_dis
        if use_dir:  # an edge of weight 0 adds 0 * E_Dir = +0.0: its energies unchanged
            e += w_ * dirs
        if c_short:
            e += c_short * per_pair(_short(metres, cell=cell, short_length=short_length))
        out += list(e)
        if bound:
            bounded += list(np.zeros(e.shape, dtype=bool) if skip is None else skip)
    return (out, bounded) if bound else out


def _window_deviation(lay: _Window, candidates, edges, raster: DistanceRaster, length, scratch, *, cell, step,
                      skip=None):
    """E_Dis tables (k, d, d) of ``edges`` on a shared window, see :func:`_window_edge_tables`.

    ``skip`` (bool, (k, d, d), optional): pairs not sampled, their deviation 0; the
    others are the same doubles as with none skipped. Where all of an edge's pairs
    are sampled anyway (an edge too long for one block, or whose pairs to sample do
    not fall into a few blocks, see :class:`_PairPlan`), ``skip`` is set False.
    """
    dt, _, scale = raster
    h, w = dt.shape
    u_, v_ = edges[:, 0], edges[:, 1]
    m, d = len(edges), lay.pos.shape[1]
    nx, ny = len(lay.ox), len(lay.oy)
    n = np.maximum(np.ceil(length.reshape(m, -1).max(axis=1) / step).astype(np.int64), 1) + 1
    dev = np.empty((m, d, d))
    chunked = _SAMPLE_BUDGET // (n * d) < d  # as edge by edge: candidates of u in chunks
    for k in np.flatnonzero(chunked):
        u, v = edges[k]
        dev[k] = _deviation(candidates[u], candidates[v], _ends(candidates[u], raster),
                            _ends(candidates[v], raster), raster, cell=cell, step=step)
        if skip is not None:
            skip[k] = False
    grid = lay.ix * ny + lay.iy  # each candidate's cell in the window, x major
    plan = _PairPlan(lay) if skip is not None and skip.any() else None
    order = np.flatnonzero(~chunked)
    order = order[np.argsort(n[order], kind="stable")]
    for group in np.split(order, np.flatnonzero(np.diff(n[order])) + 1):
        if not len(group):
            continue
        ns = int(n[group[0]])
        t = np.linspace(0.0, 1.0, ns)
        wts = _trapezoid_weights(ns)
        per = max(1, _CHUNK // (d * d * ns))
        for s in range(0, len(group), per):
            ks = group[s:s + per]
            # raster row (column) of every sample, per x (y) of u's candidate and of v's
            rx = _axis_cells_batch(lay.ux[u_[ks]], lay.ux[v_[ks]], t, h, stride=w)
            cy = _axis_cells_batch(lay.uy[u_[ks]], lay.uy[v_[ks]], t, w)
            sums = np.empty((len(ks), nx, ny, d))
            # the samples of a few of u's candidate x at a time: bounded buffers
            step_x = max(1, _CHUNK // (len(ks) * ny * d * ns))
            wanted = None if plan is None or step_x < nx else plan.wanted(skip[ks])
            if wanted is None or all(x is None for x in wanted):
                if skip is not None:
                    skip[ks] = False
                # every pair's flat index: u's candidates in window order, v's in their own
                rows, cols = np.take(rx, lay.ix, axis=2), np.take(cy, lay.iy, axis=2)
                for i in range(0, nx, step_x):
                    part = rows[:, i:i + step_x]
                    shape = (len(ks), part.shape[1], ny, d, ns)
                    idx = np.add(part[:, :, None], cols[:, None, :], out=scratch("idx", shape, np.intp))
                    # every index is inside the raster: 'wrap' is the plain look-up, unbuffered
                    dist = np.take(dt.ravel(), idx, out=scratch("dist", shape, dt.dtype), mode="wrap")
                    np.matmul(dist, wts, out=sums[:, i:i + step_x])
                sums /= 2 * (ns - 1)
            else:
                # only the wanted pairs' samples are looked up and summed (the sums are
                # exact integers, whatever pairs are summed together: see _trapezoid)
                sums[:] = 0.0
                whole = np.array([x is None for x in wanted])
                if whole.any():
                    skip[ks[whole]] = False
                    rows, cols = np.take(rx[whole], lay.ix, axis=2), np.take(cy[whole], lay.iy, axis=2)
                    idx = rows[:, :, None] + cols[:, None, :]
                    sums[whole] = np.take(dt.ravel(), idx, mode="wrap") @ wts
                for kk, x in enumerate(wanted):
                    if x is not None:
                        plan.sample(sums[kk].reshape(-1), rx[kk], cy[kk], x, dt, wts)
                sums /= 2 * (ns - 1)
            dev[ks] = sums.reshape(len(ks), nx * ny, d)[:, grid] * length[ks] * (cell / scale) ** 2
    if skip is not None:
        dev[skip] = 0.0
    return dev


class _PairPlan:
    """The candidate pairs of an edge on a shared window by x pair and y pair.

    A pair of candidates ``(i, j)`` of an edge's ends is an x pair ``p = a nx + a2``
    (the window x indices of ``i`` and ``j``) and a y pair ``q = b ny + b2``; its
    samples' raster rows depend on ``p`` only and their columns on ``q`` only. The
    pairs to sample are split into blocks "these x pairs with those y pairs" (the x
    pairs wanting the same y pairs together, or the converse, whichever makes fewer
    blocks: an edge near an axis whose pairs off the axis are not sampled makes one
    or a few), and each block's indices are one broadcast sum, with no per-pair gather.
    """

    def __init__(self, lay: _Window):
        nx, ny, d = len(lay.ox), len(lay.oy), lay.pos.shape[1]
        inv = np.argsort(lay.ix * ny + lay.iy)  # the candidate at each window cell
        a, a2 = np.divmod(np.arange(nx * nx), nx)
        b, b2 = np.divmod(np.arange(ny * ny), ny)
        cell_u = a[:, None] * ny + b[None, :]
        v = inv[a2[:, None] * ny + b2[None, :]]
        self.pair = inv[cell_u] * d + v  # (P, Q): the pair's flat index in (d, d)
        self.row = cell_u * d + v  # (P, Q): its row among the (nx, ny, d) sums

    def wanted(self, skip):
        """Blocks ``[(p, q), ...]`` (x pairs, y pairs) holding exactly the pairs not
        skipped of each edge (``skip``: (k, d, d)), or None for an edge of no such
        form or none skipped (all its pairs are sampled)."""
        keep = ~skip.reshape(len(skip), -1)[:, self.pair]  # (k, P, Q)
        rows, cols = keep.all(axis=2), keep.all(axis=1)  # x pairs (y pairs) wanting all
        rest = keep & ~rows[:, :, None] & ~cols[:, None, :]
        rr, cc = rest.any(axis=2), rest.any(axis=1)
        # the rest a rectangle: as from an edge's aligned pairs (its x or y extent 0)
        # and its oblique ones (both extents over T)
        fits = ~keep.all(axis=(1, 2)) & (rest == (rr[:, :, None] & cc[:, None, :])).all(axis=(1, 2))
        out = []
        every_q = np.arange(keep.shape[2])
        for k in range(len(keep)):
            if not fits[k]:
                out.append(None)
                continue
            p0 = np.flatnonzero(rows[k])
            blocks = [(p0, every_q)] if len(p0) else []
            if (rr[k] == ~rows[k]).all():  # the rest's x pairs are all the others: one block
                blocks.append((np.flatnonzero(rr[k]), np.flatnonzero(cols[k] | cc[k])))
            else:
                if cols[k].any():
                    blocks.append((np.flatnonzero(~rows[k]), np.flatnonzero(cols[k])))
                if rr[k].any():
                    blocks.append((np.flatnonzero(rr[k]), np.flatnonzero(cc[k])))
            out.append(blocks)
        return out

    def sample(self, out, rx, cy, blocks, dt, wts):
        """The blocks' pairs' weighted sums of samples (``wts``), into their places
        in ``out`` (nx ny d: u's window cell, v's candidate)."""
        ns = len(wts)
        rx, cy = rx.reshape(-1, ns), cy.reshape(-1, ns)
        for p, q in blocks:
            every_p, every_q = len(p) == len(rx), len(q) == len(cy)  # (no gather of all rows)
            idx = np.add((rx if every_p else rx[p])[:, None, :], (cy if every_q else cy[q])[None, :, :])
            rows = self.row if every_p else self.row[p]
            out[rows if every_q else rows[:, q]] = np.take(dt.ravel(), idx, mode="wrap") @ wts


class _Scratch:
    """Buffers reused from chunk to chunk of one call: fresh pages for every few
    edges' samples cost the kernel more time than the look-ups. Dropped with the
    call, so nothing stays allocated between snakes."""

    def __init__(self):
        self.bufs: dict[str, np.ndarray] = {}

    def __call__(self, name: str, shape: tuple, dtype) -> np.ndarray:
        size = int(np.prod(shape))
        buf = self.bufs.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = self.bufs[name] = np.empty(size, dtype=dtype)
        return buf[:size].reshape(shape)


def _axis_cells_batch(u0, u1, t, size, stride=1):
    """:func:`_axis_cells` of several edges (rows of ``u0``, ``u1``) before the look-up:
    shape (k, len(u0[0]), len(u1[0]), len(t)), one row per pair of distinct values."""
    d = u1[:, None, :] - u0[:, :, None]
    c = np.floor(u0[:, :, None, None] + 0.5 + t * d[..., None]).astype(np.intp)
    np.clip(c, 0, size - 1, out=c)
    c *= stride
    return c

def vertex_energy_tables(candidates, grid_xy, *, cell: float, c_move: float) -> list[np.ndarray]:
    """Vertex energies: ``c_move`` times the displacement (m) from the input position.

    A small tie-breaker (the paper's vertex energy is zero): among equally good
    solutions, the one that moves vertices least.
    """
    g = np.asarray(grid_xy, dtype=np.float64)
    return [c_move * cell * np.hypot(*(c - g[i]).T) for i, c in enumerate(candidates)]
