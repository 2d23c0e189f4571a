"""``footprints``: building footprints from classified LAS/LAZ tiles into a GeoPackage."""

from __future__ import annotations

import dataclasses
import json
import logging

import numpy as np

from ..errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["footprints_job", "load_footprints_config", "FIELDS"]

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
