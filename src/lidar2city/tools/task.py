"""What runs on a worker: one block spec + the run's options -> its buildings.

:func:`run_block` is the one task of ``reconstruct``, pure in what it returns:
it reads the block's points from the tiles named in the spec (paths travel,
not points), classifies them if the run's input is raw, traces footprints if
none were given, and builds every building of the block with
:func:`reconstruct_block` (the per-building step). The same spec and options
give the same results in any process, so the output does not depend on the
executor (:mod:`lidar2city.tools.engine`), the number of workers or the order
in which blocks finish.
"""

from __future__ import annotations

import logging
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import EmptyInputError
from ..io.las import TileReader

logger = logging.getLogger(__name__)

__all__ = ["BlockOptions", "BlockOutput", "block_footprints", "run_block", "reconstruct_block"]


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


@dataclass(eq=False)
class BlockOutput:
    """The results of one block, in its footprints' order.

    ``points`` says whether the block held building points at all (a run where
    no block does is an error); ``failed``: the task failed twice and every
    building carries that reason; ``worker_mb`` the peak resident memory of
    the process that ran it (a measure of the run, never written).
    """

    index: int
    results: list
    footprints: object
    points: bool = False
    failed: bool = False
    worker_mb: float = 0.0


# decoded tiles kept per process across blocks, least recently used first out: a
# block reads its buildings plus a margin, so it meets up to 3 x 3 tiles and a run
# of neighbouring blocks (:mod:`lidar2city.tools.engine` gives a worker runs of
# consecutive blocks) reuses them. At least ``_TILE_CACHE_SIZE`` tiles are kept,
# more while they hold no more than ``_TILE_CACHE_POINTS`` points in all, so a
# worker's memory is bounded whatever the area (about 40 bytes a point)
_TILE_CACHE_SIZE = 4
_TILE_CACHE_POINTS = 3_000_000
_tiles: OrderedDict = OrderedDict()
_tiles_lock = threading.Lock()


def _cached_points() -> int:
    return sum(len(world) for world, _ in _tiles.values())


class _SharedTileReader(TileReader):
    """A :class:`TileReader` whose decoded tiles are shared by the blocks of a process."""

    def _tile(self, k):
        t = self.tiles[k]
        st = os.stat(t.path)
        key = (t.path, st.st_size, st.st_mtime_ns)
        with _tiles_lock:
            hit = _tiles.get(key)
            if hit is not None:
                _tiles.move_to_end(key)
                return hit
        hit = super()._tile(k)
        self._tiles.clear()
        with _tiles_lock:
            _tiles[key] = hit
            while len(_tiles) > _TILE_CACHE_SIZE and _cached_points() > _TILE_CACHE_POINTS:
                _tiles.popitem(last=False)
        return hit


def _block_cloud(spec, options):
    """``(cloud, classes)`` of the spec's world box, or ``(None, None)`` without building points."""
    from .reconstruct import point_roles

    if spec.world_box is None or not spec.tiles:
        return None, None
    reader = _SharedTileReader(list(spec.tiles), origin=np.asarray(spec.frame.origin))
    cloud = reader.box(*spec.world_box)
    if len(cloud) == 0:
        return None, None
    try:
        _, _, classes = point_roles(cloud, options.config, classified=options.classified)
    except EmptyInputError:
        return None, None
    return cloud, classes


def _traced_footprints(spec, options, cloud, classes):
    """The footprints traced in the block's box whose centre lies in its cell, or None."""
    from .blocks import block_keys
    from .reconstruct import _subset, footprints_from_points

    try:
        fps = footprints_from_points(cloud, classes, config=options.footprints_config)
    except EmptyInputError:
        return None
    bounds = np.array([g.bounds for g in fps.geometries], dtype=np.float64).reshape(-1, 4)
    centre = np.column_stack([(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2])
    keys = block_keys(centre, spec.frame, options.block_size)
    idx = [i for i in range(len(fps)) if (keys[i, 0], keys[i, 1]) == tuple(spec.cell)]
    return _subset(fps, idx) if idx else None


def block_footprints(spec):
    """The spec's footprints read from their file by feature id, in the block's
    order, local frame, with their output positions in ``_index``."""
    from ..datamodel import Footprints
    from ..io.vector import read_footprints

    ref, frame = spec.footprints, spec.frame
    fps, _ = read_footprints(ref.path, layer=ref.layer, id_field=ref.id_field,
                             origin=frame.origin[:2], xy_unit=frame.xy_unit,
                             target_crs=frame.crs, fids=ref.fids, unique_ids=False)
    return Footprints(fps.geometries, list(ref.ids), {**fps.attributes,
                                                      "_index": list(ref.positions)})


def run_block(spec, options: BlockOptions) -> BlockOutput:
    """Every building of one block (the task a worker runs); see :func:`_run_block`."""
    out = _run_block(spec, options)
    out.worker_mb = _peak_mb()
    return out


def _peak_mb() -> float:
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
    from ..datamodel import Footprints

    cloud, classes = _block_cloud(spec, options)
    fps = None if spec.footprints is None else block_footprints(spec)
    if fps is not None and cloud is not None and not options.classified:
        # raw input: the footprints say where the buildings are
        from ..footprints.points import claim_footprint_points

        cfg = options.config
        classes = claim_footprint_points(cloud.xyz[:, :2], classes, fps.geometries,
                                         building_classes=cfg.building_classes,
                                         excluded=(*cfg.ground_classes, 7),
                                         min_points=cfg.min_points)
    if fps is None:  # traced
        fps = None if cloud is None else _traced_footprints(spec, options, cloud, classes)
        if fps is None:
            return BlockOutput(spec.index, [], Footprints([], []), cloud is not None)
        fps = Footprints(fps.geometries, [f"b{j + 1}" for j in range(len(fps))], fps.attributes)
    if cloud is None:  # no building point in this block
        results = [_unmodelled(fid, "invalid footprint: empty geometry" if g is None or g.is_empty
                               else "no building point in the block around the footprint")
                   for fid, g in zip(fps.ids, fps.geometries, strict=True)]
        return BlockOutput(spec.index, results, fps, False)
    images = options.check_images
    if images is not None and spec.footprints is None:
        # traced ids are numbered per block: one folder of check images per block
        images = str(Path(images) / f"block_{spec.cell[0]}_{spec.cell[1]}")
    return BlockOutput(spec.index, reconstruct_block(cloud, classes, fps, options,
                                                     check_images=images), fps, True)


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


def _unmodelled(fid, reason):
    from ..datamodel import BuildingResult

    return BuildingResult(str(fid), status="failed", reason=reason)
