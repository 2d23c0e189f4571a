"""The block planner: tiles and footprints to an ordered list of block specs.

A block is a cell of a square grid of ``block_size`` metres aligned on the
CRS's origin (not on the tiles). A building belongs to the block holding the
centre of its footprint's bounding box. A :class:`BlockSpec` is plain,
picklable data: the world box whose points the block reads, the headers of
the tiles that meet it (paths, not points), and the block's footprints (or,
without footprints, the grid cell to trace them in). Specs are numbered in a
fixed order (grid rows south to north, west to east), and the output is
assembled in that order whichever executor ran them and in whichever order
they finished. :func:`lidar2city.tools.task.run_block` is what runs a spec.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BlockSpec", "Frame", "FootprintRef", "footprint_blocks", "traced_blocks", "block_keys",
           "split_size", "SPLIT_LEAST", "traced_parts", "BLOCK_POINTS", "footprint_block_size",
           "meet_blocks", "meet_size", "MEET_SHARE", "MEET_PARTS"]


@dataclass(frozen=True, eq=False)
class Frame:
    """The run's local frame: world origin (CRS units), CRS and metres per CRS unit."""

    origin: np.ndarray
    crs: object
    xy_unit: float
    z_unit: float

    @classmethod
    def of(cls, reader) -> Frame:
        return cls(np.array(reader.origin, dtype=np.float64), reader.crs, reader.xy_unit,
                   reader.z_unit)

    def to_world(self, local_box) -> tuple:
        """A local ``(xmin, ymin, xmax, ymax)`` box in world CRS units."""
        o = np.asarray(self.origin[:2])
        box = np.asarray(local_box, dtype=np.float64)
        return tuple(float(v) for v in np.concatenate([o + box[:2] / self.xy_unit,
                                                       o + box[2:] / self.xy_unit]))


@dataclass(frozen=True, eq=False)
class BlockSpec:
    """One task: a block of the grid, as plain data.

    Attributes
    ----------
    index : int
        Position in the run's fixed block order.
    cell : (int, int)
        Grid cell ``(col, row)`` on the CRS origin.
    world_box : tuple of 4 float or None
        World box whose points the block reads; None when it has nothing to read
        (all its footprints are empty).
    tiles : tuple of TileInfo
        Headers of the tiles meeting ``world_box``.
    frame : Frame
    footprints : FootprintRef, Footprints or None
        The block's footprints (read by the worker from the file); None: trace
        them in the cell; a :class:`~lidar2city.datamodel.Footprints` (local,
        with their output positions in ``_index``): those a first pass traced
        in the cell (:func:`traced_parts`), carried inline.
    traced : bool
        ``footprints`` were traced by the run: no points are claimed for them
        (the block that traces them builds them as traced, unclaimed).
    cost : float or None
        The block's expected work in buildings, for cutting the run into
        tasks of equal work; None: its number of footprints.
    """

    index: int
    cell: tuple
    world_box: tuple | None
    tiles: tuple
    frame: Frame
    footprints: object = None
    traced: bool = False
    cost: float | None = None

    @property
    def size(self) -> int:
        """Buildings known before the block runs (0 when traced)."""
        return 0 if self.footprints is None else len(self.footprints)

    @property
    def work(self) -> float:
        """The block's expected work (:attr:`cost`, else its footprints, at least 1)."""
        return float(self.cost) if self.cost is not None else float(max(self.size, 1))


def block_keys(centres_local, frame: Frame, block_size: float) -> np.ndarray:
    """Grid cell (on the CRS's origin) of local points: ``(col, row)`` per point."""
    world = np.asarray(frame.origin[:2]) + np.asarray(centres_local, dtype=np.float64) / frame.xy_unit
    return np.floor(world / (block_size / frame.xy_unit)).astype(np.int64)


def _tiles_meeting(tiles, box):
    if box is None:
        return ()
    x0, y0, x1, y1 = box
    return tuple(t for t in tiles if t.count and not (t.maxs[0] < x0 or t.mins[0] > x1
                                                      or t.maxs[1] < y0 or t.mins[1] > y1))


@dataclass(frozen=True, eq=False)
class FootprintRef:
    """A block's footprints by reference: the worker reads them from the file.

    Attributes
    ----------
    path, layer, id_field
        The footprint source, as given to ``reconstruct``.
    fids : tuple of int
        OGR feature ids of the block's footprints, in the file's order.
    ids : tuple of str
        Their building ids (made unique over the whole file by the planner).
    positions : tuple of int
        Their positions in the run's output order.
    """

    path: str
    layer: object
    id_field: str | None
    fids: tuple
    ids: tuple
    positions: tuple

    def __len__(self) -> int:
        return len(self.fids)


def footprint_blocks(tiles, frame: Frame, bounds, block_size: float, margin: float,
                     footprints, *, split: int | None = None, meet: int | None = None) -> list:
    """Specs of the blocks of footprints given by their local ``bounds``, row by row.

    Parameters
    ----------
    bounds : ndarray, shape (N, 4)
        Local ``(xmin, ymin, xmax, ymax)`` of each footprint in output order
        (NaN for an empty one: it goes to the block of the origin).
    footprints : callable
        ``footprints(idx)``: what a spec carries for the footprints ``idx``
        (positions, in order), e.g. a :class:`FootprintRef`.
    split : int, optional
        Cut a block of more than ``split`` footprints into ``ceil(n / split)``
        parts (:func:`_split_parts`: strips across the block's longer side of
        decreasing expected work, :func:`footprint_work`, which each part
        carries as its :attr:`BlockSpec.cost`), each a spec of its own reading
        its footprints' box plus ``margin``, so that several processes can
        share one block's buildings (a single large tile). Only for blocks
        whose buildings do not depend on one another's points (given
        footprints on classified points: :func:`lidar2city.tools.task.splittable`);
        None (default): a block is one spec.
    meet : int, optional
        With ``split``: the processes that will share the blocks in contiguous
        shares of equal work (:class:`lidar2city.tools.engine.RunDealer`; ``meet``
        - 1 places where two sides meet). A block of at most ``split`` footprints
        whose footprints in the blocks' order reach within :data:`MEET_SHARE` of
        the total of such a place is cut too, into equal strips of at most
        :func:`meet_size` footprints (:func:`meet_blocks`): a side that ends its
        share there takes small parts of the other's, not a whole block.
    """
    bounds, centre, empty, cells, which, blocks = _footprint_cells(bounds, frame, block_size)
    work = footprint_work(bounds) if split is not None else None
    near = (meet_blocks([len(b) for b in blocks], meet)
            if split is not None and meet is not None and meet > 1 else set())
    fine = meet_size(len(bounds), meet) if near else None
    specs = []
    for k, block in enumerate(blocks):
        row, col = cells[which[block[0]]]
        if k in near and len(block) <= split:
            parts = _split_parts(block, centre, empty, fine, work, ramp=1.0)
        else:
            parts = _split_parts(block, centre, empty, split, work)
        for idx in parts:
            b = bounds[[i for i in idx if not empty[i]]]
            world = None
            if len(b):
                world = frame.to_world([b[:, 0].min() - margin, b[:, 1].min() - margin,
                                        b[:, 2].max() + margin, b[:, 3].max() + margin])
            specs.append(BlockSpec(len(specs), (int(col), int(row)), world,
                                   _tiles_meeting(tiles, world), frame, footprints(idx),
                                   cost=float(work[idx].sum()) if len(parts) > 1 else None))
    return specs


def _footprint_cells(bounds, frame: Frame, block_size: float) -> tuple:
    """``(bounds, centres, empty, cells, which, blocks)``: the footprints' grid cells
    (``cells`` row by row, y then x; ``which`` cell of each footprint) and the
    positions of each cell's footprints (``blocks``, in footprint order)."""
    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 4)
    centre = np.column_stack([(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2])
    empty = ~np.isfinite(centre).all(axis=1)
    keys = block_keys(np.where(empty[:, None], 0.0, centre), frame, block_size)
    # group by block, row by row (y, then x); footprint order kept inside a block
    cells, which = np.unique(keys[:, ::-1], axis=0, return_inverse=True)
    which = np.asarray(which).reshape(-1)
    order = np.argsort(which, kind="stable")
    cuts = np.flatnonzero(np.diff(which[order])) + 1
    return bounds, centre, empty, cells, which, np.split(order, cuts)


#: the most tile points a block of given footprints should read
#: (:func:`footprint_block_size`): held compact while the block runs (17 bytes a
#: point, ~34 MB), besides the decoded tiles it reads them from. Delft (640,510
#: points) stays one 1 km block; on 4 x 4 copies of it (10.2 M points) 1 km
#: blocks read up to ~4 M points each (peak RSS 263 MB), 250 m blocks ~1.3 M
BLOCK_POINTS = 2_000_000


def footprint_block_size(tiles, frame: Frame, bounds, margin: float, largest: float, *,
                         budget: int | None = None) -> float:
    """The block size of a run of given footprints: ``largest``, halved while a block
    would read more than ``budget`` tile points, not below ``2 * margin`` (a block
    smaller than the margin its buildings read around them reads mostly its
    neighbours' points again).

    A block's points are estimated from the tile headers (each tile's points
    spread evenly over its header box) within the box the block reads (its
    footprints' box plus ``margin``, :func:`footprint_blocks`). With given
    footprints a building's points do not depend on its block, so neither
    does the output: the size only bounds what a block holds at once.

    Parameters
    ----------
    tiles : sequence of TileInfo
    bounds : ndarray, shape (N, 4)
        Local bounds of the footprints (NaN for an empty one).
    margin : float
        What a building reads around its footprint's box (m).
    largest : float
        The largest (and first tried) block size (m).
    budget : int, optional
        The most points a block should read (default :data:`BLOCK_POINTS`).

    Returns
    -------
    float
    """
    budget = BLOCK_POINTS if budget is None else budget
    full = [t for t in tiles if t.count]
    if not full:
        return float(largest)
    lo = np.array([t.mins[:2] for t in full], dtype=np.float64)
    hi = np.array([t.maxs[:2] for t in full], dtype=np.float64)
    count = np.array([t.count for t in full], dtype=np.float64)
    size = float(largest)
    while size / 2 >= 2 * margin and _most_points(lo, hi, count, frame, bounds, size,
                                                  margin) > budget:
        size /= 2
    return size


def _most_points(lo, hi, count, frame, bounds, block_size, margin) -> float:
    """The most tile points (by the headers, spread evenly) a block of ``block_size``
    reads."""
    bounds, _, empty, _, _, blocks = _footprint_cells(bounds, frame, block_size)
    o, u = np.asarray(frame.origin[:2]), frame.xy_unit
    most = 0.0
    for block in blocks:
        b = bounds[block[~empty[block]]]
        if not len(b):
            continue
        x0, y0 = o + (b[:, :2].min(axis=0) - margin) / u
        x1, y1 = o + (b[:, 2:].max(axis=0) + margin) / u
        w = np.clip(np.minimum(hi[:, 0], x1) - np.maximum(lo[:, 0], x0), 0.0, None)
        h = np.clip(np.minimum(hi[:, 1], y1) - np.maximum(lo[:, 1], y0), 0.0, None)
        span = hi - lo
        # the share of a tile's box inside the block's (a box without width: all of it)
        fx = np.where(span[:, 0] > 0, w / np.where(span[:, 0] > 0, span[:, 0], 1.0), 1.0)
        fy = np.where(span[:, 1] > 0, h / np.where(span[:, 1] > 0, span[:, 1], 1.0), 1.0)
        meets = (hi[:, 0] >= x0) & (lo[:, 0] <= x1) & (hi[:, 1] >= y0) & (lo[:, 1] <= y1)
        most = max(most, float((count * np.where(meets, fx * fy, 0.0)).sum()))
    return most


#: the fewest footprints a part of a split block holds (:func:`split_size`):
#: each part reads its box and builds its buildings' surroundings on its own
SPLIT_LEAST = 8


def split_size(total: int, runs: int) -> int | None:
    """The most footprints a block part may hold so that ``total`` footprints
    make at least ``runs`` tasks of similar size (an executor's runs, e.g. 4
    per worker), and at least :data:`SPLIT_LEAST`; None for one run (one
    process: no block is split)."""
    if runs <= 1 or total <= 0:
        return None
    return max(SPLIT_LEAST, -(-int(total) // int(runs)))


#: a block cut into parts for several workers is cut into strips of decreasing
#: expected work, the first ``RAMP`` times the last (:func:`_weighted_parts`), handed
#: out largest first to whichever worker is free: the large parts keep the workers
#: busy, the small last ones even out their ends (with parts of equal work one
#: worker could wait a whole part for the other at the end of the run)
RAMP = 3.0


#: the share of the total footprints on either side of a place where two workers'
#: shares meet within which a block is cut into small parts (:func:`meet_blocks`)
MEET_SHARE = 0.1
#: parts per worker a block where two shares meet is cut to (:func:`meet_size`)
MEET_PARTS = 16


def meet_blocks(sizes, workers: int) -> set:
    """The blocks (positions in ``sizes``, each block's footprints, in the blocks'
    order) that hold footprints within :data:`MEET_SHARE` of the total of a place
    where the contiguous shares of ``workers`` processes meet (``k / workers`` of
    the total, ``k`` = 1 .. ``workers`` - 1): where one side, its share done, takes
    the other's blocks from the far end. The tail of a run is the rest of the block
    the other side is running then: a block of 4 x 4 Delft copies' 250 m grid
    holds up to 226 buildings, ~10 % of the run's CPU."""
    sizes = np.asarray(sizes, dtype=np.float64)
    if workers < 2 or not len(sizes) or not sizes.sum() > 0:
        return set()
    end = np.cumsum(sizes)
    start = end - sizes
    total = float(end[-1])
    out = set()
    for k in range(1, int(workers)):
        lo, hi = total * (k / workers - MEET_SHARE), total * (k / workers + MEET_SHARE)
        out.update(np.flatnonzero((end > lo) & (start < hi) & (sizes > 0)).tolist())
    return out


def meet_size(total: int, workers: int) -> int:
    """The most footprints of a part of a block cut where shares meet
    (:func:`meet_blocks`): ``total / (workers x MEET_PARTS)``, at least
    :data:`SPLIT_LEAST`."""
    return max(SPLIT_LEAST, -(-int(total) // (int(workers) * MEET_PARTS)))


def _split_parts(block, centre, empty, split, weights=None, *, ramp: float | None = None) -> list:
    """A block's footprint positions (in order) cut into ``ceil(n / split)`` parts
    for several workers: strips across its longer side (by their centres; ties
    and empty footprints in footprint order) of decreasing total ``weights``
    (each footprint's expected work, default 1: numbers of footprints), the first
    :data:`RAMP` times the last, each part in footprint order; ``[block]`` when it
    is not cut (``split`` None, or a block of at most ``split`` footprints)."""
    idx = np.asarray(block, dtype=np.int64)
    if split is None or len(idx) <= split:
        return [idx.tolist()]
    k = -(-len(idx) // int(split))
    w = (np.ones(int(idx.max()) + 1 if len(idx) else 0) if weights is None
         else np.asarray(weights, dtype=np.float64))
    return _weighted_parts(idx, centre, empty, w, k, ramp=RAMP if ramp is None else ramp)


def footprint_work(bounds) -> np.ndarray:
    """Each footprint's expected work, in buildings (mean 1), from its local
    ``bounds`` (N, 4): half a building's count, half its box's area (a building's
    work grows with its points; the box is what the plan knows of it). An empty
    footprint (NaN bounds) counts as half a building."""
    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 4)
    area = np.nan_to_num((bounds[:, 2] - bounds[:, 0]) * (bounds[:, 3] - bounds[:, 1]), nan=0.0)
    mean = float(area.mean()) if len(area) else 0.0
    return 0.5 + (0.5 * area / mean if mean > 0 else 0.5)


def traced_parts(spec, bounds, margin: float, weights, share: float, footprints,
                 start: int) -> list:
    """Specs of the parts of a traced block (``spec``, from :func:`traced_blocks`)
    whose footprints a first pass traced, numbered from ``start``.

    Parameters
    ----------
    bounds : ndarray, shape (N, 4)
        Local bounds of the block's traced footprints, in their order.
    margin : float
        What a building reads around its footprint's box (m).
    weights : ndarray, shape (N,)
        Each footprint's expected work (e.g. its area: a building's cost grows
        with its points), in buildings.
    share : float
        The most work a part should hold: the block is cut into strips
        across its longer side of about equal work (:func:`_weighted_parts`),
        each part carrying its work as :attr:`BlockSpec.cost`. Not of decreasing
        work (:data:`RAMP`), as the parts of given footprints: a traced building
        may weigh as much as a part, and a strip past its share by one such
        building left one part of 7 with 30 % of the block's CPU (Delft, 2
        workers: the busier worker 8.1 against 8.0 CPU s with equal strips).
    footprints : callable
        ``footprints(idx)``: what a part carries for the footprints ``idx``.

    Each part reads its footprints' box plus ``margin`` within the block's own
    box: every box a building queries (its footprint's box plus at most
    ``margin``) then holds the same points as in the whole block's cloud,
    which is what the block built them from.
    """
    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 4)
    if not len(bounds):
        return []
    centre = np.column_stack([(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2])
    empty = ~np.isfinite(centre).all(axis=1)
    wb = spec.world_box
    weights = np.asarray(weights, dtype=np.float64).reshape(-1)
    k = max(1, int(np.ceil(weights.sum() / share - 1e-9))) if share > 0 else 1
    specs = []
    for idx in _weighted_parts(np.arange(len(bounds)), centre, empty, weights, k):
        b = bounds[[i for i in idx if not empty[i]]]
        world = None
        if len(b):
            w = spec.frame.to_world([b[:, 0].min() - margin, b[:, 1].min() - margin,
                                     b[:, 2].max() + margin, b[:, 3].max() + margin])
            world = (max(w[0], wb[0]), max(w[1], wb[1]), min(w[2], wb[2]), min(w[3], wb[3]))
        specs.append(BlockSpec(start + len(specs), spec.cell, world, _tiles_meeting(spec.tiles, world),
                               spec.frame, footprints(idx), traced=True,
                               cost=float(weights[idx].sum())))
    return specs


def _weighted_parts(idx, centre, empty, weights, k: int, *, ramp: float = 1.0) -> list:
    """Footprint positions ``idx`` cut into at most ``k`` strips across their longer
    side (by their centres, ties and empty footprints in footprint order) of
    about equal total ``weights`` (indexed by position), each part in footprint
    order; ``ramp`` > 1: strips of decreasing totals instead, the first ``ramp``
    times the last (linearly in between)."""
    idx = np.asarray(idx, dtype=np.int64)
    if k <= 1 or len(idx) <= 1:
        return [idx.tolist()]
    c = centre[idx]
    ok = ~empty[idx]
    span = (np.ptp(c[ok], axis=0) if ok.any() else np.zeros(2))
    axis = int(span[1] > span[0])
    along = idx[np.lexsort((idx, np.where(ok, c[:, axis], -np.inf)))]
    cum = np.cumsum(weights[along])
    shares = np.cumsum(np.linspace(float(ramp), 1.0, k))
    # a strip ends with the footprint that brings it past its share of the total
    ends = np.searchsorted(cum, cum[-1] * shares[:-1] / shares[-1], side="left") + 1
    cuts = np.unique(np.concatenate([[0], np.clip(ends, 1, len(along)), [len(along)]]))
    return [np.sort(along[a:b]).tolist() for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


#: points per square metre of a tile's header box under which the box is taken
#: to be blown up by stray returns: its blocks are the cells its points occupy
SPARSE_HEADER_DENSITY = 1e-3


def traced_blocks(tiles, frame: Frame, world_bounds, block_size: float, buffer: float) -> list:
    """Specs of every cell of the tiles' extent, row by row, to trace footprints in
    (the cell plus ``buffer`` metres is read; those centred in the cell are kept).

    A tile whose header box spans several cells with fewer than
    :data:`SPARSE_HEADER_DENSITY` points per square metre (a few stray returns
    kilometres off) gives only the cells its points occupy and their neighbours
    (its points are read for this), not every cell of its box.
    """
    step = block_size / frame.xy_unit
    k0 = np.floor(np.asarray(world_bounds[:2]) / step).astype(np.int64)
    k1 = np.floor(np.asarray(world_bounds[2:]) / step).astype(np.int64)
    pad = buffer / frame.xy_unit
    cells = _sparse_cells(tiles, frame, step)
    if cells is None:
        cells = _tile_cells(tiles, step)
    # only the cells the tiles' boxes meet (tiles far apart, e.g. two areas in one
    # folder, do not make every cell between them a block), within the extent
    cells = [(r, c) for r, c in cells if k0[1] <= r <= k1[1] and k0[0] <= c <= k1[0]]
    specs = []
    for row, col in cells:
        world = (col * step - pad, row * step - pad, (col + 1) * step + pad,
                 (row + 1) * step + pad)
        specs.append(BlockSpec(len(specs), (int(col), int(row)), world,
                               _tiles_meeting(tiles, world), frame))
    return specs


def _tile_cells(tiles, step) -> list:
    """``(row, col)`` of the cells the header boxes of the tiles with points meet, in
    row order."""
    cells = set()
    for t in tiles:
        if not t.count:
            continue
        lo = np.floor(np.asarray(t.mins[:2]) / step).astype(np.int64)
        hi = np.floor(np.asarray(t.maxs[:2]) / step).astype(np.int64)
        cells.update((int(r), int(c)) for r in range(lo[1], hi[1] + 1) for c in range(lo[0], hi[0] + 1))
    return sorted(cells)


def _sparse_cells(tiles, frame, step):
    """``(row, col)`` of the cells to trace when a tile's header box is nearly empty, in
    row order; None when no tile is (every cell of the extent is traced)."""
    from ..io.las import occupied_cells

    def box_cells(t):
        lo = np.floor(np.asarray(t.mins[:2]) / step).astype(np.int64)
        hi = np.floor(np.asarray(t.maxs[:2]) / step).astype(np.int64)
        return lo, hi

    full = [t for t in tiles if t.count]
    sparse = []
    for t in full:
        lo, hi = box_cells(t)
        area = float(np.prod((np.asarray(t.maxs[:2]) - t.mins[:2]) * frame.xy_unit))
        if np.prod(hi - lo + 1) > 4 and t.count < SPARSE_HEADER_DENSITY * area:
            sparse.append(t)
    if not sparse:
        return None
    cells = set()
    for t in full:
        if any(t is u for u in sparse):
            near = occupied_cells(t.path, step)
            ring = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1)])
            cells.update(map(tuple, (near[:, None, :] + ring[None]).reshape(-1, 2)[:, ::-1]))
        else:
            lo, hi = box_cells(t)
            cells.update((r, c) for r in range(lo[1], hi[1] + 1) for c in range(lo[0], hi[0] + 1))
    return sorted((int(r), int(c)) for r, c in cells)
