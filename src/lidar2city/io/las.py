"""LAS / LAZ reading and writing (laspy with the lazrs backend)."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..crs import parse_crs, unit_factors
from ..datamodel import PointCloud
from ..errors import CRSError, EmptyInputError, FileFormatError, InputError
from ._atomic import atomic_path, check_input_file

logger = logging.getLogger(__name__)

__all__ = ["LasTile", "read_las", "read_points", "write_las", "write_points", "POINT_ATTRIBUTES"]

#: laspy dimension names copied into :attr:`PointCloud.attributes` when present.
POINT_ATTRIBUTES = (
    "classification",
    "return_number",
    "number_of_returns",
    "intensity",
    "red",
    "green",
    "blue",
)


@dataclass(eq=False)
class LasTile:
    """A LAS/LAZ file held in memory with its resolved CRS.

    ``data`` is the :class:`laspy.LasData` (kept so that a tool can write every
    input attribute back unchanged); algorithms get :meth:`point_cloud`.
    """

    path: str
    data: object
    crs: object

    def point_cloud(self, *, origin=None) -> PointCloud:
        """The tile as a :class:`PointCloud` in local metric coordinates."""
        return _to_point_cloud(self.data, self.crs, origin=origin)


def _read_crs(las, path):
    try:
        return las.header.parse_crs()
    except Exception as exc:  # laspy raises several kinds for broken VLRs
        logger.warning("%s: CRS VLR could not be parsed (%s); pass --crs", path, exc)
        return None


def read_las(path, *, crs=None) -> LasTile:
    """Read a LAS/LAZ file.

    Parameters
    ----------
    path : str or Path
    crs : str or pyproj.CRS, optional
        Overrides (or supplies) the CRS stored in the file's VLRs.

    Raises
    ------
    FileFormatError
        If the file is missing or not a readable LAS/LAZ file.
    """
    import laspy

    p = check_input_file(path)
    try:
        las = laspy.read(p)
    except Exception as exc:  # laspy.LaspyException, OSError, ValueError from lazrs
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"{str(p)!r} is not a readable LAS/LAZ file: {msg}") from None
    resolved = parse_crs(crs) if crs is not None else _read_crs(las, p)
    return LasTile(str(p), las, resolved)


def _to_point_cloud(las, crs, *, origin=None) -> PointCloud:
    xy_unit, z_unit = unit_factors(crs)
    n = len(las.points)
    if n == 0:
        return PointCloud(np.zeros((0, 3)), np.zeros(3), crs, xy_unit, z_unit, {})
    # scaled integer coordinates -> float64 world, then local
    world = np.empty((n, 3), dtype=np.float64)
    world[:, 0] = las.x
    world[:, 1] = las.y
    world[:, 2] = las.z
    names = set(las.point_format.dimension_names)
    attrs = {name: np.asarray(las[name]) for name in POINT_ATTRIBUTES if name in names}
    if not np.isfinite(world).all():
        raise InputError("point coordinates contain NaN or infinite values")
    return PointCloud.from_world(world, crs=crs, xy_unit=xy_unit, z_unit=z_unit,
                                 origin=origin, attributes=attrs)


def read_points(paths, *, crs=None, require_crs=False) -> PointCloud:
    """Read one or several LAS/LAZ tiles as one point cloud (one area).

    Tiles must share a CRS (or have none, with ``crs`` given). The local origin
    is the lower corner of all tiles together, so a building across a seam is
    one set of points.

    Raises
    ------
    FileFormatError, CRSError, EmptyInputError
    """
    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__iter__"):
        paths = [paths]
    tiles = [read_las(p, crs=crs) for p in paths]
    if not tiles:
        raise EmptyInputError("no input file given")
    crss = {t.crs.to_wkt() if t.crs is not None else None for t in tiles}
    if len(crss) > 1:
        raise CRSError("input tiles have different CRSs; pass --crs to force one or reproject them")
    tile_crs = tiles[0].crs
    if require_crs and tile_crs is None:
        raise CRSError(f"{tiles[0].path!r} has no CRS; pass --crs EPSG:xxxx")
    mins = [t.data.header.mins for t in tiles if len(t.data.points)]
    if not mins:
        raise EmptyInputError("the input files hold no points")
    origin = np.floor(np.min(mins, axis=0))
    origin[2] = 0.0
    clouds = [t.point_cloud(origin=origin) for t in tiles]
    if len(clouds) == 1:
        return clouds[0]
    keys = set.intersection(*(set(c.attributes) for c in clouds))
    return PointCloud(
        np.concatenate([c.xyz for c in clouds]), origin, tile_crs,
        clouds[0].xy_unit, clouds[0].z_unit,
        {k: np.concatenate([c.attributes[k] for c in clouds]) for k in sorted(keys)},
    )


def write_las(path, tile: LasTile, *, classification=None) -> None:
    """Write ``tile`` (every point, every attribute) to ``path``; optionally new classes.

    The format (LAS or LAZ) follows the extension. Written under a temporary
    name and renamed on success. The CRS is written as a WKT VLR when the file
    had none and one was supplied.
    """
    las = tile.data
    if classification is not None:
        classification = np.asarray(classification)
        if classification.shape != (len(las.points),):
            raise InputError(
                f"classification has shape {classification.shape}, expected ({len(las.points)},)"
            )
        las.classification = classification.astype(np.uint8)
    if tile.crs is not None and _needs_crs_vlr(las):
        try:
            las.header.add_crs(tile.crs)
        except Exception as exc:  # older point formats cannot hold WKT in every case
            logger.warning("could not store the CRS in %s: %s", path, exc)
    _write(las, path)


def _write(las, path) -> None:
    """Write ``las`` to ``path`` (LAZ with lazrs when the extension says so), atomically."""
    import laspy

    laz = str(path).lower().endswith(".laz")
    with atomic_path(path) as tmp:
        las.write(str(tmp), do_compress=laz,
                  laz_backend=laspy.LazBackend.Lazrs if laz else None)


def _needs_crs_vlr(las) -> bool:
    try:
        return las.header.parse_crs() is None
    except Exception:
        return True


def write_points(path, cloud: PointCloud, *, scale=0.001) -> None:
    """Write a :class:`PointCloud` to a new LAS 1.4 / LAZ file (point format 6 or 7)."""
    import laspy

    has_rgb = all(k in cloud.attributes for k in ("red", "green", "blue"))
    header = laspy.LasHeader(point_format=7 if has_rgb else 6, version="1.4")
    world = cloud.to_world(cloud.xyz)
    header.offsets = np.floor(world.min(axis=0)) if len(world) else np.zeros(3)
    header.scales = np.array([scale / cloud.xy_unit, scale / cloud.xy_unit, scale / cloud.z_unit])
    if cloud.crs is not None:
        header.add_crs(cloud.crs)
    las = laspy.LasData(header)
    las.x, las.y, las.z = world[:, 0], world[:, 1], world[:, 2]
    for name, values in cloud.attributes.items():
        if name in las.point_format.dimension_names:
            las[name] = values
    _write(las, path)
