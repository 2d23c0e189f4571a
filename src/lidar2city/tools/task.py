"""What runs on a worker: one block spec + the run's options -> its buildings.

:func:`run_block` is the one task of ``reconstruct``, pure in what it returns:
it reads the block's points from the tiles named in the spec (paths travel,
not points), classifies them if the run's input is raw, traces footprints if
none were given, and builds every building of the block with
:func:`reconstruct_block` (the per-building step). The same spec and options
give the same results in any process, so the output does not depend on the
executor (:mod:`lidar2city.tools.engine`), the number of workers or the order
in which blocks finish. With several workers and fewer traced blocks than
their runs, :func:`trace_outlines` traces a block first (its outlines
regularised in pieces by all the workers, :func:`regularise_parts`, when they
are many; the footprints :func:`trace_footprints` gives in one pass) and its
buildings are built in parts (specs carrying the traced footprints inline,
built as the block builds them). :func:`trace_block` is the task of ``footprints`` on a
folder of tiles (the same blocks, traced). Decoded tiles are shared by the
blocks a process runs in turn and kept only while its next blocks read them
(:func:`tile_keeper`).
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import EmptyInputError
from ..io.las import DecodedTile, SpilledTile, TileReader
# what a block imports: named in the engine, which the command line asks to start its
# worker server before this module (and NumPy) is imported
from .engine import LOD22_MODULES, WORKER_MODULES, worker_modules  # noqa: F401

logger = logging.getLogger(__name__)

__all__ = ["BlockOptions", "BlockOutput", "block_footprints", "footprint_groups",
           "give_back_memory", "hold_tiles", "predecode", "run_block", "reconstruct_block", "splittable", "tile_keeper",
           "TracedBlock", "worker_modules", "trace_footprints",
           "trace_block", "trace_outlines", "outline_parts", "regularise_parts",
           "staged_footprints", "TracedStage", "OutlineParts", "RegularisedParts"]


@dataclass(frozen=True, eq=False)
class BlockOptions:
    """The run-wide options every block gets (plain, picklable data).

    Attributes
    ----------
    config : Lod1Config
    classified : bool
        Whether the run's input is classified (decided once for all blocks).
    block_size : float
        Grid step (m): traced footprints are kept in the cell holding their centre.
    lod22 : Lod22Config or None
        Build LoD2.2 roofs from the roof topology.
    primitives : PrimitivesConfig or None
        Build LoD2.2 from fitted primitives (``method="primitives"``).
    user_primitives : dict or None
        Footprint id -> primitive and approximate parameters.
    check_images : str or None
        Folder for one PNG per building (primitives); with traced footprints,
        one sub-folder per block (``block_COL_ROW``), their ids being per block.
    footprints_config : config or None
        The ``[footprints]`` stage for tracing footprints.
    edits : tuple of Edit
        The corrections of an ``EDITS.json`` (:mod:`lidar2city.tools.edit`),
        re-applied to their buildings inside the block; empty: none.
    edit_context : EditContext or None
        How the run builds a building, for re-applying ``edits``.
    ground_filter : bool
        The classified input has no ground class anywhere: each block filters its
        ground from the points that are not building points.
    encode : dict or None
        For a streamed CityJSONSeq output of given footprints: the LoDs written
        and the writer's ``scale``, ``xy_unit`` and ``z_unit``; each building's
        feature text is then made in the block (:func:`encode_block`), so the
        run's client only appends text in order. None: the client encodes.
    """

    config: object
    classified: bool
    block_size: float
    lod22: object = None
    primitives: object = None
    user_primitives: dict | None = None
    check_images: str | None = None
    footprints_config: object = None
    edits: tuple = ()
    edit_context: object = None
    encode: dict | None = None
    ground_filter: bool = False
    decoded: tuple = ()


@dataclass(eq=False)
class BlockOutput:
    """The results of one block, in its footprints' order.

    ``points`` says whether the block held building points at all (a run where
    no block does is an error); ``failed``: the task failed twice and every
    building carries that reason; ``worker_mb`` the peak resident memory of
    the process that ran it, ``cpu`` the CPU seconds that process spent on the
    block and ``worker`` which process it was (measures of the run, never written).
    ``encoded``: with :attr:`BlockOptions.encode`, each building's
    ``(feature text, local extent)`` (:func:`encode_block`); None otherwise.
    """

    index: int
    results: list
    footprints: object
    points: bool = False
    failed: bool = False
    worker_mb: float = 0.0
    cpu: float = 0.0
    worker: str = ""
    encoded: list | None = None
    #: a traced block's first stage when its outlines are regularised by all the
    #: workers (:func:`trace_outlines`): ``footprints`` is then None
    staged: object = None


class _TileCache:
    """Decoded tiles shared by the blocks a process runs in turn, kept only while
    a later block of the same run still reads them, and never in memory between
    blocks.

    A run of consecutive blocks (:mod:`lidar2city.tools.engine` gives a process
    runs of neighbouring blocks) first tells the cache its blocks
    (:func:`tile_keeper`). As soon as a block has read its points
    (:meth:`release`), each tile it read is cut down to the points inside the
    boxes of the run's later blocks (the only points they will take from it)
    and written to an unlinked scratch file (:class:`~lidar2city.io.las.SpilledTile`,
    17 bytes a point); a tile no later block reads is dropped. The next block
    that reads the tile loads those points back instead of decoding the LAZ
    again. A tile is decoded about once per run, and the scratch files hold at
    most :data:`KEEP_BLOCKS` times the largest block read (soonest needed
    first), so neither memory nor scratch space grows with the area: what a
    process holds while a block runs is that block's points, compact (17
    bytes a point), and the full-width cloud of one group of its buildings at
    a time (:func:`_run_groups`). Outside a run every tile is dropped after
    its block.
    """

    def __init__(self):
        self.tiles = {}  # key -> DecodedTile (being read) or SpilledTile
        # key -> the blocks (indices) whose boxes the kept points cover; None: all
        self.covers = {}
        self.lock = threading.Lock()
        # path -> [(position in the run, world box, block index)] while a run is on
        self.later = None
        self.position = {}  # block index -> position in the run
        self.decoded = 0
        self.largest = 0  # points of the largest block read
        self.saved = {}  # key -> a file of the tile decoded by the run's client
        # key -> a tile this process decoded before its workers were forked from it
        # (:func:`hold_tiles`): read by the blocks, never cut nor dropped by them
        self.held = {}

    def read(self, n: int) -> None:
        """Note a block's read of ``n`` points."""
        self.largest = max(self.largest, int(n))

    def get(self, tile, decode, index=None):
        """The decoded ``tile`` (``decode()`` when it is not kept, or when what is kept
        was cut without the points of the block ``index``), keyed by its file's
        path, size and modification time."""
        st = os.stat(tile.path)
        key = (tile.path, st.st_size, st.st_mtime_ns)
        with self.lock:
            hit = self.tiles.get(key)
            cover = self.covers.get(key)
            if hit is not None and cover is not None and index not in cover:
                self._drop([key])  # kept for other blocks only: decoded again
                hit = None
            if isinstance(hit, SpilledTile):
                spilled, hit = hit, hit.load()
                spilled.close()
                self.tiles[key] = hit
        if hit is None:
            hit = self.held.get(key)
            if hit is None:
                hit = self._load_saved(key)
            if hit is None:
                hit = decode()
                with self.lock:
                    self.decoded += 1
            with self.lock:
                self.tiles[key] = hit
                self.covers[key] = None
        return hit

    def _load_saved(self, key):
        """The tile ``key`` as the run's client decoded it (:func:`predecode`), or None."""
        path = self.saved.get(key)
        if path is None:
            return None
        from ..io.las import load_tile

        try:
            return load_tile(path)
        except (OSError, ValueError, KeyError) as exc:  # gone or cut short: decoded here
            logger.debug("tile %s not loaded from %s: %s", key[0], path, exc)
            return None

    def holds(self, tile, index=None) -> bool:
        """Whether ``tile`` is kept with the points of the block ``index`` (no decoding)."""
        try:
            st = os.stat(tile.path)
        except OSError:
            return False
        key = (tile.path, st.st_size, st.st_mtime_ns)
        with self.lock:
            cover = self.covers.get(key)
            return key in self.tiles and (cover is None or index in cover)

    def start(self, specs, ahead=()) -> None:
        """A run of ``specs`` begins, to be followed by ``ahead`` (the blocks the
        process expects to run next): index which of these blocks read which
        tile. A tile kept from the previous run stays when one of these blocks
        reads it; a block it was not cut for decodes it again (:meth:`get`)."""
        later = {}
        for k, spec in enumerate([*specs, *ahead]):
            if spec.world_box is not None:
                for t in spec.tiles:
                    later.setdefault(t.path, []).append((k, spec.world_box, spec.index))
        with self.lock:
            for key in list(self.tiles):
                if key[0] not in later:
                    self._drop([key])
            self.later = later
            self.position = {spec.index: k for k, spec in enumerate([*specs, *ahead])}

    def release(self, index, path=None) -> None:
        """The block ``index`` has read its points (from the tile ``path``, default
        all): keep of each tile only what the run's later blocks read, in scratch
        files (see :meth:`keep_after`)."""
        self.keep_after(self.position.get(index, -1) if self.later is not None else None,
                        path=path)

    def keep_after(self, k, path=None) -> None:
        """Keep of each tile (or of the tile ``path``) only what the run's blocks
        after position ``k`` (and the blocks ahead) read from it, written to
        scratch files, soonest needed first, up to :data:`KEEP_BLOCKS` times the
        largest block read (what the next block reads is always kept); ``k``
        None: keep nothing."""
        with self.lock:
            later = self.later or {}
            kept = []
            for key in list(self.tiles):
                if path is not None and key[0] != path:
                    continue
                boxes = [] if k is None else [e for e in later.get(key[0], ()) if e[0] > k]
                if not boxes or key in self.held:  # (a held tile is read again from memory)
                    self._drop([key])
                    continue
                tile = self.tiles[key]
                if isinstance(tile, DecodedTile):  # read by this block: cut and put away
                    # the comparisons of TileReader.box
                    inside = tile.inside([b for _, b, _ in boxes])
                    tile = self.tiles[key] = (tile.take(inside) if not inside.all()
                                              else tile).spill()
                    # the blocks whose points it now holds: those of the boxes, and
                    # of the blocks it held before (a tile loaded back from scratch)
                    cover = frozenset(i for _, _, i in boxes)
                    old = self.covers.get(key)
                    self.covers[key] = cover if old is None else cover & old
                kept.append((boxes[0][0], key, len(tile)))
            # farthest next use out first (Belady) when over the budget
            kept.sort(key=lambda item: (item[0], item[1]))
            budget, total = KEEP_BLOCKS * self.largest, 0
            for first, key, n in kept:
                total += n
                if not (first == k + 1 or total <= budget):
                    self._drop([key])

    def end_run(self, k) -> None:
        """The run is over after its position ``k``: keep only what the blocks ahead read."""
        self.keep_after(k)
        with self.lock:
            self.later = None
            self.position = {}

    def _drop(self, keys) -> None:
        for key in keys:
            tile = self.tiles.pop(key)
            self.covers.pop(key, None)
            if isinstance(tile, SpilledTile):
                tile.close()

    def stop(self) -> None:
        """Drop every tile (no run is on)."""
        with self.lock:
            self._drop(list(self.tiles))
            self.later = None
            self.position = {}

    def points(self) -> int:
        with self.lock:
            return sum(len(tile) for tile in self.tiles.values())

    def after_fork(self) -> None:
        """In a process just forked from this one: a lock of its own (another thread
        may have held the parent's), and none of the tiles kept in scratch files
        (their files' offsets are shared with the parent's): read again if needed.
        The tiles held in memory (:attr:`held`, decoded tiles) are kept, shared
        copy-on-write."""
        self.lock = threading.Lock()
        for key in [k for k, t in self.tiles.items() if isinstance(t, SpilledTile)]:
            del self.tiles[key]  # the parent's file: never closed nor read here
            self.covers.pop(key, None)


#: the tile points a process keeps in scratch files between blocks: at most
#: this many times its largest block read (besides what the next block reads),
#: ~40 MB of scratch space for blocks of 300,000 points; enough for the strip
#: of tiles a row of blocks leaves to the next row on areas tens of blocks wide
KEEP_BLOCKS = 8
_cache = _TileCache()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_cache.after_fork)


#: the most points the run's client decodes for its workers (:func:`predecode`):
#: ~1 CPU-second of decoding, ~70 MB of scratch files
PREDECODE_POINTS = 4_000_000


def predecode(tiles, stack) -> tuple:
    """Decode ``tiles`` once, in the run's client while its local cluster starts,
    for every worker to load instead of decoding them again
    (:attr:`BlockOptions.decoded`): the tiles of a block cut into parts that
    all the workers share, whose first tasks would each decode them.

    Tiles are taken in order while their points add up to at most
    :data:`PREDECODE_POINTS`. Each is saved to a scratch file in the
    temporary folder, registered with ``stack`` (a
    :class:`contextlib.ExitStack`) to be removed when the run ends, or by an
    interrupted run's clean-up. A tile that cannot be decoded is left to the
    blocks, whose failure gives their buildings its reason as before.
    Returns :attr:`BlockOptions.decoded`.
    """
    from ..io._atomic import new_scratch_file, scratch_path
    from ..io.las import save_tile

    out = []
    for key, tile in _decoded_ahead(tiles):
        # named by host and process: a later run removes what a killed one left
        name = new_scratch_file("lidar2city-tile-", ".npz")
        path = str(stack.enter_context(scratch_path(name)))
        save_tile(tile, path)
        del tile
        out.append((key, path))
    return tuple(out)


def _decoded_ahead(tiles):
    """``(key, decoded tile)`` of ``tiles`` in order (each path once) while their points
    add up to at most :data:`PREDECODE_POINTS`; a tile that cannot be decoded is
    skipped, left to the blocks, which state its failure per building."""
    from ..io.las import read_tile

    total = 0
    for t in {t.path: t for t in tiles}.values():
        total += int(t.count)
        if total > PREDECODE_POINTS:
            return
        try:
            st = os.stat(t.path)
            tile = read_tile(t.path)
        except Exception as exc:  # noqa: BLE001 - left to the blocks, which state it per building
            logger.debug("%s not decoded ahead: %s", t.path, exc)
            continue
        yield (t.path, st.st_size, st.st_mtime_ns), tile


def hold_tiles(tiles, stack) -> int:
    """Decode ``tiles`` once, here, for this process and the workers it will fork
    (:class:`lidar2city.tools.forked.ForkExecutor`: they inherit them copy-on-write)
    to read instead of decoding them again: the tiles of a block cut into parts
    that every worker shares (:func:`lidar2city.tools.reconstruct.shared_tiles`).
    As :func:`predecode`, up to :data:`PREDECODE_POINTS` points, a tile that cannot
    be decoded left to the blocks; the tiles are let go when ``stack`` (a
    :class:`contextlib.ExitStack`) closes. Returns the tiles held."""
    held = []
    for key, tile in _decoded_ahead(tiles):
        with _cache.lock:
            _cache.held[key] = tile
        held.append(key)

    def let_go():
        with _cache.lock:
            for key in held:
                _cache.held.pop(key, None)

    stack.callback(let_go)
    return len(held)


def tile_keeper(specs, ahead=()):
    """The run hook of :meth:`lidar2city.tools.engine.InProcess.map` for blocks:
    ``keep(k)`` after the ``k``-th block of the run keeps only the tile points
    the run's next blocks (and the blocks ``ahead``, which the process will
    run next) read; after the last block, only those the blocks ahead read."""
    _cache.start(specs, ahead)
    ended = []

    def keep(k):
        if ended:
            return
        if k >= len(specs) - 1:
            ended.append(k)
            _cache.end_run(k)
        else:
            _cache.keep_after(k)

    return keep


class _SharedTileReader(TileReader):
    """A :class:`TileReader` whose decoded tiles are shared by the blocks of a run;
    each tile is put away (:meth:`_TileCache.release`) as soon as the block ``index``
    has taken its points from it."""

    def __init__(self, tiles, *, origin, index):
        super().__init__(tiles, origin=origin)
        self.index = index
        self.decoded = False

    def _taken(self, k):
        _cache.release(self.index, path=self.tiles[k].path)
        if self.decoded:  # a decoding's transient arrays, freed: not left to pile up
            self.decoded = False
            give_back_memory()

    def _visit_order(self, ks):
        # the tiles to decode first, while the block holds none of its points yet
        # (a decoding needs several times the memory of the points it keeps)
        return sorted(ks, key=lambda k: _cache.holds(self.tiles[k], self.index))

    def _tile(self, k):
        def decode():
            hit = super(_SharedTileReader, self)._tile(k)
            self._tiles.clear()  # held by the shared cache only
            self.decoded = True
            return hit

        return _cache.get(self.tiles[k], decode, self.index)


def _read_parts(spec):
    """``(reader, parts)``: the points of the spec's world box, compact and unordered
    (:meth:`~lidar2city.io.las.TileReader.parts`, shared decoded tiles); None when
    the spec has nothing to read."""
    if spec.world_box is None or not spec.tiles:
        return None
    reader = _SharedTileReader(list(spec.tiles), origin=np.asarray(spec.frame.origin),
                               index=spec.index)
    try:
        parts = reader.parts(*spec.world_box)
        _cache.read(sum(len(p) for p in parts))
    finally:
        _cache.release(spec.index)  # the block runs with its own points only
    return reader, parts


def _read_box(spec, read=None):
    """The points of the spec's world box (shared decoded tiles; ``read``: those of
    :func:`_read_parts` already read), or None when empty."""
    read = _read_parts(spec) if read is None else read
    if read is None:
        return None
    cloud = read[0].cloud(read[1])
    return cloud if len(cloud) else None


def _measured(task, spec, *args):
    """``task(spec, *args)`` with its process's peak memory, CPU seconds and name set
    on the output; outside a run (:func:`tile_keeper`) no decoded tile is kept."""
    t0 = time.process_time()
    try:
        out = task(spec, *args)
    finally:
        if _cache.later is None:  # not in a run: nothing to keep
            _cache.stop()
        give_back_memory()
    out.worker_mb = _peak_mb()
    out.cpu = time.process_time() - t0
    out.worker = f"{socket.gethostname()}:{os.getpid()}"
    return out


def _block_cloud(spec, options, read=None):
    """``(cloud, classes)`` of the spec's world box (``read``: its points already read),
    or ``(None, None)`` without building points."""
    from .reconstruct import point_roles

    cloud = _read_box(spec, read)
    if cloud is None:
        return None, None
    try:
        _, _, classes = point_roles(cloud, options.config, classified=options.classified,
                                    ground_filter=options.ground_filter)
    except EmptyInputError:
        return None, None
    return cloud, classes


def _traced_footprints(spec, options, cloud, classes):
    """The footprints traced in the block's box whose centre lies in its cell, or None."""
    from .reconstruct import footprints_from_points

    try:
        fps = footprints_from_points(cloud, classes, config=options.footprints_config,
                                     within=_cell_box(spec, options.block_size))
    except EmptyInputError:
        return None
    return _in_cell(spec, options, fps, _building_xy(cloud, classes, options))


def _building_xy(cloud, classes, options):
    """The block's building points (x, y), (N, 2): those a traced footprint must hold."""
    return np.ascontiguousarray(
        cloud.xyz[np.isin(classes, options.config.building_classes), :2])


def _in_cell(spec, options, fps, building_xy):
    """Of the block's traced footprints ``fps``, those whose centre lies in its cell
    and that hold at least ``lod1.min_points`` of the ``building_xy``; None if none."""
    from .blocks import block_keys
    from .reconstruct import _subset

    bounds = np.array([g.bounds for g in fps.geometries], dtype=np.float64).reshape(-1, 4)
    centre = np.column_stack([(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2])
    keys = block_keys(centre, spec.frame, options.block_size)
    idx = [i for i in range(len(fps)) if (keys[i, 0], keys[i, 1]) == tuple(spec.cell)]
    # a traced region holding fewer building points than a model needs (lod1.min_points)
    # is no building found: at 1 pts/m2 the tracer's smallest regions (4 m2) hold a
    # handful, and each came out as a failed building ('too few points (1 < 10)')
    cfg = options.config
    held = _points_inside(building_xy, [fps.geometries[i] for i in idx])
    small = [i for i, n in zip(idx, held, strict=True) if n < cfg.min_points]
    if small:
        logger.info("%d traced region(s) with fewer than %d building points left out",
                    len(small), cfg.min_points)
        idx = [i for i in idx if i not in small]
    return _subset(fps, idx) if idx else None


def _cell_box(spec, block_size: float) -> tuple:
    """The local box of the spec's cell of the ``block_size`` grid: the buildings
    traced there are those centred in it, and the regions far outside it are not
    regularised (the box read around a cell is mostly other cells', which trace
    their own buildings)."""
    frame = spec.frame
    step = block_size / frame.xy_unit
    o = np.asarray(frame.origin[:2], dtype=np.float64)
    cell = np.asarray(spec.cell, dtype=np.float64)
    return tuple(float(v) for v in np.concatenate([(cell * step - o) * frame.xy_unit,
                                                   ((cell + 1) * step - o) * frame.xy_unit]))


def _block_traced(spec, options, cloud, classes):
    """The block's traced footprints (:func:`_traced_footprints`), numbered ``b1``,
    ``b2``... in the block; none without building points."""
    return _numbered(None if cloud is None else _traced_footprints(spec, options, cloud, classes))


def _numbered(fps):
    """``fps`` (or None: none) with the ids ``b1``, ``b2``... of a block's traced footprints."""
    from ..datamodel import Footprints

    if fps is None:
        return Footprints([], [])
    return Footprints(fps.geometries, [f"b{j + 1}" for j in range(len(fps))], fps.attributes)


def trace_footprints(spec, options: BlockOptions) -> BlockOutput:
    """The first pass of a traced block shared by several workers: its footprints
    (:func:`_block_traced`, the block's own cloud and classes, as
    :func:`run_block` traces them) in ``footprints``, no results; the
    buildings are then built in parts (:func:`lidar2city.tools.blocks.traced_parts`)."""
    _cache.saved = dict(options.decoded)
    return _measured(_trace_footprints, spec, options)


def _trace_footprints(spec, options):
    cloud, classes = _block_cloud(spec, options)
    return BlockOutput(spec.index, [], _block_traced(spec, options, cloud, classes),
                       cloud is not None)


#: a traced block whose first pass finds fewer outlines than this regularises them
#: there (:func:`trace_outlines`): sharing so few among the workers would not pay
#: for a second round of the executor. On Delft an outline's regularisation takes
#: ~1.3 ms + 0.1 ms per vertex (~22 ms on average, 1.7 CPU s for 80); the second
#: round (a fork, the pieces sent and returned) cost ~0.09 CPU s on a 75 m corner
#: of the tile (``benchmarks/bench_traced_outlines.py --areas clip --least 1``)
STAGED_LEAST = 24


@dataclass(eq=False)
class TracedStage:
    """A traced block's first stage (:func:`trace_outlines`): its ``outlines``
    (:class:`lidar2city.footprints.extract.TracedOutlines`), to be regularised by
    all the workers (:func:`regularise_parts`), and what its last stage
    (:func:`staged_footprints`) needs: the block's building points ``building_xy``."""

    outlines: object
    building_xy: np.ndarray


@dataclass(eq=False)
class OutlineParts:
    """Some outlines of a traced block to regularise (:func:`regularise_parts`):
    the block's position ``block`` in the run, the outlines' positions ``parts``
    in the block's outlines, and ``outlines``, those outlines only."""

    block: int
    parts: tuple
    outlines: object
    work: float = 0.0


@dataclass(eq=False)
class RegularisedParts:
    """The footprints of an :class:`OutlineParts`, in its order, and the measures of
    the process that made them (as :class:`BlockOutput`'s)."""

    block: int
    parts: tuple
    footprints: list
    worker_mb: float = 0.0
    cpu: float = 0.0
    worker: str = ""


def trace_outlines(spec, options: BlockOptions, least: int | None = None) -> BlockOutput:
    """The first pass of a traced block whose outlines the workers share: its outlines
    (:func:`lidar2city.footprints.extract.trace_outlines`, the block's own cloud
    and classes, as :func:`run_block` traces them) in ``staged``
    (a :class:`TracedStage`); with fewer than ``least`` (default
    :data:`STAGED_LEAST`) outlines, its footprints as :func:`trace_footprints`
    gives them (regularised here: one pass)."""
    _cache.saved = dict(options.decoded)
    return _measured(_trace_outlines, spec, options, STAGED_LEAST if least is None else least)


def _trace_outlines(spec, options, least):
    import dataclasses

    from ..footprints.extract import regularise_outlines, trace_outlines
    from .reconstruct import footprints_config

    cloud, classes = _block_cloud(spec, options)
    if cloud is None:
        return BlockOutput(spec.index, [], _numbered(None), False)
    cfg = dataclasses.asdict(footprints_config(options.footprints_config))
    try:
        outlines = trace_outlines(cloud.xyz, classes, within=_cell_box(spec, options.block_size),
                                  **cfg)
    except EmptyInputError:
        return BlockOutput(spec.index, [], _numbered(None), True)
    stage = TracedStage(outlines, _building_xy(cloud, classes, options))
    if len(outlines) >= least:
        return BlockOutput(spec.index, [], None, True, staged=stage)
    return BlockOutput(spec.index, [], staged_footprints(spec, options, stage,
                                                         regularise_outlines(outlines)), True)


def outline_parts(staged: dict, pieces: int) -> list:
    """The outlines of the traced blocks ``staged`` (position in the run -> its
    :class:`TracedStage`) in about ``pieces`` :class:`OutlineParts` of equal expected
    work (:meth:`~lidar2city.footprints.extract.TracedOutlines.work`), heaviest
    outlines first: handed out in this order to whichever worker is free, the
    last, lightest ones even out the workers' ends."""
    work, block, part = [], [], []
    for b in sorted(staged):
        w = staged[b].outlines.work()
        work.append(w)
        block.append(np.full(len(w), b, dtype=np.int64))
        part.append(np.arange(len(w), dtype=np.int64))
    if not work:
        return []
    work, block, part = np.concatenate(work), np.concatenate(block), np.concatenate(part)
    order = np.lexsort((part, block, -work))
    share = float(work.sum()) / max(int(pieces), 1)
    out, run, acc = [], [], 0.0

    def close():
        by = {}
        for k in run:
            by.setdefault(int(block[k]), []).append(int(part[k]))
        for b, ks in sorted(by.items()):
            ks = sorted(ks)
            out.append(OutlineParts(b, tuple(ks), staged[b].outlines.take(ks),
                                    float(work[(block == b) & np.isin(part, ks)].sum())))

    for k in order:
        run.append(k)
        acc += work[k]
        if acc >= share:
            close()
            run, acc = [], 0.0
    if run:
        close()
    return out


def regularise_parts(item: OutlineParts) -> RegularisedParts:
    """The footprints of some outlines of a traced block
    (:func:`lidar2city.footprints.extract.regularise_outlines`), the task that
    shares a block's regularisation among the workers."""
    from ..footprints.extract import regularise_outlines

    t0 = time.process_time()
    found = regularise_outlines(item.outlines)
    return RegularisedParts(item.block, item.parts, found, _peak_mb(), time.process_time() - t0,
                            f"{socket.gethostname()}:{os.getpid()}")


def staged_footprints(spec, options, stage: TracedStage, found):
    """A staged block's last stage: its footprints, ``found`` (one per outline of
    ``stage``, in order) made disjoint, those centred in its cell and holding enough
    building points, numbered (what :func:`trace_footprints` returns)."""
    from ..footprints.extract import assemble_footprints
    from .reconstruct import as_footprints

    found = assemble_footprints(stage.outlines, found)
    if not found:
        return _numbered(None)
    return _numbered(_in_cell(spec, options, as_footprints(found), stage.building_xy))


def _points_inside(xy, geometries) -> list:
    """How many of the points ``xy`` (N, 2) each polygon holds."""
    import shapely

    order = np.argsort(xy[:, 0], kind="stable")
    xs = xy[order, 0]
    out = []
    for g in geometries:
        x0, y0, x1, y1 = g.bounds
        c = order[np.searchsorted(xs, x0, "left"):np.searchsorted(xs, x1, "right")]
        c = c[(xy[c, 1] >= y0) & (xy[c, 1] <= y1)]
        out.append(int(np.count_nonzero(shapely.contains_xy(g, xy[c, 0], xy[c, 1]))))
    return out


def block_footprints(spec):
    """The spec's footprints read from their file by feature id, in the block's
    order, local frame, with their output positions in ``_index``."""
    from ..datamodel import Footprints
    from ..io.vector import read_footprints

    ref, frame = spec.footprints, spec.frame
    if isinstance(ref, Footprints):  # carried inline (traced by a first pass)
        return ref
    fps, _ = read_footprints(ref.path, layer=ref.layer, id_field=ref.id_field,
                             origin=frame.origin[:2], xy_unit=frame.xy_unit,
                             target_crs=frame.crs, fids=ref.fids, unique_ids=False)
    return Footprints(fps.geometries, list(ref.ids), {**fps.attributes,
                                                      "_index": list(ref.positions)})


def run_block(spec, options: BlockOptions) -> BlockOutput:
    """Every building of one block (the task a worker runs); see :func:`_run_block`."""
    _cache.saved = dict(options.decoded)
    return _measured(_encoded_block, spec, options)


def _encoded_block(spec, options):
    return encode_block(_run_block(spec, options), options)


def encode_block(out: BlockOutput, options: BlockOptions) -> BlockOutput:
    """With ``options.encode`` and given footprints: ``out`` with each building's
    CityJSONSeq text and extent (:func:`lidar2city.io.cityjsonseq.encode_feature`,
    the LoDs not written left out, the run's measures not written) in
    ``encoded``, and light results (no geometry: the LoD keys of what is
    written, the status, reason and attributes the run's summary counts), so
    that little travels back and the client only appends text."""
    enc = options.encode
    if enc is None or out.failed or not out.results or "_index" not in out.footprints.attributes:
        return out
    import dataclasses

    from ..datamodel import Footprints
    from ..io.cityjsonseq import encode_feature
    from .reconstruct import _without_run_attributes

    fps = out.footprints
    keys = sorted(k for k in fps.attributes if not k.startswith("_"))
    encoded, light = [], []
    for j, r in enumerate(out.results):
        kept = {lod: s for lod, s in r.solids.items() if lod in enc["lods"]}
        written = _without_run_attributes(dataclasses.replace(r, solids=kept))
        encoded.append(encode_feature(written, {k: fps.attributes[k][j] for k in keys},
                                      scale=enc["scale"], xy_unit=enc["xy_unit"],
                                      z_unit=enc["z_unit"]))
        light.append(dataclasses.replace(r, footprint=None, solids=dict.fromkeys(kept, ()),
                                         parts={}))
    out.results, out.encoded = light, encoded
    out.footprints = Footprints([None] * len(fps), list(fps.ids), fps.attributes)
    return out


def give_back_memory() -> None:
    """Give the heap memory freed by a block back to the system (glibc's
    ``malloc_trim``; elsewhere nothing): what glibc keeps after a block is
    scattered free space that the next block's arrays, of other sizes, do not
    all reuse, so without it a process's resident memory creeps up with the
    number of blocks it has run."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)


def _malloc_trim():
    global _TRIM
    if _TRIM is False:
        try:
            import ctypes

            _TRIM = ctypes.CDLL("libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _TRIM = None
    return _TRIM


_TRIM = False


def _peak_mb() -> float:
    """This process's peak resident memory (MB): Linux's ``VmHWM``, the peak of
    its own address space. ``ru_maxrss`` is only the fallback: Linux carries it
    over ``exec``, so a process started by a large one (a Dask worker spawned
    by its nanny, a benchmark's child) would report its parent's size."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        import resource
    except ImportError:  # pragma: no cover - not on Windows
        return 0.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _run_block(spec, options: BlockOptions) -> BlockOutput:
    """Every building of one block.

    Parameters
    ----------
    spec : BlockSpec
        From :mod:`lidar2city.tools.blocks`.
    options : BlockOptions

    Returns
    -------
    BlockOutput
        One result per footprint of the block, in the block's footprint order;
        traced footprints are numbered ``b1``, ``b2``... inside the block (the
        run renumbers them in block order).
    """
    read = None
    if _by_groups(spec, options):
        read = _read_parts(spec)
        if all("classification" in p.attrs for p in read[1]):
            return _run_groups(spec, options, *read)
    cloud, classes = _block_cloud(spec, options, read)
    fps = None if spec.footprints is None else block_footprints(spec)
    if fps is not None and cloud is not None and not spec.traced:
        # the footprints say where the buildings are
        classes = _claim(cloud, classes, fps, options)
    if fps is None:  # traced
        fps = _block_traced(spec, options, cloud, classes)
        if not len(fps):
            return BlockOutput(spec.index, [], fps, cloud is not None)
    if cloud is None:  # no building point in this block
        return _without_points(spec, fps)
    images = options.check_images
    if images is not None and spec.footprints is None:
        # traced ids are numbered per block: one folder of check images per block
        images = str(Path(images) / f"block_{spec.cell[0]}_{spec.cell[1]}")
    return BlockOutput(spec.index, reconstruct_block(cloud, classes, fps, options,
                                                     check_images=images), fps, True)


#: about how many points a block turns into a full-width cloud at a time: its
#: buildings are built in groups of neighbouring footprints, each group with
#: the points around it only (:func:`_run_groups`), so that what a block holds
#: at full width does not grow with how many points the block reads
GROUP_POINTS = 40_000


#: classes a classified tile's footprint without building points may claim: those a
#: classifier puts a missed building in (never created, unclassified, vegetation)
CLAIMABLE = (0, 1, 3, 4, 5)


def _claim(cloud, classes, fps, options):
    """``classes`` with the points of footprints that hold no building points claimed
    for them (:func:`lidar2city.footprints.points.claim_footprint_points`): on a raw
    tile every non-ground point, on a classified one (ours or a vendor's) only
    :data:`CLAIMABLE` points, since a small shed or a roof taken for trees must
    not leave its footprint without a model."""
    from ..footprints.points import claim_footprint_points

    cfg = options.config
    return claim_footprint_points(cloud.xyz[:, :2], classes, fps.geometries,
                                  building_classes=cfg.building_classes,
                                  excluded=(*cfg.ground_classes, 7), min_points=cfg.min_points,
                                  claimable=CLAIMABLE if options.classified else None)


def splittable(options) -> bool:
    """Whether a block's buildings with these options depend only on the points
    around each footprint (classified input, LoD1 / LoD2.2 from the roof
    topology): given footprints can then be built group by group
    (:func:`_run_groups`), and a block cut into parts of its footprints
    (:func:`lidar2city.tools.blocks.footprint_blocks` ``split``) gives the same
    results. Classifying raw points, filtering the ground of a tile without a
    ground class, fitting primitives and re-applying edits look at the whole block."""
    return bool(options.classified and options.primitives is None and not options.edits
                and not options.ground_filter)


def _by_groups(spec, options) -> bool:
    """Whether the block's buildings can be built group by group with the same
    results (:func:`splittable`, given footprints, points to read)."""
    return (splittable(options) and spec.footprints is not None
            and spec.world_box is not None and bool(spec.tiles))


def _local(part, d, origin, scale):
    """Local coordinate ``d`` of a compact part's points, computed as
    :meth:`~lidar2city.io.las.TileReader.cloud` computes it (the same bits)."""
    c = part.column(d)
    np.subtract(c, origin[d], out=c)
    return np.multiply(c, scale, out=c)


def footprint_groups(bounds, box, spacing_area: float, *, points: int = GROUP_POINTS,
                     least: float = 50.0) -> list:
    """Footprints grouped by the square cells (from ``box``'s lower corner) holding
    their centres, the cells sized so that one holds about ``points`` points at
    ``spacing_area`` m² per point, and at least ``least`` m wide.

    Parameters
    ----------
    bounds : ndarray, shape (N, 4)
        Local ``(xmin, ymin, xmax, ymax)`` of each footprint (NaN when empty:
        they go with the first cell).
    box : sequence of 4 float
        The block's local box.

    Returns
    -------
    list of list of int
        The footprints of each group, in their order, groups row by row.
    """
    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 4)
    side = max(float(np.sqrt(points * spacing_area)), float(least))
    centre = np.column_stack([(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2])
    centre = np.nan_to_num(centre - np.asarray(box[:2], dtype=np.float64), nan=0.0)
    keys = np.floor(np.maximum(centre, 0.0) / side).astype(np.int64)
    groups: dict = {}
    for i, (kx, ky) in enumerate(keys.tolist()):
        groups.setdefault((ky, kx), []).append(i)
    return [groups[k] for k in sorted(groups)]


def _run_groups(spec, options, reader, parts) -> BlockOutput:
    """Every building of a block, group by group (:func:`footprint_groups`): the
    block's points are held compact (17 bytes a point) and each group gets the
    full-width cloud of its footprints' surroundings only (search radius and
    roof overhang, + 1 m), in the canonical order of the block's cloud. A
    building queries its points by its footprint's box, so it gets the same
    points in the same order as from the whole block's cloud, and the area's
    ground level (50 m around) is taken from the block's compact points: the
    same results as :func:`reconstruct_block` on the block's cloud."""
    from .reconstruct import _subset, reconstruct_buildings

    cfg = options.config
    fps = block_footprints(spec)
    n = sum(len(p) for p in parts)
    if not n or not any(np.isin(p.attrs["classification"], cfg.building_classes).any()
                        for p in parts):
        return _without_points(spec, fps)
    frame, origin = spec.frame, reader.origin
    xy, z_unit = reader.xy_unit, reader.z_unit

    def area_ground(x0, y0, x1, y1):
        world = frame.to_world([x0 - 1.0, y0 - 1.0, x1 + 1.0, y1 + 1.0])
        out = []
        for p in parts:
            idx = np.flatnonzero(p.inside([world])
                                 & np.isin(p.attrs["classification"], cfg.ground_classes))
            if len(idx):
                q = p.take(idx)
                x, y = _local(q, 0, origin, xy), _local(q, 1, origin, xy)
                keep = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
                out.append(_local(q, 2, origin, z_unit)[keep])
        return np.concatenate(out) if out else np.zeros(0)

    bounds = np.array([[np.nan] * 4 if g is None or g.is_empty else g.bounds
                       for g in fps.geometries], dtype=np.float64).reshape(-1, 4)
    wb = np.asarray(spec.world_box, dtype=np.float64)
    box = np.concatenate([(wb[:2] - origin[:2]) * xy, (wb[2:] - origin[:2]) * xy])
    area = float((box[2] - box[0]) * (box[3] - box[1]))
    pad = cfg.search_radius + (options.lod22.overhang if options.lod22 is not None else 0.0) + 1.0
    results = [None] * len(fps)
    # cells at least 5 paddings wide: a group's cloud is at most ~2x its cells' area
    for idx in footprint_groups(bounds, box, area / n, points=GROUP_POINTS, least=5 * pad):
        b = bounds[idx]
        b = b[np.isfinite(b).all(axis=1)]
        sub = []
        if len(b):  # the group's surroundings: what its buildings query
            world = frame.to_world([b[:, 0].min() - pad, b[:, 1].min() - pad,
                                    b[:, 2].max() + pad, b[:, 3].max() + pad])
            sub = [p.take(np.flatnonzero(p.inside([world]))) for p in parts]
        cloud = reader.cloud(sub)
        classes = cloud.attributes.get("classification", np.zeros(0, dtype=np.uint8))
        done = reconstruct_buildings(cloud, _subset(fps, idx), config=cfg,
                                     building=np.isin(classes, cfg.building_classes),
                                     ground=np.isin(classes, cfg.ground_classes),
                                     lod22=options.lod22, area_ground=area_ground)
        # footprints the classes left without building points claim theirs and are
        # built again (only those: nothing to do, and no cost, where every one has them)
        short = [j for j, r in enumerate(done) if not r.ok
                 and r.attributes.get("point_count", cfg.min_points) < cfg.min_points]
        if short and len(classes) and not spec.traced:  # traced: never claimed
            few = _subset(fps, [idx[j] for j in short])
            claimed = _claim(cloud, classes, few, options)
            if (claimed != classes).any():
                again = reconstruct_buildings(cloud, few, config=cfg,
                                              building=np.isin(claimed, cfg.building_classes),
                                              ground=np.isin(claimed, cfg.ground_classes),
                                              lod22=options.lod22, area_ground=area_ground)
                for j, r in zip(short, again, strict=True):
                    done[j] = r
        del cloud, classes, sub
        for i, r in zip(idx, done, strict=True):
            results[i] = r
    return BlockOutput(spec.index, results, fps, True)


def reconstruct_block(cloud, classes, footprints, options: BlockOptions, *,
                      check_images=None) -> list:
    """The per-building step of a block: LoD1 (+ LoD2.2) of every footprint, in order,
    with the run's edits (``options.edits``) re-applied to the buildings they name.

    ``check_images``: the folder for the primitives' check images of this block.
    """
    from .reconstruct import add_primitives, reconstruct_buildings

    cfg = options.config
    building = np.isin(classes, cfg.building_classes)
    ground = np.isin(classes, cfg.ground_classes)
    results = reconstruct_buildings(cloud, footprints, config=cfg, building=building,
                                    ground=ground, lod22=options.lod22)
    if options.primitives is not None:
        with_classes = cloud.with_attributes(classification=classes)
        fitted = add_primitives(results, with_classes, footprints, config=options.primitives,
                                user_primitives=options.user_primitives)
        if check_images is not None:  # block by block: nothing is kept
            from .primitives import write_check_images

            Path(check_images).mkdir(parents=True, exist_ok=True)
            write_check_images(check_images, with_classes, fitted)
    if options.edits:  # corrections of EDITS.json, where the block's points are
        from .edit import apply_block_edits

        results = apply_block_edits(results, footprints, cloud, classes, options.edits,
                                    options.edit_context)
    return results


def _without_points(spec, fps) -> BlockOutput:
    """The output of a block without any building point: each footprint's reason."""
    results = [_unmodelled(fid, "invalid footprint: empty geometry" if g is None or g.is_empty
                           else "no building point in the block around the footprint")
               for fid, g in zip(fps.ids, fps.geometries, strict=True)]
    return BlockOutput(spec.index, results, fps, False)


def _unmodelled(fid, reason):
    from ..datamodel import BuildingResult

    return BuildingResult(str(fid), status="failed", reason=reason)


@dataclass(eq=False)
class TracedBlock:
    """The footprints a block traced (``footprints``), those centred in its cell,
    in the tracing's order: ``polygons`` (local, the run's frame) and one dict
    of fields each; ``spacing`` the block's building point spacing (m)."""

    index: int
    polygons: list
    fields: list
    spacing: float = 0.0
    worker_mb: float = 0.0
    cpu: float = 0.0
    worker: str = ""


def trace_block(spec, config, block_size: float) -> TracedBlock:
    """The task of ``lidar2city footprints`` on a folder of tiles: the footprints
    (:func:`lidar2city.footprints.extract_footprints` with the ``[footprints]``
    stage ``config``) traced in the spec's box whose centre lies in its cell of
    the ``block_size`` grid.

    The points are read as for ``reconstruct`` (shared tiles, canonical order);
    points without any of the building class are classified in the box first.
    """
    return _measured(_trace_block, spec, config, block_size)


def _trace_block(spec, config, block_size):
    import dataclasses

    from ..footprints import extract_footprints, point_spacing
    from .blocks import block_keys

    out = TracedBlock(spec.index, [], [])
    cloud = _read_box(spec)
    if cloud is None:
        return out
    cls = cloud.get("classification")
    if cls is None or not np.any(cls == config.building_class):
        from .classify import classify_cloud

        cls = np.asarray(classify_cloud(cloud))
    building = cloud.xyz[cls == config.building_class, :2]
    if not len(building):
        return out
    found = extract_footprints(cloud.xyz, cls, within=_cell_box(spec, block_size),
                               **dataclasses.asdict(config))
    if not found:
        return out
    out.spacing = float(point_spacing(building))
    b = np.array([f.polygon.bounds for f in found], dtype=np.float64).reshape(-1, 4)
    centre = np.column_stack([(b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2])
    keys = block_keys(centre, spec.frame, block_size)
    for f, key in zip(found, keys, strict=True):
        if (int(key[0]), int(key[1])) == tuple(spec.cell):
            out.polygons.append(f.polygon)
            out.fields.append({**f.attributes, "status": f.status, "reason": f.reason})
    return out
