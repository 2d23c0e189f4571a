"""Building footprints from classified points: regions, outlines, simplification, regularisation.

Pipeline (all grid lengths derive from the point spacing ``s`` of the
building points unless given):

1. building field on a grid of ``cell = 1.5 s`` (:func:`..grid.building_fraction`):
   the building share among all points (normalised convolution, ``sigma = s``),
   cells farther than ``void_distance = s`` from any point (with the default cell:
   every cell without a point) counting as not building;
2. regions ``field >= 0.5``, 8-connected; holes under ``min_hole_area`` filled,
   regions under ``min_area`` dropped; each region split where the roof jumps
   by more than ``split_step`` (:func:`..grid.split_at_steps`: row houses of
   different heights become one footprint each, parts under
   ``split_min_area`` join their neighbour);
3. the 0.5 iso-line of the field around each region (marching squares, sub-cell);
4. an optional ``edge_offset`` (negative shrinks: LiDAR sees roof edges, which
   overhang the walls that cadastral footprints such as the Dutch BGT draw; on
   the Delft AHN3 tile the traced outlines lie about 0.2-0.3 m outside the BGT
   walls, while on synthetic scans without overhang they are unbiased to 0.03 m,
   so the default is 0: the outline the LiDAR sees);
5. a regulariser from :data:`..regularizers.REGULARIZERS`, with the
   Douglas–Peucker tolerance ``simplify = cell``: ``none`` (and the fallback of
   the others) keeps the simplified outline, vertices refitted to the lines
   through the traced outline (:func:`..trace.simplify_polygon`); the snake
   simplifies on its own.

Row houses of one height sharing walls form one block: points alone do not show
party walls where the roof does not step. The per-area quality does not depend
on it; per-object matching against a cadastre that splits the block does.
Adjacent parts of one region are made disjoint after regularisation (the
larger keeps the shared edge).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..classify.features import distinct_positions, scan_line_gap
from ..config import field as cfield
from ..errors import AlgorithmError, ConfigError, EmptyInputError, InputError
from .grid import (Grid, building_fraction, building_regions, cell_heights, point_spacing,
                   split_at_steps)
from .regularizers import REGULARIZERS, vertex_count
from .trace import trace_regions

logger = logging.getLogger(__name__)

__all__ = ["FootprintsConfig", "Footprint", "TracedOutlines", "assemble_footprints",
           "extract_footprints", "grid_lengths", "regularise_outlines", "regularised_reach",
           "trace_outlines"]


@dataclass(frozen=True)
class FootprintsConfig:
    """Options of stage ``footprints`` (the keywords of :func:`extract_footprints`)."""

    building_class: int = cfield(6, "ASPRS class of building points.")
    cell: float | None = cfield(None, "Grid cell (m); default 1.5 x the building point spacing.")
    sigma: float | None = cfield(
        None, "Gaussian sigma (m) of the building share; default the point spacing.")
    void_distance: float | None = cfield(
        None, "Cells farther (m) from any point count as not building; default the spacing.")
    min_area: float = cfield(4.0, "Smallest building kept (m2).")
    min_hole_area: float = cfield(4.0, "Smallest courtyard kept as a hole (m2).")
    split_step: float = cfield(
        2.0, "Roof height jump (m) that splits a block into buildings; 0 disables.")
    split_min_area: float = cfield(
        10.0, "Smallest part (m2) of a split block kept as a building of its own.")
    edge_offset: float = cfield(
        0.0, "Outline offset (m) after tracing; negative shrinks (roof overhang over the walls).")
    simplify: float | None = cfield(
        None, "Douglas-Peucker tolerance (m); default the cell; 0 disables.")
    regularize: Literal["none", "snake", "fit"] = cfield(
        "none", "Outline regulariser: none, snake, or fit (polygon fitting with "
        "complexity-penalised selection on the rasterised outline).")
    snake_cell: float | None = cfield(
        None, "Grid cell (m) of the snake's candidate positions; default the cell.")
    snake_window: int = cfield(3, "Snake search half-window w (cells): (2w+1)^2 states per vertex.")
    snake_threshold: float | None = cfield(
        None, "Snake threshold T (m): an edge whose smaller x/y extent (building frame) is within "
        "T is pulled onto the building axes, others stay oblique; default 2 x snake_window x "
        "snake_cell, the largest misalignment the search window can correct.")
    snake_sample_step: float = cfield(
        2.0, "Spacing of the snake's deviation samples along a candidate edge, in cells of "
        "its distance raster (a quarter of snake_cell): 1 reads every cell, 2 every other one.")

    def __post_init__(self):
        for name in ("cell", "sigma", "void_distance", "snake_cell", "snake_threshold",
                     "snake_sample_step"):
            v = getattr(self, name)
            if v is not None and not v > 0:
                raise ConfigError(f"footprints.{name}: must be > 0, got {v}")
        for name in ("min_area", "min_hole_area", "split_step", "split_min_area"):
            if getattr(self, name) < 0:
                raise ConfigError(f"footprints.{name}: must be >= 0, got {getattr(self, name)}")
        if self.simplify is not None and self.simplify < 0:
            raise ConfigError(f"footprints.simplify: must be >= 0, got {self.simplify}")
        if self.regularize not in REGULARIZERS:
            raise ConfigError(f"footprints.regularize: {self.regularize!r} is not one of "
                              f"{', '.join(map(repr, REGULARIZERS))}")
        if self.snake_window < 1:
            raise ConfigError(f"footprints.snake_window: must be >= 1, got {self.snake_window}")


@dataclass(frozen=True, eq=False)
class Footprint:
    """One extracted building footprint.

    ``polygon`` is a shapely Polygon in the local metric frame of the points;
    ``status`` is ``"ok"`` or ``"unregularised"`` (the regulariser failed for
    this building: ``reason`` says why and ``polygon`` is the simplified
    outline); ``attributes`` holds ``area`` (m2), ``direction`` (degrees,
    dominant direction modulo 90), ``n_vertices``, ``type_i`` .. ``type_iv``
    (snake graph reductions of each type), ``mean_deviation`` (m), ``n_points``
    (building points inside).
    """

    polygon: object
    status: str = "ok"
    reason: str = ""
    attributes: dict = field(default_factory=dict)


def grid_lengths(spacing: float, *, cell=None, sigma=None, void_distance=None, simplify=None,
                 snake_cell=None) -> dict:
    """Resolve the grid lengths (m) from the point spacing where they are not given."""
    cell = cell if cell is not None else 1.5 * spacing
    return {
        "cell": cell,
        "sigma": sigma if sigma is not None else spacing,
        "void_distance": void_distance if void_distance is not None else spacing,
        "simplify": simplify if simplify is not None else cell,
        "snake_cell": snake_cell if snake_cell is not None else cell,
    }


def _parts(geom, min_area):
    return [g for g in getattr(geom, "geoms", [geom])
            if g.geom_type == "Polygon" and g.area >= max(min_area, 1e-9)]


#: the largest building grid traced at once (cells): a 10 km x 10 km block at 1 m
MAX_GRID_CELLS = 1e8


def extract_footprints(xyz, classification, *, building_class: int = 6, cell: float | None = None,
                       sigma: float | None = None, void_distance: float | None = None,
                       min_area: float = 4.0,
                       min_hole_area: float = 4.0, split_step: float = 2.0,
                       split_min_area: float = 10.0, edge_offset: float = 0.0,
                       simplify: float | None = None, regularize: str = "none",
                       snake_cell: float | None = None, snake_window: int = 3,
                       snake_threshold: float | None = None, snake_sample_step: float = 2.0,
                       within=None,
                       callback=None) -> list[Footprint]:
    """Building footprints (one polygon per building block, with courtyards) from classified points.

    The composition of three stages, each a pure function a caller may also run
    apart (several workers sharing one block's outlines): :func:`trace_outlines`
    (field, regions, split, outlines), :func:`regularise_outlines` (each outline,
    independently) and :func:`assemble_footprints` (the parts of one region made
    disjoint); the result is the same whichever way they are run.

    Parameters
    ----------
    xyz : ndarray, shape (N, 3) or (N, 2)
        Local metric coordinates of all points (building and others: the other
        points tell where the building stops).
    classification : ndarray of int, shape (N,)
        ASPRS classes.
    building_class : int
        Class of building points.
    cell, sigma, void_distance, simplify, snake_cell : float, optional
        Lengths in metres; defaults from the building point spacing ``s``:
        ``1.5 s``, ``s``, ``s``, ``cell``, ``cell``
        (see the module docstring).
    min_area, min_hole_area : float
        Smallest building and smallest courtyard kept (m2).
    split_step, split_min_area : float
        A region is split where its roof jumps by more than ``split_step`` (m),
        into parts of at least ``split_min_area`` (m2)
        (:func:`~lidar2city.footprints.grid.split_at_steps`); ``split_step = 0``
        or 2-D points keep one footprint per connected region.
    edge_offset : float
        Offset (m) of the traced outline; negative shrinks.
    regularize : {"none", "snake", "fit"}
        A key of :data:`~lidar2city.footprints.regularizers.REGULARIZERS`.
    snake_window : int
        Half-window (cells of ``snake_cell``) of the snake's candidate positions.
    snake_threshold : float, optional
        The snake's T (m) separating edges to align from oblique ones (eq. 4);
        default ``2 * snake_window * snake_cell``: moving both ends of an edge by
        at most the window, the snake can straighten an edge whose smaller
        extent is up to that, not more.
    snake_sample_step : float
        Spacing (cells of the snake's distance raster, ``snake_cell / 4``) of the
        deviation energy's samples along a candidate edge.
    within : (xmin, ymin, xmax, ymax), optional
        Local box: only the footprints whose bounding box may have its centre
        in it are wanted (a block keeps those centred in its cell). The
        regions whose traced outline, grown by :func:`regularised_reach`, stays
        clear of the box are left out before they are regularised; the others
        come out as without it (the caller picks the centred ones).
    callback : callable, optional
        Called as ``callback(done, total)`` after each building.

    Returns
    -------
    list of Footprint
        In a deterministic order (grid scan order of the regions).

    Raises
    ------
    InputError
        For arrays of the wrong shape, non-finite coordinates, an unknown
        regulariser, or points spread over more than :data:`MAX_GRID_CELLS` cells.
    EmptyInputError
        When no point has ``building_class``.

    Examples
    --------
    >>> fps = extract_footprints(cloud.xyz, cloud.get("classification"))  # doctest: +SKIP
    >>> [f.attributes["area"] for f in fps]  # doctest: +SKIP
    """
    outlines = trace_outlines(
        xyz, classification, building_class=building_class, cell=cell, sigma=sigma,
        void_distance=void_distance, min_area=min_area, min_hole_area=min_hole_area,
        split_step=split_step, split_min_area=split_min_area, edge_offset=edge_offset,
        simplify=simplify, regularize=regularize, snake_cell=snake_cell,
        snake_window=snake_window, snake_threshold=snake_threshold,
        snake_sample_step=snake_sample_step, within=within)
    found: list[Footprint] = []
    ends = np.searchsorted(outlines.traced, np.arange(outlines.n_traced), side="right")
    start = 0
    for n_done, end in enumerate(ends, start=1):
        # the parts of one traced region, then the callback
        found += regularise_outlines(outlines, range(start, int(end)))
        start = int(end)
        if callback is not None:
            callback(n_done, outlines.n_traced)
    return assemble_footprints(outlines, found)


@dataclass(frozen=True, eq=False)
class TracedOutlines:
    """The outlines :func:`trace_outlines` found, before regularisation (small, picklable).

    Attributes
    ----------
    parts : list of shapely Polygon
        The outlines to regularise (each traced region's outline, offset by
        ``edge_offset``, in parts of at least ``min_area``), in the grid scan
        order of their regions.
    traced : ndarray of int, shape (P,)
        Which traced region (0 .. ``n_traced - 1``) each part comes from (non-decreasing).
    regions : ndarray of int, shape (P,)
        The connected region of each part: parts of one region are made disjoint
        (:func:`assemble_footprints`).
    n_points : ndarray of int, shape (P,)
        Building points inside each part's traced region (or part).
    n_traced : int
        How many traced regions (those without a part of ``min_area`` included).
    settings : dict
        The regulariser and its lengths (:func:`regularise_outlines`), ``min_area``.
    numbers : ndarray of int, shape (P,), optional
        The parts' positions among the outlines these were taken from
        (:meth:`take`); None: their own.
    """

    parts: list
    traced: np.ndarray
    regions: np.ndarray
    n_points: np.ndarray
    n_traced: int
    settings: dict
    numbers: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.parts)

    def take(self, parts) -> TracedOutlines:
        """These outlines' ``parts`` (positions) only, each keeping its position
        (``numbers``): to regularise them elsewhere (:func:`regularise_outlines`)."""
        idx = np.asarray(parts, dtype=np.int64).reshape(-1)
        numbers = idx if self.numbers is None else self.numbers[idx]
        return TracedOutlines([self.parts[k] for k in idx], self.traced[idx], self.regions[idx],
                              self.n_points[idx], self.n_traced, self.settings, numbers)

    def work(self) -> np.ndarray:
        """Expected regularisation work of each part (its outline's vertices, plus a
        fixed share): what :func:`regularise_outlines` spends grows with them."""
        import shapely

        if not self.parts:
            return np.zeros(0)
        return shapely.get_num_coordinates(np.array(self.parts, dtype=object)) + 20.0


def trace_outlines(xyz, classification, *, building_class: int = 6, cell: float | None = None,
                   sigma: float | None = None, void_distance: float | None = None,
                   min_area: float = 4.0, min_hole_area: float = 4.0, split_step: float = 2.0,
                   split_min_area: float = 10.0, edge_offset: float = 0.0,
                   simplify: float | None = None, regularize: str = "none",
                   snake_cell: float | None = None, snake_window: int = 3,
                   snake_threshold: float | None = None, snake_sample_step: float = 2.0,
                   within=None) -> TracedOutlines:
    """The first stage of :func:`extract_footprints`: the building field, its regions
    (split at roof steps) and their outlines, to be regularised.

    Parameters and Raises as :func:`extract_footprints` (without ``callback``).

    Returns
    -------
    TracedOutlines
        For :func:`regularise_outlines` (any subset of the parts, anywhere) and
        :func:`assemble_footprints`.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    cls = np.asarray(classification)
    if xyz.ndim != 2 or xyz.shape[1] not in (2, 3):
        raise InputError(f"xyz must have shape (N, 3) or (N, 2), got {xyz.shape}")
    if cls.shape != (len(xyz),):
        raise InputError(f"classification has shape {cls.shape}, expected ({len(xyz)},)")
    if regularize not in REGULARIZERS:
        raise InputError(f"regularize must be one of {', '.join(REGULARIZERS)}, got {regularize!r}")
    FootprintsConfig(building_class=building_class, cell=cell, sigma=sigma,
                     void_distance=void_distance, min_area=min_area,
                     min_hole_area=min_hole_area, split_step=split_step,
                     split_min_area=split_min_area, edge_offset=edge_offset, simplify=simplify,
                     regularize=regularize, snake_cell=snake_cell, snake_window=snake_window,
                     snake_threshold=snake_threshold, snake_sample_step=snake_sample_step)
    if not np.isfinite(xyz).all():
        raise InputError("point coordinates contain NaN or infinite values")
    xy = xyz[:, :2]
    is_b = cls == building_class
    bxy, oxy = xy[is_b], xy[~is_b]
    if len(bxy) < 3:
        raise EmptyInputError(f"no building points (class {building_class}) in the input")
    # the distinct positions, found once: the spacing counts them, the scan-line test
    # looks at them (a first/last-pulse survey stores a one-echo pulse twice)
    positions = distinct_positions(bxy)
    spacing = point_spacing(bxy, distinct=len(positions))
    # scan lines far closer along than across: the grid must bridge the gap between
    # lines, or every line over a roof is a footprint of its own (8:1 at 8 pts/m2)
    gap = scan_line_gap(positions, spacing, distinct=True)
    if gap is not None:
        logger.info("building points in scan lines %.2f m apart: spacing %.3f m taken as %.3f m",
                    gap, spacing, max(spacing, 0.75 * gap))
        spacing = max(spacing, 0.75 * gap)
    L = grid_lengths(spacing, cell=cell, sigma=sigma, void_distance=void_distance,
                     simplify=simplify, snake_cell=snake_cell)
    logger.info("building point spacing %.3f m; cell %.3f m, sigma %.3f m, void %.2f m",
                spacing, L["cell"], L["sigma"], L["void_distance"])
    span = np.ptp(bxy, axis=0) / L["cell"]
    if not np.prod(span + 1.0) <= MAX_GRID_CELLS:
        raise InputError(f"the building points span {np.ptp(bxy[:, 0]):.0f} m x "
                         f"{np.ptp(bxy[:, 1]):.0f} m at a spacing of {spacing:.3g} m: too large a "
                         f"grid of {L['cell']:.3g} m cells (check the coordinates, or process the "
                         "area in smaller blocks)")
    pad = int(np.ceil((3 * L["sigma"] + L["void_distance"]) / L["cell"])) + 2
    grid = Grid.around(bxy, L["cell"], pad=pad)
    inside = ((oxy[:, 0] >= grid.x0) & (oxy[:, 1] >= grid.y0)
              & (oxy[:, 0] < grid.x0 + grid.shape[1] * grid.cell)
              & (oxy[:, 1] < grid.y0 + grid.shape[0] * grid.cell))
    fld = building_fraction(grid, bxy, oxy[inside], sigma=L["sigma"],
                            void_distance=L["void_distance"])
    regions, _ = building_regions(fld, L["cell"], min_area=min_area, min_hole_area=min_hole_area)
    labels = regions
    if split_step > 0 and xyz.shape[1] == 3:
        labels = split_at_steps(regions, cell_heights(grid, xyz[is_b]), L["cell"],
                                step=split_step, min_area=max(split_min_area, min_area))
    # the connected region of each part: parts of one region share edges
    region_of = np.zeros(int(labels.max()) + 1, dtype=np.int64)
    region_of[labels[labels > 0]] = regions[labels > 0]
    traced = trace_regions(fld, labels, grid, min_hole_area=min_hole_area)
    if within is not None:
        traced = _near(traced, region_of, within,
                       regularised_reach(L, window=snake_window) + abs(edge_offset))
    bi, bj = grid.index(bxy)
    point_counts = np.bincount(labels[bi, bj], minlength=int(labels.max()) + 1)

    threshold = (snake_threshold if snake_threshold is not None
                 else 2.0 * snake_window * L["snake_cell"])
    parts, of_traced, n_points = [], [], []
    for n, (label, poly) in enumerate(traced):
        pieces = _parts(poly.buffer(edge_offset, join_style="mitre") if edge_offset else poly,
                        min_area)
        for part in pieces:
            parts.append(part)
            of_traced.append(n)
            n_points.append(int(point_counts[label]) if len(pieces) == 1 else
                            int(np.count_nonzero(_contains(part, bxy))))
    labels_of = np.array([label for label, _ in traced], dtype=np.int64)
    of_traced = np.array(of_traced, dtype=np.int64)
    return TracedOutlines(
        parts, of_traced, region_of[labels_of[of_traced]] if len(of_traced) else of_traced,
        np.array(n_points, dtype=np.int64), len(traced),
        {"regularize": regularize, "cell": L["snake_cell"], "window": snake_window,
         "tolerance": L["simplify"], "t_adjust": threshold, "sample_step": snake_sample_step,
         "min_area": min_area})


def regularise_outlines(outlines: TracedOutlines, parts=None) -> list[Footprint]:
    """The second stage of :func:`extract_footprints`: the outlines ``parts`` (indices
    into ``outlines.parts``; default all) regularised, each on its own (a part's
    footprint depends on no other part: any subset gives the same footprints).

    A part whose regulariser fails keeps its simplified outline, with status
    ``"unregularised"`` and the failure as its reason.

    Returns
    -------
    list of Footprint
        One per part, in the order of ``parts``.
    """
    st = outlines.settings
    regularizer = REGULARIZERS[st["regularize"]]
    out = []
    for k in (range(len(outlines)) if parts is None else parts):
        part = outlines.parts[k]
        # each regulariser simplifies the outline if it uses the simplified one
        try:
            reg, info = regularizer(part, cell=st["cell"], window=st["window"],
                                    tolerance=st["tolerance"], t_adjust=st["t_adjust"],
                                    sample_step=st["sample_step"])
            if reg is None or reg.is_empty or not reg.is_valid or reg.geom_type != "Polygon":
                raise AlgorithmError("the regulariser returned no valid polygon")
        except AlgorithmError as exc:
            reg, info = REGULARIZERS["none"](part, tolerance=st["tolerance"])
            info.update(status="unregularised", reason=str(exc))
        if info["status"] != "ok":
            logger.info("footprint %d kept unregularised: %s",
                        k if outlines.numbers is None else int(outlines.numbers[k]),
                        info["reason"])
        attrs = {
            "area": float(reg.area),
            "direction": float(info["direction"]),
            "n_vertices": int(info["n_vertices"]),
            "mean_deviation": float(info["mean_deviation"]),
            "n_points": int(outlines.n_points[k]),
            **{f"type_{t.lower()}": int(info["reductions"].get(t, 0))
               for t in ("I", "II", "III", "IV")},
        }
        out.append(Footprint(reg, info["status"], info["reason"], attrs))
    return out


def assemble_footprints(outlines: TracedOutlines, footprints) -> list[Footprint]:
    """The last stage of :func:`extract_footprints`: ``footprints`` (one per part of
    ``outlines``, in their order, from :func:`regularise_outlines`) with the
    overlaps between parts of one region removed (the larger keeps the shared
    edge; a part left under ``min_area`` is dropped)."""
    footprints = list(footprints)
    if len(footprints) != len(outlines):
        raise InputError(f"{len(footprints)} footprints for {len(outlines)} outlines")
    return _disjoint(footprints, outlines.regions, outlines.settings["min_area"])


def regularised_reach(lengths: dict, *, window: int) -> float:
    """How far (m) a regularised outline may lie outside its traced outline, with margin.

    The snake moves each vertex of the Douglas-Peucker outline (traced vertices)
    to a grid position at most ``window + 1`` cells of ``snake_cell`` away on each
    axis, and its refit moves it at most ``window + 1`` cells more: under
    ``(sqrt(2) + 1) (window + 1) snake_cell``, taken as ``4 (window + 1) snake_cell``;
    a fallback's simplified outline moves a vertex at most ``3 simplify``. The
    reach is twice their sum plus one grid ``cell``, lengths from
    :func:`grid_lengths`.
    """
    snake = 4.0 * (window + 1) * lengths["snake_cell"]
    return 2.0 * (snake + 3.0 * lengths["simplify"] + lengths["cell"])


def _near(traced, region_of, box, reach):
    """The ``(label, polygon)`` of ``traced`` whose connected region's outlines, grown by
    ``reach``, meet ``box``: the others cannot give a footprint centred in it (the
    parts of a region are kept together: each loses what its larger parts cover)."""
    import shapely

    if not traced:
        return traced
    bounds = shapely.bounds(np.array([poly for _, poly in traced], dtype=object))
    reg = region_of[np.array([label for label, _ in traced])]
    x0, y0, x1, y1 = box
    meets = ((bounds[:, 0] - reach <= x1) & (bounds[:, 2] + reach >= x0)
             & (bounds[:, 1] - reach <= y1) & (bounds[:, 3] + reach >= y0))
    keep = np.isin(reg, reg[meets])
    return [t for t, k in zip(traced, keep, strict=True) if k]


def _disjoint(footprints, regions, min_area):
    """The footprints with the overlaps between parts of one region removed: each
    part loses what the larger parts of its region cover (its largest polygon is
    kept; a part left under ``min_area`` is dropped)."""
    import shapely

    regions = np.asarray(regions, dtype=np.int64)
    if len(np.unique(regions)) == len(regions):
        return footprints
    drop = set()
    out = list(footprints)
    for r in np.unique(regions):
        members = np.flatnonzero(regions == r)
        if len(members) < 2:
            continue
        members = sorted(members, key=lambda i: (-out[i].polygon.area, i))
        taken = None
        for i in members:
            poly = out[i].polygon
            if taken is not None and poly.intersects(taken):
                cut = _parts(shapely.difference(poly, taken), 0.0)
                cut = max(cut, key=lambda g: g.area) if cut else None
                if cut is None or cut.area < max(min_area, 1e-9):
                    drop.add(i)
                    continue
                poly = shapely.Polygon(cut.exterior, list(cut.interiors))
                out[i] = Footprint(poly, out[i].status, out[i].reason,
                                   {**out[i].attributes, "area": float(poly.area),
                                    "n_vertices": vertex_count(poly)})
            taken = poly if taken is None else shapely.union(taken, poly)
    return [f for i, f in enumerate(out) if i not in drop]


def _contains(polygon, xy):
    import shapely

    return shapely.contains_xy(polygon, xy[:, 0], xy[:, 1])
