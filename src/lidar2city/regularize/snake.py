"""Regularise building outlines (and any planar topology) with the 2-D snake.

The vertices of a building's topology graph move, each within a window of
grid positions around where it is, to the joint configuration that minimises
direction energy (edges near the building's axes become exactly parallel to
them, oblique walls stay oblique) plus deviation energy (stay on the original
outline). The minimum is global: :func:`lidar2city.snake.minimize_energy`.

* :func:`adjust_planar_graph` works on a general planar graph (vertices,
  edges, fixed / free flags) — a footprint ring set or a whole roof topology.
* :func:`regularize_polygon` regularises one footprint polygon with holes.

References
----------
Yan, J., Zhang, K., Zhang, C., Chen, S.-C., Narasimhan, G. (2015).
Automatic construction of 3-D building model from airborne LIDAR data
through 2-D snake algorithm. IEEE TGRS 53(1), 3–14 (eqs. 4–6).
"""

from __future__ import annotations

import inspect
import logging
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
import shapely

from ..config import field
from ..errors import AlgorithmError, ConfigError, EmptyInputError, InputError
from ..snake.energies import (
    candidate_positions,
    distance_raster,
    edge_energy_tables,
    vertex_energy_tables,
)
from ..snake.solver import minimize_energy
from .direction import dominant_direction, from_frame, segments_of, to_frame

__all__ = ["SnakeConfig", "adjust_planar_graph", "regularize_polygon", "regularize_polygons"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class SnakeConfig:
    """Options of the 2-D snake regularisation (stage ``snake``)."""

    cell: float = field(0.5, "grid cell size (m) of candidate positions and of the distance raster; about the point spacing")
    window: int = field(2, "half-width w of the candidate window: (2w+1)^2 positions per vertex")
    t_adjust: float | None = field(None, "threshold T (m): an edge whose smaller x/y extent is within T is pulled onto the building axes; default 2 * cell")
    c_dir: float | None = field(None, "weight C_Dir of the direction energy (eq. 6); default T in metres, enough to align every adjustable edge")
    c_dis: float = field(1.0, "weight C_Dis of the deviation energy (eq. 6)")
    c_move: float = field(0.05, "tie-breaking vertex energy per metre of displacement")
    c_short: float | None = field(None, "energy (m^2) of an edge shorter than short_length but not zero, to remove noise jogs; default 2 * cell^2; 0 = off")
    short_length: float | None = field(None, "length (m) below which an edge counts as a jog; default 2 * cell")
    direction: float | None = field(None, "building direction in radians; default estimated per polygon (length-weighted histogram)")
    simplify_tolerance: float | None = field(None, "Douglas-Peucker tolerance (m) applied before the snake; default cell; 0 = none")
    refine: bool = field(True, "after the snake, shift each edge along its normal to the median of the input outline near it (keeps all angles; removes grid quantisation)")
    strategy: Literal["auto", "paper"] = field("auto", "solver choice when no degree <= 2 vertex is left: 'paper' always type IV, 'auto' also general elimination when cheaper")

    def __post_init__(self):
        _check_options(self.cell, self.window, self.t_adjust, self.c_dir, self.c_dis, self.c_move,
                       self.simplify_tolerance, c_short=self.c_short, short_length=self.short_length,
                       error=ConfigError, prefix="snake.")
        if self.strategy not in ("auto", "paper"):
            raise ConfigError(f"snake.strategy: {self.strategy!r} is not one of 'auto', 'paper'")


def _check_options(cell, window, t_adjust, c_dir, c_dis, c_move, simplify_tolerance,
                   *, c_short=None, short_length=None, error=InputError, prefix=""):
    if not (np.isfinite(cell) and cell > 0):
        raise error(f"{prefix}cell must be a positive number of metres, got {cell}")
    if isinstance(window, bool) or int(window) != window or not 0 <= window <= 10:
        raise error(f"{prefix}window must be an integer in [0, 10], got {window}")
    for name, val in (("t_adjust", t_adjust), ("c_dir", c_dir), ("simplify_tolerance", simplify_tolerance),
                      ("c_short", c_short), ("short_length", short_length)):
        if val is not None and not (np.isfinite(val) and val >= 0):
            raise error(f"{prefix}{name} must be >= 0 (or unset), got {val}")
    for name, val in (("c_dis", c_dis), ("c_move", c_move)):
        if not (np.isfinite(val) and val >= 0):
            raise error(f"{prefix}{name} must be >= 0, got {val}")


def _grid_pivot(xy, cell):
    """The building frame's origin: the vertices' mean on a grid node (so that with
    direction 0 the snake's grid is the world grid)."""
    return np.round(xy.mean(axis=0) / cell) * cell if len(xy) else np.zeros(2)


def _frame_solve(xy, edges, segs, *, cell, window, direction, t_adjust, c_dir, c_dis, c_move,
                 fixed, strategy, c_short=0.0, short_length=0.0, subdivide=4, sample_step=1.0,
                 pivot=None):
    """Solve the snake in the building frame; return grid positions and details."""
    pivot = _grid_pivot(xy, cell) if pivot is None else np.asarray(pivot, dtype=np.float64)
    q = to_frame(xy, direction, pivot) / cell
    seg_q = to_frame(segs, direction, pivot) / cell
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    cands = candidate_positions(q, window, fixed=fixed)
    raster = distance_raster(seg_q, margin=int(window) + 2, subdivide=subdivide)
    kwargs = dict(cell=cell, t_adjust=t_adjust, c_dis=c_dis, c_short=c_short, short_length=short_length,
                  step=sample_step)
    # The deviation of a pair that pays the direction energy (an adjustable edge left
    # off the axes) is bounded below by 0, not sampled: most pairs of a window, hardly
    # ever in the minimum. Those tables' minimum is the true energy's minimum as soon
    # as it uses no bounded entry; otherwise the edges whose bounded entry it used get
    # their true tables and the graph is solved again (exact; see edge_energy_tables).
    tables, bounded = edge_energy_tables(cands, edges, raster, c_dir=c_dir, bound=True, **kwargs)
    unary = vertex_energy_tables(cands, q, cell=cell, c_move=c_move)
    weights = np.broadcast_to(np.asarray(c_dir, dtype=np.float64), (len(edges),))
    while True:
        sol = minimize_energy(unary, edges, tables, strategy=strategy)
        s = sol.states
        used = np.flatnonzero([b[s[u], s[v]] for (u, v), b in zip(edges, bounded, strict=True)])
        if not len(used):
            break
        true = edge_energy_tables(cands, edges[used], raster, c_dir=weights[used], **kwargs)
        for k, t in zip(used, true, strict=True):
            tables[k], bounded[k] = t, np.zeros(t.shape, dtype=bool)
    grid = np.array([cands[v][s] for v, s in enumerate(sol.states)]).reshape(-1, 2)
    return grid, pivot, sol


def _defaults(cell, t_adjust, c_dir):
    t = 2.0 * cell if t_adjust is None else float(t_adjust)
    c = t if c_dir is None else c_dir
    return t, c


def _short_defaults(cell, c_short, short_length):
    cs = 2.0 * cell * cell if c_short is None else float(c_short)
    ls = 2.0 * cell if short_length is None else float(short_length)
    return cs, ls


def adjust_planar_graph(
    vertices_xy,
    edges,
    *,
    original_segments=None,
    cell: float = 0.5,
    window: int = 2,
    direction: float | None = None,
    t_adjust: float | None = None,
    c_dir=None,
    c_dis: float = 1.0,
    c_move: float = 0.05,
    c_short: float = 0.0,
    short_length: float | None = None,
    fixed=None,
    strategy: str = "auto",
    subdivide: int = 4,
    sample_step: float = 1.0,
    pivot=None,
) -> tuple[np.ndarray, dict]:
    """Move the vertices of a planar topology graph to the snake's global minimum.

    Parameters
    ----------
    vertices_xy : array, shape (n, 2)
        Vertex positions (local metres).
    edges : array of int, shape (m, 2)
        The topology: index pairs, ``u != v``.
    original_segments : array (k, 2, 2) or shapely geometry, optional
        The data the result must stay on (deviation energy); default the
        graph's own edges.
    cell : float
        Grid cell (m). Free vertices snap to the grid of the building frame.
    window : int
        Each free vertex may move to ``(2w+1)**2`` grid positions.
    direction : float, optional
        Building direction (radians); default :func:`dominant_direction` of
        ``original_segments``.
    t_adjust : float, optional
        ``T`` (m) of the direction energy; default ``2 * cell``.
    c_dir : float or array of float (m,), optional
        ``C_Dir``, for all edges or per edge (0 = no direction constraint on
        that edge, e.g. hips and valleys of a roof); default ``T`` (m).
    c_dis, c_move : float
        ``C_Dis`` and the tie-breaking displacement weight.
    c_short, short_length : float
        Jog energy (m^2; default 0 = off for general graphs, whose short
        edges may be real) and its length (m, default ``2 * cell``).
    fixed : array of bool, shape (n,), optional
        Vertices that keep their exact position (one state).
    strategy : {"auto", "paper"}
        Passed to :func:`~lidar2city.snake.minimize_energy`.
    subdivide : int
        Distance raster cells per grid cell (:func:`~lidar2city.snake.energies.distance_raster`).
    sample_step : float
        Spacing (raster cells) of the deviation's samples along each candidate
        edge (:func:`~lidar2city.snake.energies.edge_energy_tables`).
    pivot : array (2,), optional
        Origin (m) of the building frame, whose grid the free vertices snap to;
        default the vertices' mean rounded to a multiple of ``cell``. A part of a
        graph solved again on its own keeps the whole graph's grid by passing the
        whole graph's pivot (``_grid_pivot``): the minimum of a connected part does
        not depend on the rest.

    Returns
    -------
    new_xy : ndarray, shape (n, 2)
    info : dict
        ``direction`` (radians), ``direction_deg``, ``energy``, ``reductions``,
        ``states`` (candidate index per vertex, 0 = snapped input position),
        ``moved`` (number of vertices whose snapped position changed),
        ``coincident`` (groups of vertex indices that ended at the same
        position: edges between them collapsed; merge them if needed).

    Raises
    ------
    InputError, EmptyInputError
        Malformed vertices, edges or options.

    Examples
    --------
    >>> xy = np.array([[0, 0], [10, 0.4], [10.2, 5], [0.3, 5.1]])
    >>> new, info = adjust_planar_graph(xy, [(0, 1), (1, 2), (2, 3), (3, 0)], direction=0.0)
    >>> sorted(set(np.round(new[:, 1], 6).tolist()))
    [0.0, 5.0]
    """
    xy = np.asarray(vertices_xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise InputError(f"vertices_xy must have shape (n, 2), got {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise InputError("vertices_xy must be finite")
    e = np.asarray(edges)
    if e.size == 0:
        raise EmptyInputError("edges: the graph has no edge")
    if e.ndim != 2 or e.shape[1] != 2 or not np.issubdtype(e.dtype, np.integer):
        raise InputError(f"edges must be integer pairs of shape (m, 2), got {e.shape} {e.dtype}")
    if e.min() < 0 or e.max() >= len(xy) or np.any(e[:, 0] == e[:, 1]):
        raise InputError(f"edges must join distinct vertices in [0, {len(xy)})")
    if c_dir is not None and np.ndim(c_dir) > 0:
        c_dir = np.asarray(c_dir, dtype=np.float64)
        if c_dir.shape != (len(e),) or not np.all(np.isfinite(c_dir) & (c_dir >= 0)):
            raise InputError(f"c_dir must be a number or {len(e)} non-negative numbers (one per edge)")
        _check_options(cell, window, t_adjust, None, c_dis, c_move, None, c_short=c_short, short_length=short_length)
    else:
        _check_options(cell, window, t_adjust, c_dir, c_dis, c_move, None, c_short=c_short, short_length=short_length)
    fixed_arr = np.zeros(len(xy), dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
    if fixed_arr.shape != (len(xy),):
        raise InputError(f"fixed must have shape ({len(xy)},), got {fixed_arr.shape}")
    segs = xy[e] if original_segments is None else segments_of(original_segments)
    if len(segs) == 0:
        raise EmptyInputError("original_segments holds no edge of positive length")
    if direction is None:
        direction = dominant_direction(segs)
    t, c = _defaults(cell, t_adjust, c_dir)
    cs, ls = _short_defaults(cell, c_short, short_length)
    if pivot is not None:
        pivot = np.asarray(pivot, dtype=np.float64)
        if pivot.shape != (2,) or not np.all(np.isfinite(pivot)):
            raise InputError(f"pivot must be a finite (x, y), got {pivot!r}")
    grid, pivot, sol = _frame_solve(xy, e, segs, cell=cell, window=window, direction=direction,
                                    t_adjust=t, c_dir=c, c_dis=c_dis, c_move=c_move,
                                    fixed=fixed_arr, strategy=strategy, c_short=cs, short_length=ls,
                                    subdivide=subdivide, sample_step=sample_step, pivot=pivot)
    new = from_frame(grid * cell, direction, pivot)
    new[fixed_arr] = xy[fixed_arr]
    info = {
        "direction": float(direction),
        "direction_deg": float(np.degrees(direction)),
        "energy": float(sol.energy),
        "reductions": dict(sol.reductions),
        "states": sol.states,
        "moved": int(np.count_nonzero(sol.states[~fixed_arr] != 0)),
        "coincident": _coincident(new),
    }
    return new, info


def _coincident(xy: np.ndarray) -> list[list[int]]:
    """Groups (size >= 2) of vertices at identical positions."""
    if len(xy) < 2:
        return []
    _, inverse, counts = np.unique(xy, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    return [np.flatnonzero(inverse == g).tolist() for g in np.flatnonzero(counts > 1)]


def _clean_ring(g: np.ndarray) -> np.ndarray:
    """Drop repeated, collinear and spike vertices of a closed ring on the grid (exact)."""
    while len(g) >= 3:
        g = g[np.any(g != np.roll(g, 1, axis=0), axis=1)]
        if len(g) < 3:
            break
        a = g - np.roll(g, 1, axis=0)
        b = np.roll(g, -1, axis=0) - g
        cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
        keep = np.abs(cross) > 1e-9
        if keep.all():
            break
        g = g[keep]
    return g


def _refit_ring(ring: np.ndarray, ref: np.ndarray, *, max_dist: float, max_shift: float) -> np.ndarray:
    """Re-fit each edge's offset to the input outline, keeping every edge's direction.

    The snake places walls on grid lines; each edge line ``n . x = c`` here
    moves (along its normal only) to the median of the input outline points
    that are nearest to it (away from its ends, within ``max_dist``), and the
    vertices become the intersections of consecutive lines. Angles are kept
    exactly, so a regularised outline stays regular. The ring is returned
    unchanged if any vertex would move more than ``max_shift``.

    Parameters
    ----------
    ring : ndarray, shape (k, 2)
        Open ring (building frame, metres), no repeated or collinear vertices.
    ref : ndarray, shape (N, 2)
        Points sampled along the input outline (same frame).
    """
    a = ring
    b = np.roll(ring, -1, axis=0)
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    t = d / length[:, None]
    n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    rel = ref[:, None, :] - a[None, :, :]  # (N, k, 2)
    s = np.einsum("nkc,kc->nk", rel, t) / length
    foot = a[None] + np.clip(s, 0, 1)[..., None] * d[None]
    dist = np.hypot(*(ref[:, None, :] - foot).transpose(2, 0, 1))
    near = np.argmin(dist, axis=1)
    rows = np.arange(len(ref))
    inner = (s[rows, near] > 0.1) & (s[rows, near] < 0.9) & (dist[rows, near] <= max_dist)
    c = np.einsum("kc,kc->k", n, a)
    proj = np.einsum("nc,nc->n", ref, n[near])
    for i in range(len(ring)):
        sel = inner & (near == i)
        if np.count_nonzero(sel) >= 3:
            c[i] = np.median(proj[sel])
    # Vertex i joins edge i-1 and edge i.
    n0, c0 = np.roll(n, 1, axis=0), np.roll(c, 1)
    det = n0[:, 0] * n[:, 1] - n0[:, 1] * n[:, 0]
    if np.any(np.abs(det) < 1e-6):
        return ring
    x = (c0 * n[:, 1] - c * n0[:, 1]) / det
    y = (n0[:, 0] * c - n[:, 0] * c0) / det
    new = np.stack([x, y], axis=1)
    if np.max(np.hypot(*(new - ring).T)) > max_shift:
        return ring
    return new


def _repair(poly, keep: float = 0.95):
    """Largest valid piece of an invalid polygon, or None if it loses > 5 % of the area."""
    fixed = shapely.make_valid(poly)
    parts = [g for g in getattr(fixed, "geoms", [fixed]) if isinstance(g, shapely.Polygon)]
    parts += [q for g in getattr(fixed, "geoms", []) if isinstance(g, shapely.MultiPolygon) for q in g.geoms]
    if not parts:
        return None
    total = sum(g.area for g in parts)
    best = max(parts, key=lambda g: g.area)
    if total <= 0 or best.area < keep * total or best.area < keep * abs(shapely.Polygon(poly.exterior).area):
        return None
    best = shapely.simplify(best, 0.0)  # drops collinear vertices added at crossings
    return best if isinstance(best, shapely.Polygon) and best.is_valid and not best.is_empty else None


def _open_ring(ring) -> np.ndarray:
    xy = np.asarray(ring.coords, dtype=np.float64)[:, :2]
    return xy[:-1] if len(xy) > 1 and np.array_equal(xy[0], xy[-1]) else xy


def _mean_deviation(result, reference, step: float) -> float:
    line = shapely.segmentize(result.boundary, max_segment_length=step)
    pts = shapely.points(shapely.get_coordinates(line))
    return float(np.mean(shapely.distance(pts, reference.boundary)))


def regularize_polygon(
    polygon,
    *,
    cell: float = 0.5,
    window: int = 2,
    t_adjust: float | None = None,
    c_dir: float | None = None,
    c_dis: float = 1.0,
    c_move: float = 0.05,
    direction: float | None = None,
    simplify_tolerance: float | None = None,
    refine: bool = True,
    c_short: float | None = None,
    short_length: float | None = None,
    strategy: str = "auto",
    sample_step: float = 1.0,
):
    """Regularise a building footprint with the 2-D snake.

    The rings (exterior and courtyards) are simplified (Douglas–Peucker), and
    their vertices form one graph solved once. The deviation energy is
    measured against the *input* outline, so simplification does not drift.

    Parameters
    ----------
    polygon : shapely.Polygon
        Footprint in local metres (traced or simplified), holes allowed.
    cell, window, t_adjust, c_dir, c_dis, c_move, strategy
        See :func:`adjust_planar_graph`.
    direction : float, optional
        Building direction in radians; default estimated from the polygon.
    simplify_tolerance : float, optional
        Douglas–Peucker tolerance (m) before the snake; default ``cell``;
        0 keeps every vertex.
    c_short, short_length : float, optional
        Energy (m^2) of a jog (an edge shorter than ``short_length`` m but
        not of zero length) — beyond the paper, removes the steps noise
        leaves; defaults ``2 * cell**2`` and ``2 * cell``; 0 = off.
    refine : bool
        After the snake, move each edge along its normal to the median of the
        input outline near it (directions unchanged): removes the grid's
        quantisation of wall positions (beyond the paper).
    sample_step : float
        Spacing (cells of the distance raster, a quarter of ``cell``) of the
        deviation energy's samples along a candidate edge
        (:func:`lidar2city.snake.energies.deviation_energy`); 1 reads every
        raster cell the edge crosses, 2 every other one (half the look-ups).

    Returns
    -------
    polygon : shapely.Polygon
        The regularised footprint, or the input when regularisation failed.
    info : dict
        ``status`` ("regularized" or "fallback"), ``reason`` (why, on
        fallback), ``direction_deg``, ``n_vertices`` (of the result),
        ``n_vertices_in`` (snake vertices), ``reductions`` (type I–IV counts),
        ``energy``, ``mean_deviation_m`` (mean distance of the result's
        boundary to the input boundary), ``holes_dropped``, ``repaired``
        (crossing vertices were untangled, keeping the main piece),
        ``refined`` (the offset refit was kept; it is dropped when it would
        make the outline invalid), ``time_s``.

    Raises
    ------
    InputError
        Not a polygon, empty, or bad options.

    Examples
    --------
    >>> import shapely
    >>> noisy = shapely.Polygon([(0, 0), (12.1, 0.2), (11.9, 8.1), (6, 7.8), (0.1, 8.2)])
    >>> poly, info = regularize_polygon(noisy, direction=0.0, refine=False)
    >>> sorted(shapely.get_coordinates(poly.exterior)[:-1].round(6).tolist())
    [[0.0, 0.0], [0.0, 8.0], [12.0, 0.0], [12.0, 8.0]]
    >>> poly, info = regularize_polygon(noisy, direction=0.0)  # walls refitted to the data
    >>> len(poly.exterior.coords) - 1, info["status"]
    (4, 'regularized')
    """
    t0 = time.perf_counter()
    if not isinstance(polygon, shapely.Polygon):
        raise InputError(f"polygon must be a shapely Polygon, got {type(polygon).__name__}")
    if polygon.is_empty or polygon.area <= 0:
        raise EmptyInputError("polygon is empty")
    _check_options(cell, window, t_adjust, c_dir, c_dis, c_move, simplify_tolerance,
                   c_short=c_short, short_length=short_length)
    if not (np.isfinite(sample_step) and sample_step > 0):
        raise InputError(f"sample_step must be a positive number of raster cells, got {sample_step}")
    tol = cell if simplify_tolerance is None else float(simplify_tolerance)
    info: dict = {"status": "fallback", "reason": "", "direction_deg": None,
                  "n_vertices": len(polygon.exterior.coords) - 1,
                  "n_vertices_in": 0, "reductions": {"I": 0, "II": 0, "III": 0, "IV": 0},
                  "energy": None, "mean_deviation_m": 0.0, "holes_dropped": 0, "repaired": False,
                  "refined": False}

    def done(result):
        info["time_s"] = time.perf_counter() - t0
        return result, info

    simple = polygon.simplify(tol, preserve_topology=True) if tol > 0 else polygon
    if direction is None:
        # Projection profiles of the input outline: robust to the zig-zag of traced
        # outlines, whose short edges' directions are mostly noise.
        direction = dominant_direction(polygon, method="profile", profile_bin=cell / 2)
    info["direction_deg"] = float(np.degrees(direction))
    rings = [_open_ring(simple.exterior)] + [_open_ring(r) for r in simple.interiors]
    info["holes_dropped"] = sum(1 for r in rings[1:] if len(r) < 3)
    rings = [rings[0]] + [r for r in rings[1:] if len(r) >= 3]
    if len(rings[0]) < 3:
        info["reason"] = "outline degenerate after simplification"
        return done(polygon)
    sizes = [len(r) for r in rings]
    xy = np.concatenate(rings)
    starts = np.cumsum([0] + sizes[:-1])
    edges = np.concatenate([
        np.stack([s + np.arange(k), s + (np.arange(k) + 1) % k], axis=1)
        for s, k in zip(starts, sizes, strict=True)
    ])
    t, c = _defaults(cell, t_adjust, c_dir)
    cs, ls = _short_defaults(cell, c_short, short_length)
    try:
        grid, pivot, sol = _frame_solve(xy, edges, segments_of(polygon), cell=cell, window=window,
                                        direction=direction, t_adjust=t, c_dir=c, c_dis=c_dis,
                                        c_move=c_move, fixed=None, strategy=strategy,
                                        c_short=cs, short_length=ls, sample_step=sample_step)
    except AlgorithmError as exc:  # pragma: no cover - rings always reduce by I-III
        info["reason"] = f"snake failed: {exc}"
        return done(polygon)
    info.update(n_vertices_in=int(len(xy)), reductions=dict(sol.reductions), energy=float(sol.energy))
    cleaned = [_clean_ring(grid[s : s + k]) for s, k in zip(starts, sizes, strict=True)]
    if len(cleaned[0]) < 3:
        if window > 1:
            # a window wider than the building lets every vertex gather in one place:
            # the global minimum of a smaller window is the best non-degenerate outline
            return regularize_polygon(
                polygon, cell=cell, window=window - 1, t_adjust=t_adjust, c_dir=c_dir,
                c_dis=c_dis, c_move=c_move, direction=direction,
                simplify_tolerance=simplify_tolerance, refine=refine, c_short=c_short,
                short_length=short_length, strategy=strategy, sample_step=sample_step)
        info["reason"] = "outline collapsed"
        return done(polygon)
    holes = [h for h in cleaned[1:] if len(h) >= 3]
    info["holes_dropped"] += len(cleaned) - 1 - len(holes)
    frame_rings = [cleaned[0] * cell] + [h * cell for h in holes]
    tries = [frame_rings]
    if refine:
        # Reference points every cell / 4 (at most ~2e6 point-edge pairs in the refit).
        k = sum(len(r) for r in frame_rings)
        spacing = max(cell / 4, polygon.boundary.length * k / 2e6)
        line = shapely.segmentize(polygon.boundary, max_segment_length=spacing)
        ref = to_frame(shapely.get_coordinates(line), direction, pivot)
        refined = [_refit_ring(r, ref, max_dist=(window + 1) * cell, max_shift=(window + 1) * cell)
                   for r in frame_rings]
        tries.insert(0, refined)
    shapes = [shapely.Polygon(from_frame(t[0], direction, pivot), [from_frame(h, direction, pivot) for h in t[1:]])
              for t in tries]
    result, used = None, None
    for k, g in enumerate(shapes):
        if g.is_valid:
            result, used = g, k
            break
    if result is None:
        # The snake has no topology constraint: vertices may cross (a small loop at a
        # spike, a courtyard touching the outline). Repair, and keep the main piece if
        # it holds nearly all the area.
        for k, g in enumerate(shapes):
            result, used = _repair(g), k
            if result is not None:
                break
        if result is None:
            info["reason"] = f"regularised outline invalid ({shapely.is_valid_reason(shapes[0])})"
            return done(polygon)
        info["repaired"] = True
    info["refined"] = bool(refine and used == 0)
    info["status"] = "regularized"
    info["n_vertices"] = len(result.exterior.coords) - 1 + sum(len(r.coords) - 1 for r in result.interiors)
    info["mean_deviation_m"] = _mean_deviation(result, polygon, cell / 2)
    return done(result)


def regularize_polygons(geometries, **options) -> tuple[list, list[dict]]:
    """Regularise many footprints; a batch never dies on one building.

    Parameters
    ----------
    geometries : sequence of shapely Polygon or MultiPolygon
        Footprints in local metres. A MultiPolygon is regularised part by part.
    **options
        Keywords of :func:`regularize_polygon` (e.g. ``**asdict(SnakeConfig())``).

    Returns
    -------
    results : list of shapely geometry
        The regularised footprints (the input where regularisation failed).
    infos : list of dict
        As :func:`regularize_polygon`; ``status`` is ``"regularized"``,
        ``"fallback"`` or ``"error"`` (bad or empty geometry), with a
        ``reason``. For a MultiPolygon, counts are summed over its parts and
        the direction is that of the largest part.

    Raises
    ------
    InputError
        Invalid options (checked once, before any polygon).
    """
    known = set(inspect.signature(regularize_polygon).parameters) - {"polygon"}
    unknown = sorted(set(options) - known)
    if unknown:
        raise InputError(f"unknown option {unknown[0]!r}; known: {', '.join(sorted(known))}")
    _check_options(options.get("cell", 0.5), options.get("window", 2), options.get("t_adjust"),
                   options.get("c_dir"), options.get("c_dis", 1.0), options.get("c_move", 0.05),
                   options.get("simplify_tolerance"), c_short=options.get("c_short"),
                   short_length=options.get("short_length"))
    results, infos = [], []
    for geom in geometries:
        try:
            if isinstance(geom, shapely.MultiPolygon):
                parts = sorted(geom.geoms, key=lambda g: -g.area)
                done = [regularize_polygon(g, **options) for g in parts]
                info = dict(done[0][1])
                info["reductions"] = {k: sum(d[1]["reductions"].get(k, 0) for d in done)
                                      for k in done[0][1]["reductions"]}
                for key in ("n_vertices", "n_vertices_in", "holes_dropped"):
                    info[key] = sum(d[1][key] for d in done)
                info["status"] = ("regularized" if all(d[1]["status"] == "regularized" for d in done)
                                  else "fallback")
                info["reason"] = "; ".join(d[1]["reason"] for d in done if d[1]["reason"])
                results.append(shapely.MultiPolygon([d[0] for d in done]))
                infos.append(info)
            else:
                out, info = regularize_polygon(geom, **options)
                results.append(out)
                infos.append(info)
        except (InputError, AlgorithmError, shapely.errors.GEOSException) as exc:
            logger.warning("footprint not regularised: %s", exc)
            results.append(geom)
            infos.append({"status": "error", "reason": str(exc)})
    return results, infos
