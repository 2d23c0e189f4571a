"""``footprints``: building footprints from classified LAS/LAZ tiles into a GeoPackage."""

from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np

from ..errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["footprints_job", "footprints_on_tiles", "load_footprints_config", "FIELDS",
           "TRACE_BUFFER"]

#: Output fields per building, in order.
FIELDS = ("id", "area", "direction", "n_vertices", "mean_deviation", "n_points",
          "type_i", "type_ii", "type_iii", "type_iv", "status", "reason")


def load_footprints_config(path=None, **overrides):
    """The ``[footprints]`` section of a TOML run config (defaults when absent), with overrides.

    The file's other sections are validated too. ``None`` values in
    ``overrides`` mean "not given" and are ignored.

    Raises
    ------
    ConfigError, FileFormatError
    """
    from ..config import stage_config

    return stage_config("footprints", path, **overrides)


def _building_classes(cloud, building_class):
    """The classification, running ground filtering and classification when it has no buildings."""
    cls = cloud.get("classification")
    if cls is not None and np.any(cls == building_class):
        return cls
    from .classify import classify_cloud

    logger.info("no building class in the input: classifying the points")
    cls = np.asarray(classify_cloud(cloud))
    if cls.shape != (len(cloud),) or not np.any(cls == building_class):
        raise InputError(f"no building points (class {building_class}) found after classification")
    return cls


def footprints_job(inputs, output, *, crs=None, config=None, callback=None) -> dict:
    """Read tiles, extract footprints, write them to ``output`` (GeoPackage, input CRS).

    Parameters
    ----------
    inputs : path or sequence of paths
        LAS/LAZ tiles of one area.
    output : path
        Vector file (``.gpkg``); layer ``footprints`` with :data:`FIELDS`.
    crs : str or pyproj.CRS, optional
        CRS of the input when the files have none (or to override it).
    config : FootprintsConfig, optional
        Stage options; defaults when omitted.
    callback : callable, optional
        ``callback(done, total)`` per building.

    Returns
    -------
    dict
        ``buildings``, ``area`` (m2), ``unregularised`` count, ``points``,
        ``reductions`` (total snake operations by type), ``output``.
    """
    from ..footprints import FootprintsConfig, extract_footprints
    from ..io.las import read_points
    from ..io.vector import VectorLayer, write_layers

    cfg = config if config is not None else FootprintsConfig()
    cloud = read_points(inputs, crs=crs)
    cloud.require_points()
    if cloud.crs is None:
        logger.warning("the input has no CRS: the output will have none (pass --crs)")
    cls = _building_classes(cloud, cfg.building_class)
    fps = extract_footprints(cloud.xyz, cls, callback=callback, **dataclasses.asdict(cfg))
    if not fps:
        raise InputError("no building footprint found (all regions below min_area?)")
    import shapely

    geoms = [shapely.MultiPolygon([f.polygon]) for f in fps]
    fields = {
        "id": [f"b{i + 1:05d}" for i in range(len(fps))],
        **{k: [f.attributes[k] for f in fps] for k in FIELDS[1:-2]},
        "status": [f.status for f in fps],
        "reason": [f.reason for f in fps],
    }
    from .. import __version__
    from ..footprints import grid_lengths, point_spacing

    spacing = point_spacing(cloud.xyz[cls == cfg.building_class, :2])
    lengths = grid_lengths(spacing, cell=cfg.cell, sigma=cfg.sigma,
                           void_distance=cfg.void_distance, simplify=cfg.simplify,
                           snake_cell=cfg.snake_cell)
    meta = {"lidar2city_version": __version__,
            "lidar2city_config": json.dumps({"footprints": dataclasses.asdict(cfg)}),
            "lidar2city_footprints_resolved": json.dumps(
                {"point_spacing": round(spacing, 4), **{k: round(v, 4) for k, v in lengths.items()}})}
    write_layers(output, [VectorLayer("footprints", geoms, fields, "MultiPolygon")],
                 origin=cloud.origin, crs=cloud.crs, xy_unit=cloud.xy_unit,
                 z_unit=cloud.z_unit, metadata=meta)
    return {
        "buildings": len(fps),
        "area": float(sum(f.attributes["area"] for f in fps)),
        "unregularised": sum(f.status != "ok" for f in fps),
        "points": len(cloud),
        "reductions": {t: int(sum(f.attributes[f"type_{t.lower()}"] for f in fps))
                       for t in ("I", "II", "III", "IV")},
        "output": str(output),
    }


#: metres read around a block's cell when tracing on tiles: a building whose
#: centre lies in the cell is traced whole up to twice this across (as ``reconstruct``)
TRACE_BUFFER = 150.0


def footprints_on_tiles(inputs, output, *, crs=None, config=None, block_size=1000.0,
                        workers=1, scheduler=None, progress=None) -> dict:
    """Footprints of a folder (or glob) of tiles, block by block on an executor, into one file.

    The area is cut into the cells of a ``block_size`` grid on the CRS origin
    (:func:`lidar2city.tools.blocks.traced_blocks`, the planner of
    ``reconstruct``); each block reads its cell plus :data:`TRACE_BUFFER`
    metres from the tiles that meet it, traces the footprints there
    (:func:`lidar2city.tools.task.trace_block`) and keeps those whose centre
    lies in its cell, so a building across tiles or blocks is traced once and
    whole. Blocks run in this process (``workers=1``), on a local Dask cluster
    or on ``scheduler``'s; the footprints are numbered and written in block
    order, so the file is the same bytes whatever the executor.

    Parameters
    ----------
    inputs : path or sequence of paths
        Tiles: files, folders or glob patterns (:func:`lidar2city.io.tiles.tile_paths`).
    output : path
        Vector file (``.gpkg``); layer ``footprints`` with :data:`FIELDS`.
    crs, config
        As :func:`footprints_job`.
    block_size : float
        Side (m) of the blocks.
    workers, scheduler
        Where the blocks run (:func:`lidar2city.tools.engine.make_executor`).
    progress : callable, optional
        ``progress(blocks done, blocks, footprints so far)`` after each block.

    Returns
    -------
    dict
        As :func:`footprints_job`, with ``blocks`` and ``failed_blocks`` (the
        cells of blocks that failed twice: the run goes on without them).

    Raises
    ------
    InputError
        No footprint found; bad options (a scheduler that does not answer).
    CRSError
        Tiles with different CRSs.
    """
    from ..footprints import FootprintsConfig
    from ..io.las import TileReader, scan_tiles
    from ..io.tiles import tile_paths
    from . import task
    from .blocks import Frame, traced_blocks
    from .engine import make_executor

    if not block_size > 0:
        raise InputError(f"block_size must be positive, got {block_size}")
    cfg = config if config is not None else FootprintsConfig()
    tiles = scan_tiles(tile_paths(inputs), crs=crs)
    reader = TileReader(tiles)
    if reader.crs is None:
        logger.warning("the input has no CRS: the output will have none (pass --crs)")
    frame = Frame.of(reader)
    specs = traced_blocks(tiles, frame, reader.world_bounds(), block_size, TRACE_BUFFER)
    done, found, failed = {}, 0, []
    with make_executor(workers, scheduler) as executor:
        logger.info("%d blocks on %s", len(specs), executor.describe())
        for i, out in executor.map(task.trace_block, specs, cfg, float(block_size),
                                   run_hook=task.tile_keeper):
            if isinstance(out, BaseException):  # the run goes on; the block is reported
                msg = str(out).splitlines()[0] if str(out) else ""
                logger.error("block %d (cell %s) failed twice: %s%s; no footprint traced there",
                             i, specs[i].cell, type(out).__name__, f": {msg}" if msg else "")
                failed.append(specs[i].cell)
                out = task.TracedBlock(i, [], [])
            done[i] = out
            found += len(out.polygons)
            if progress is not None:
                progress(len(done), len(specs), found)
    blocks = [done[i] for i in range(len(specs))]
    polygons = [p for b in blocks for p in b.polygons]
    rows = [f for b in blocks for f in b.fields]
    if not polygons:
        from ..io.las import check_header_bounds

        check_header_bounds(tiles)  # blocks are planned on the headers' bounds
        raise InputError("no building footprint found (all regions below min_area?)")
    import shapely

    fields = {"id": [f"b{i + 1:05d}" for i in range(len(polygons))],
              **{k: [r[k] for r in rows] for k in FIELDS[1:]}}
    spacings = [b.spacing for b in blocks if b.polygons]
    from .. import __version__
    from ..io.vector import VectorLayer, write_layers

    meta = {"lidar2city_version": __version__,
            "lidar2city_config": json.dumps({"footprints": dataclasses.asdict(cfg)}),
            "lidar2city_footprints_resolved": json.dumps(
                {"block_size": float(block_size), "blocks": len(specs),
                 "point_spacing": [round(min(spacings), 4), round(max(spacings), 4)]})}
    from .reconstruct import fixed_gpkg_date

    with fixed_gpkg_date():
        write_layers(output, [VectorLayer("footprints",
                                          [shapely.MultiPolygon([p]) for p in polygons],
                                          fields, "MultiPolygon")],
                     origin=frame.origin, crs=frame.crs, xy_unit=frame.xy_unit,
                     z_unit=frame.z_unit, metadata=meta)
    return {
        "buildings": len(polygons),
        "area": float(sum(r["area"] for r in rows)),
        "unregularised": sum(r["status"] != "ok" for r in rows),
        "points": reader.count,
        "reductions": {t: int(sum(r[f"type_{t.lower()}"] for r in rows))
                       for t in ("I", "II", "III", "IV")},
        "output": str(output),
        "blocks": len(specs),
        "failed_blocks": failed,
    }
