"""LAS / LAZ reading and writing (laspy with the lazrs backend)."""

from __future__ import annotations

import contextlib
import logging
import os
from dataclasses import dataclass

import numpy as np

from ..crs import parse_crs, unit_factors
from ..datamodel import PointCloud
from ..errors import CRSError, EmptyInputError, FileFormatError, InputError
from ._atomic import atomic_path, check_input_file

logger = logging.getLogger(__name__)

#: set in a process forked from another (:func:`laz_backend`)
_FORKED = [False]


def _forked() -> None:
    _FORKED[0] = True


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forked)


def laz_backend():
    """The LAZ decoder this process reads with: laspy's choice (lazrs on a thread pool
    of all the cores), except in a process forked from another
    (:class:`lidar2city.tools.forked.ForkExecutor`'s workers), which decodes on its
    calling thread: the pool of the process it was forked from, created by that
    process's first decoding, has no threads in it, and a decoding handed to it
    would wait for ever (measured: a child's ``laspy.read`` after its parent's
    never returns)."""
    if not _FORKED[0]:
        return None
    import laspy

    return laspy.LazBackend.Lazrs

__all__ = ["DecodedTile", "SpilledTile", "LasTile", "TileInfo", "TileReader", "read_las",
           "read_tile", "save_tile", "load_tile", "read_points", "count_points", "scan_tiles",
           "check_header_bounds", "occupied_cells",
           "with_neighbours",
           "write_las", "write_points", "POINT_ATTRIBUTES"]

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


@contextlib.contextmanager
def _reading(path):
    """Reading ``path`` with laspy: its errors become one :class:`FileFormatError`.

    laspy logs a decompression failure before raising it; that log is silenced
    here since the error raised says the same in one line.
    """
    laspy_log = logging.getLogger("laspy")
    level = laspy_log.level
    laspy_log.setLevel(logging.CRITICAL + 1)
    try:
        yield
    except (FileFormatError, CRSError, InputError):
        raise
    except Exception as exc:  # laspy.LaspyException, OSError, lazrs.LazrsError, ValueError
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise FileFormatError(f"{str(path)!r} is not a readable LAS/LAZ file: "
                              f"{_other_format(path) or msg}") from None
    finally:
        laspy_log.setLevel(level)


#: leading bytes of the files a user may give where a LAS/LAZ tile is expected
_SIGNATURES = ((b"ply", "it is a PLY point cloud; convert it to LAS/LAZ first (e.g. "
                        "`pdal translate IN.ply OUT.laz`; a roof-only cloud with every "
                        "point class 6)"),
               (b"II*\x00", "it is a GeoTIFF raster (a DSM goes in with --dsm)"),
               (b"MM\x00*", "it is a GeoTIFF raster (a DSM goes in with --dsm)"),
               (b"SQLite format 3", "it is a GeoPackage / SQLite file (footprints go in with "
                                    "--footprints)"),
               (b"{", "it is a JSON file"))


def _other_format(path) -> str | None:
    """What ``path`` is when its first bytes are those of another known format, else None."""
    try:
        with open(path, "rb") as f:
            head = f.read(16)
    except OSError:
        return None
    return next((what for sig, what in _SIGNATURES if head.startswith(sig)), None)


def _read_crs(las, path):
    try:
        return las.header.parse_crs()
    except Exception as exc:  # laspy raises several kinds for broken VLRs
        logger.warning("%s: CRS VLR could not be parsed (%s); pass --crs", path, exc)
        return None


_RELABELLED: set = set()
#: the CRS each set of CRS records declares (parsing one takes ~15 ms: once per set)
_DECLARED: dict = {}


def _crs_records(header) -> tuple:
    """The bytes of a header's CRS records (GeoTIFF keys, WKT), a key for :data:`_DECLARED`."""
    vlrs = [*header.vlrs, *(getattr(header, "evlrs", None) or [])]
    return tuple((v.record_id, v.record_data_bytes()) for v in vlrs
                 if getattr(v, "user_id", "") == "LASF_Projection"
                 and hasattr(v, "record_data_bytes"))


def _forced_crs(forced, f, p):
    """``forced`` (a ``--crs``, or the CRS of the model being edited), with a warning when
    the file ``f`` declares another CRS: it relabels the coordinates, it does not reproject
    them (said once per pair)."""
    key = _crs_records(f.header)
    if not key:
        return forced
    if key not in _DECLARED:
        _DECLARED[key] = _read_crs(f, p)
    own = _DECLARED[key]
    if own is None or own.to_2d().equals(forced.to_2d(), ignore_axis_order=True):
        return forced
    pair = (own.to_wkt(), forced.to_wkt())
    if pair not in _RELABELLED:
        _RELABELLED.add(pair)
        logger.warning("%s declares the CRS %s but is read as %s (--crs, or the model's CRS): "
                       "its coordinates are taken as they are, not reprojected", p.name,
                       own.name, forced.name)
    return forced


#: a header scale coarser than this (m) is said: outlines and heights are no finer
COARSE_SCALE = 0.05
_COARSE: set = set()


def _check_scale(header, p, crs) -> None:
    """Warn (once per file) when the header's scale rounds coordinates coarser than
    :data:`COARSE_SCALE` metres: a tile written with a scale of 1 gave models up to
    0.5 m off without a word."""
    scales = np.asarray(header.scales, dtype=np.float64)
    if scales.max() <= 0.01 or str(p) in _COARSE:  # the usual cm or mm: no CRS parsed
        return
    try:
        xy_unit, z_unit = unit_factors(crs)
    except CRSError:  # degrees: refused where metres are needed, described by `info`
        return
    steps = scales * (xy_unit, xy_unit, z_unit)
    if steps.max() > COARSE_SCALE:
        _COARSE.add(str(p))
        logger.warning("%s: coordinates stored to %s m (header scale %s): outlines and heights "
                       "are no finer than that", p.name, f"{steps.max():g}",
                       ", ".join(f"{v:g}" for v in header.scales))


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
    with _reading(p):
        try:
            las = laspy.read(p, laz_backend=laz_backend())
        except Exception:
            # a header counting more points than the file holds: say so (its last chunk
            # decoded); checked only on failure, since a whole read finds it too
            with laspy.open(p, laz_backend=laz_backend()) as f:
                _check_point_count(f, p)
            raise
        if las.header.point_count and not las.header.are_points_compressed:
            # an uncompressed file holding more records than its header counts: a warning
            _check_record_count(las.header, p)
    resolved = _forced_crs(parse_crs(crs), las, p) if crs is not None else _read_crs(las, p)
    _check_scale(las.header, p, resolved)
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
                                 origin=origin, attributes=attrs, copy=False)


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


@dataclass(frozen=True, eq=False)
class TileInfo:
    """A tile's header: path, bounds (CRS units), point count and CRS."""

    path: str
    mins: np.ndarray
    maxs: np.ndarray
    count: int
    crs: object


def scan_tiles(paths, *, crs=None, allow_empty=False, check_count=True) -> list:
    """Headers of LAS/LAZ tiles (no points read): bounds, counts, one shared CRS.

    ``allow_empty``: tiles without points are accepted (neighbour lists).
    ``check_count`` false: the point counts are not checked against the points
    (for tiles scanned again with another CRS; a check decodes a chunk a tile).

    Raises
    ------
    FileFormatError, CRSError, EmptyInputError
    """
    import laspy

    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__iter__"):
        paths = [paths]
    forced = parse_crs(crs) if crs is not None else None
    paths = list(paths)
    # few tiles: each tile's last point decoded (a chunk, 5-30 ms); many: the chunk table
    # only (0.1 ms), a count lie within the last chunk left to the blocks that read it
    exact = len(paths) <= EXACT_SCAN_TILES
    out, shared = [], {}
    for path in paths:
        p = check_input_file(path)
        with _reading(p), laspy.open(p, laz_backend=laz_backend()) as f:
            h = f.header
            mins, maxs, count = np.array(h.mins, float), np.array(h.maxs, float), int(h.point_count)
            tile_crs = _read_crs(f, p) if forced is None else _forced_crs(forced, f, p)
            _check_scale(h, p, tile_crs)
            if check_count:
                _check_point_count(f, p, exact=exact)
        if tile_crs is not None:
            # one CRS object for all the tiles of one CRS (each holds ~30 kB of PROJ
            # state: 300 MB for 10,000 tiles otherwise)
            tile_crs = shared.setdefault(tile_crs.to_wkt(), tile_crs)
        out.append(TileInfo(str(p), mins, maxs, count, tile_crs))
    if not out:
        raise EmptyInputError("no input file given")
    if len({t.crs.to_wkt() if t.crs is not None else None for t in out}) > 1:
        raise CRSError("input tiles have different CRSs; pass --crs to force one or reproject them")
    if not allow_empty and not any(t.count for t in out):
        raise EmptyInputError("the input files hold no points")
    return out


#: a scan of at most this many tiles decodes each one's last point (``exact``); a larger
#: one (an area, a country: 50,000 tiles would take ~20 min) reads their chunk tables
EXACT_SCAN_TILES = 16


def _chunk_capacity(header, path):
    """The points a LAZ file's chunk table has room for (fixed-size chunks: their number
    times their size; variable-size: their counts summed), or None when the file has no
    readable chunk table."""
    import lazrs

    vlr = next((v for v in header.vlrs if getattr(v, "record_id", None) == 22204), None)
    if vlr is None:
        return None
    try:
        laz = lazrs.LazVlr(vlr.record_data)
        with open(path, "rb") as fh:
            fh.seek(int(header.offset_to_point_data))
            table = lazrs.read_chunk_table(fh, laz)
    except Exception:  # lazrs.LazrsError, OSError: no table written, or a truncated file
        return None
    return sum(int(c[0]) for c in table)


def _check_point_count(reader, path, *, exact: bool = True) -> None:
    """Check a tile's header point count against its point data (an open laspy reader).

    With ``exact`` false, a LAZ file with a chunk table is checked against the table
    only (no decoding): a truncated file or a count beyond its chunks is found, a count
    that lies within its last chunk is not (its blocks then fail, each building with
    the reason, as a batch goes on past one bad tile).

    A LAZ file whose header counts more points than it holds was read as valid
    here and failed in every block that read it (``reconstruct`` with footprints
    wrote a model of failed buildings, exit 0; without, ``no building footprint
    found``): its last point is decoded (one chunk) so it fails at once. An
    uncompressed file whose point data holds more records than its header
    counts is read to the header's count, with a warning.

    Raises
    ------
    FileFormatError
    """
    h = reader.header
    n = int(h.point_count)
    if n == 0:
        return
    if h.are_points_compressed:
        room = None if exact else _chunk_capacity(h, path)
        if room is not None and room >= n:
            return
        try:
            if room is not None:  # fewer chunks than the count needs: say so, decode nothing
                raise ValueError(f"its chunk table holds at most {room:,}")
            reader.seek(n - 1)
            got = len(reader.read_points(1))
        except Exception as exc:  # lazrs.LazrsError, OSError, laspy.LaspyException
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            got, why = 0, f" ({msg})"
        else:
            why = ""
        reader.seek(0)
        if got != 1:
            raise FileFormatError(
                f"{str(path)!r} is not a readable LAS/LAZ file: its header counts {n:,} "
                f"points but its compressed point data ends before the last{why}: a wrong "
                "header point count, or a truncated file")
        return
    _check_record_count(h, path)


def _check_record_count(h, path) -> None:
    """Warn when an uncompressed file's point data holds more records than its header
    ``h`` counts (only those are read)."""
    import os

    n = int(h.point_count)
    end = int(getattr(h, "start_of_first_evlr", 0) or 0) or os.path.getsize(path)
    held = (end - int(h.offset_to_point_data)) // int(h.point_format.size)
    if held > n:
        logger.warning("%s: its point data holds %s point records, its header counts %s: "
                       "only those read (rewrite the header to read them all)", path,
                       f"{held:,}", f"{n:,}")


def count_points(paths, *, at_least: int | None = None) -> int:
    """The points the headers of ``paths`` declare (no point read), summed in order;
    once the sum reaches ``at_least`` the rest are not opened.

    Raises
    ------
    FileFormatError
        A path that is not a readable LAS / LAZ file.
    """
    import laspy

    total = 0
    for path in paths:
        p = check_input_file(path)
        with _reading(p), laspy.open(p, laz_backend=laz_backend()) as f:
            total += int(f.header.point_count)
        if at_least is not None and total >= at_least:
            break
    return total


def check_header_bounds(tiles, *, limit: int = 100) -> None:
    """Raise :class:`FileFormatError` naming a tile whose first point lies outside its
    header's bounds.

    Planning trusts the headers (no point is read), so a header whose bounds are
    wrong hides its tile: a run would find no footprint over it, or no building.
    Reading a point costs a LAZ chunk's decoding (~10 ms), so this is for the
    paths where a run found nothing, and looks at the first ``limit`` tiles.
    """
    import laspy

    for t in [t for t in tiles if t.count][:limit]:
        with _reading(t.path), laspy.open(t.path, laz_backend=laz_backend()) as f:
            pts = f.read_points(1)
            if not len(pts):
                continue
            xyz = np.array([float(pts.x[0]), float(pts.y[0]), float(pts.z[0])])
            tol = np.asarray(f.header.scales, dtype=np.float64)
        if np.any(xyz < t.mins - tol) or np.any(xyz > t.maxs + tol):
            raise FileFormatError(
                f"{t.path!r}: its header's bounds (x {t.mins[0]:.2f}..{t.maxs[0]:.2f}, y "
                f"{t.mins[1]:.2f}..{t.maxs[1]:.2f}, z {t.mins[2]:.2f}..{t.maxs[2]:.2f}) do not "
                f"hold its points (first point {xyz[0]:.2f}, {xyz[1]:.2f}, {xyz[2]:.2f}): "
                "rewrite the header (e.g. pdal translate or las2las) and run again")


def occupied_cells(path, step: float) -> np.ndarray:
    """``(col, row)`` of the cells of side ``step`` (CRS units, on the CRS origin) that
    hold points of the tile ``path``, sorted, decoded chunk by chunk.

    For tiles whose header box is nearly empty (a few stray returns far off):
    the cells the points occupy, not every cell of the box.
    """
    import laspy

    parts = [np.zeros((0, 2), dtype=np.int64)]
    with _reading(path), laspy.open(path, laz_backend=laz_backend()) as f:
        for chunk in f.chunk_iterator(READ_CHUNK):
            ij = np.floor(np.column_stack([np.asarray(chunk.x), np.asarray(chunk.y)]) / step)
            parts.append(np.unique(ij.astype(np.int64), axis=0))
    return np.unique(np.concatenate(parts), axis=0)


class TileReader:
    """The points of a set of tiles inside world boxes, whatever the tiling.

    A box's points come from every tile whose header bounds meet it and are
    put in a canonical order (by x, y, z, then the other attributes), so the
    cloud of a box is the same however the area was cut into files and in
    whichever order they were given. Decoded tiles are kept in a small
    least-recently-used cache (``cache`` tiles): visiting boxes in spatial
    order reads each tile about once, and memory stays bounded by a few tiles.

    Parameters
    ----------
    tiles : list of TileInfo
        From :func:`scan_tiles`.
    origin : array_like, shape (3,), optional
        World coordinates of the local origin; default the lower corner of all
        tiles rounded down to whole CRS units (z = 0).
    """

    def __init__(self, tiles, *, origin=None, cache: int = 4):
        from collections import OrderedDict

        self.tiles = list(tiles)
        self.crs = self.tiles[0].crs
        self.xy_unit, self.z_unit = unit_factors(self.crs)
        if origin is None:
            mins = [t.mins for t in self.tiles if t.count]
            origin = np.floor(np.min(mins, axis=0))
            origin[2] = 0.0
        self.origin = np.asarray(origin, dtype=np.float64)
        self.cache = max(1, int(cache))
        self._tiles = OrderedDict()
        self.reads = 0

    @property
    def count(self) -> int:
        return sum(t.count for t in self.tiles)

    def world_bounds(self) -> np.ndarray:
        """``[xmin, ymin, xmax, ymax]`` of the tiles holding points (CRS units)."""
        full = [t for t in self.tiles if t.count]
        mins = np.min([t.mins for t in full], axis=0)
        maxs = np.max([t.maxs for t in full], axis=0)
        return np.array([mins[0], mins[1], maxs[0], maxs[1]])

    def has_classes(self, classes) -> bool:
        """Whether any point of the tiles carries one of ``classes`` (read in chunks of
        growing size, from a few thousand points, stopping at the first hit: a
        classified tile is known after decoding a sliver of it)."""
        return self.classes_found([classes])[0]

    def classes_found(self, groups) -> list:
        """For each sequence of classes in ``groups``, whether any point carries one of
        them: :meth:`has_classes` of every group in one scan, stopping once each is found."""
        import laspy

        found = [False] * len(groups)
        for t in self.tiles:
            if not t.count:
                continue
            with _reading(t.path), laspy.open(t.path, laz_backend=laz_backend()) as f:
                if "classification" not in f.header.point_format.dimension_names:
                    continue
                size, left = 16_384, int(f.header.point_count)
                while left > 0:
                    chunk = f.read_points(min(size, left))
                    if len(chunk) == 0:
                        break
                    left -= len(chunk)
                    cls = np.asarray(chunk.classification)
                    found = [was or bool(np.isin(cls, g).any())
                             for was, g in zip(found, groups, strict=True)]
                    if all(found):
                        return found
                    size = min(4 * size, READ_CHUNK)
        return found

    def _tile(self, k) -> DecodedTile:
        if k in self._tiles:
            self._tiles.move_to_end(k)
            return self._tiles[k]
        path = self.tiles[k].path
        self.reads += 1
        self._tiles[k] = read_tile(path)
        while len(self._tiles) > self.cache:
            self._tiles.popitem(last=False)
        return self._tiles[k]

    def _taken(self, k) -> None:
        """Tile ``k``'s points in a box were taken (a subclass may put the tile away)."""

    def _visit_order(self, ks) -> list:
        """The order in which the tiles ``ks`` meeting a box are read (any order gives
        the same cloud; a subclass may read first the tiles it must decode)."""
        return list(ks)

    def box(self, xmin, ymin, xmax, ymax) -> PointCloud:
        """The points with ``xmin <= x <= xmax`` and ``ymin <= y <= ymax`` (world CRS units)."""
        return self.cloud(self.parts(xmin, ymin, xmax, ymax))

    def parts(self, xmin, ymin, xmax, ymax) -> list:
        """The points of :meth:`box`, compact and not yet ordered: one
        :class:`DecodedTile` per tile meeting the box (17 bytes a point
        instead of the cloud's 24 + attributes); :meth:`cloud` makes the cloud
        of them, or of any part of them."""
        parts = []
        meeting = [k for k, t in enumerate(self.tiles)
                   if t.count and not (t.maxs[0] < xmin or t.mins[0] > xmax or t.maxs[1] < ymin
                                       or t.mins[1] > ymax)]
        for k in self._visit_order(meeting):
            tile = self._tile(k)
            parts.append(tile.take(np.flatnonzero(tile.inside([(xmin, ymin, xmax, ymax)]))))
            del tile
            self._taken(k)
        return parts

    def cloud(self, parts) -> PointCloud:
        """The :class:`PointCloud` of ``parts`` (:meth:`parts`, or parts of them) in
        the canonical order, local coordinates: a subset of a box's parts gives
        the subset of the box's cloud, in the same order and to the bit."""
        keys = sorted(set.intersection(*(set(p.attrs) for p in parts))) if parts else []
        values = {n: np.concatenate([p.attrs[n] for p in parts]) for n in keys}
        # canonical order: the same points give the same cloud whatever the tiling
        order, cols = _points_order(parts, [values[n] for n in keys])
        values = {n: v[order] for n, v in values.items()}
        # local coordinates, column by column: (world - origin) * scale, as from_world
        scale = (self.xy_unit, self.xy_unit, self.z_unit)
        local = np.empty((len(order), 3), dtype=np.float64)
        for d in range(3):
            c = cols(d, order)
            np.subtract(c, self.origin[d], out=c)
            np.multiply(c, scale[d], out=c)
            local[:, d] = c
        return PointCloud(local, self.origin.copy(), self.crs, self.xy_unit, self.z_unit, values)


def _points_order(parts, attrs):
    """``(order, cols)``: the canonical order of the points of ``parts`` (a list of
    :class:`DecodedTile`) by x, y, z then ``attrs`` (:func:`_canonical_order`), and
    ``cols(d, order)``, their world coordinate ``d`` in that order (float64, new array).

    Tiles of one resolution (the usual case) are sorted on one int64 key made
    of their integer steps, built a column at a time (no float ranks, no
    copy of all three columns): the steps of one resolution are in the order
    of the coordinates they give, so the order is the same.
    """
    if not parts:
        return np.zeros(0, dtype=np.int64), lambda d, order: np.zeros(0)
    scales = parts[0].scales
    if not all(np.array_equal(p.scales, scales) for p in parts):
        world = [np.concatenate([p.column(d) for p in parts]) for d in range(3)]
        return _canonical_order(world, attrs), lambda d, order: world[d][order]
    n = sum(len(p) for p in parts)

    def steps(d):
        out = np.empty(n, dtype=np.int64)
        i = 0
        for p in parts:
            np.add(p.steps[:, d], p.base[d], out=out[i:i + len(p)], casting="unsafe")
            i += len(p)
        return out

    def cols(d, order):
        c = np.empty(n, dtype=np.float64)
        i = 0
        for p in parts:  # base + steps: integers far below 2**53, exact in float64
            seg = c[i:i + len(p)]
            seg[...] = p.steps[:, d]
            seg += p.base[d]
            i += len(p)
        c = c[order]
        return np.multiply(c, scales[d], out=c)

    def full():
        return np.lexsort(attrs[::-1] + [cols(d, slice(None)) for d in range(3)][::-1])

    if n < 2:
        return full(), cols
    lo = [min(int(p.base[d]) + int(p.steps[:, d].min()) for p in parts if len(p)) for d in range(3)]
    hi = [max(int(p.base[d]) + int(p.steps[:, d].max()) for p in parts if len(p)) for d in range(3)]
    sizes = [h - l + 1 for l, h in zip(lo, hi, strict=True)]
    if sizes[0] * sizes[1] * sizes[2] >= 2 ** 63:
        return full(), cols
    key = None
    for d in range(3):  # ((x - x0) * ny + (y - y0)) * nz + (z - z0)
        c = steps(d)
        c -= lo[d]
        if key is None:
            key = c
        else:
            key *= sizes[d]
            key += c
        del c
    # distinct keys have one sorted order, so any sort gives it (the default is several
    # times faster than a stable one); equal keys are caught below
    order = np.argsort(key)
    key = key[order]
    if np.any(key[1:] == key[:-1]):  # coinciding points: their attributes decide
        return full(), cols
    return order, cols


def _canonical_order(cols, attrs):
    """``np.lexsort(attrs[::-1] + cols[::-1])``: the points by x, then y, z, then ``attrs``.

    Sorting on seven keys costs ~0.1 s per million points per key; points rarely
    share all three coordinates, so they are sorted once on one integer key
    made of the ranks of x, y and z, and the full sort is only run when two
    points coincide (or the ranks do not fit in one key). Same order either way.
    """
    n = len(cols[0])
    if n < 2:
        return np.lexsort(attrs[::-1] + cols[::-1])
    ranks, sizes = [], []
    for c in cols:
        u, inv = np.unique(c, return_inverse=True)
        ranks.append(inv.reshape(-1).astype(np.int64))
        sizes.append(len(u))
    if sizes[0] * sizes[1] * sizes[2] >= 2 ** 63:
        return np.lexsort(attrs[::-1] + cols[::-1])
    key = (ranks[0] * sizes[1] + ranks[1]) * sizes[2] + ranks[2]
    del ranks
    order = np.argsort(key)  # distinct keys: one order, whichever sort (equal keys below)
    k = key[order]
    if np.any(k[1:] == k[:-1]):  # coinciding points: their attributes decide
        return np.lexsort(attrs[::-1] + cols[::-1])
    return order


@dataclass(eq=False)
class DecodedTile:
    """A decoded tile's points held compactly: the coordinates as integer steps
    of the file's resolution (int32 from a per-tile ``base``, 12 bytes a point
    instead of 24) and the :data:`POINT_ATTRIBUTES` the file has.

    World coordinate ``d`` of a point is ``(base[d] + steps[:, d]) * scales[d]``:
    the file's coordinate snapped to its resolution (see :func:`read_tile`).
    """

    steps: np.ndarray  # (N, 3) int32 (int64 when a tile spans more than 2**31 steps)
    base: np.ndarray  # (3,) int64
    scales: np.ndarray  # (3,) float64
    attrs: dict

    def __len__(self) -> int:
        return len(self.steps)

    @property
    def nbytes(self) -> int:
        return self.steps.nbytes + sum(v.nbytes for v in self.attrs.values())

    def column(self, d: int) -> np.ndarray:
        """World coordinate ``d`` of every point (float64, CRS units)."""
        c = self.steps[:, d].astype(np.float64)
        c += self.base[d]  # exact: integers far below 2**53
        return np.multiply(c, self.scales[d], out=c)

    def world(self) -> np.ndarray:
        """World coordinates, shape (N, 3) float64."""
        return np.column_stack([self.column(d) for d in range(3)]) if len(self) \
            else np.zeros((0, 3))

    def inside(self, boxes) -> np.ndarray:
        """Boolean mask of the points in any of the world ``boxes`` ``(xmin, ymin, xmax, ymax)``
        (bounds included)."""
        x, y = self.column(0), self.column(1)
        mask = np.zeros(len(self), dtype=bool)
        for x0, y0, x1, y1 in boxes:
            mask |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return mask

    def take(self, idx) -> DecodedTile:
        """The points ``idx`` (indices or a mask), as a new tile."""
        return DecodedTile(self.steps[idx], self.base, self.scales,
                           {n: v[idx] for n, v in self.attrs.items()})

    def spill(self) -> SpilledTile:
        """The tile written to an unlinked scratch file (see :class:`SpilledTile`)."""
        return SpilledTile(self)


class SpilledTile:
    """A :class:`DecodedTile` kept in an unlinked scratch file instead of memory.

    The file (in the temporary folder, ``TMPDIR``) has no name from the start:
    it goes when the tile is closed or the process ends, however it ends.
    Reading it back costs a copy of its bytes (from the system's file cache
    while there is room), far less than decoding its LAZ again.
    """

    def __init__(self, tile: DecodedTile):
        import tempfile

        self.count = len(tile)
        self.base, self.scales = tile.base, tile.scales
        arrays = {"": tile.steps, **tile.attrs}
        self._layout = [(n, a.dtype, a.shape) for n, a in arrays.items()]
        self._file = tempfile.TemporaryFile(prefix="lidar2city-tile-")
        for a in arrays.values():
            if a.size:  # (an empty tile part has nothing to write)
                self._file.write(memoryview(np.ascontiguousarray(a)).cast("B"))
        self._file.flush()

    def __len__(self) -> int:
        return self.count

    def load(self) -> DecodedTile:
        """The tile back in memory (the file is kept until :meth:`close`)."""
        self._file.seek(0)
        arrays = {}
        for name, dtype, shape in self._layout:
            a = np.empty(shape, dtype=dtype)
            if a.nbytes and self._file.readinto(memoryview(a).cast("B")) != a.nbytes:
                raise OSError("a scratch file of decoded points was cut short")
            arrays[name] = a
        steps = arrays.pop("")
        return DecodedTile(steps, self.base, self.scales, arrays)

    def close(self) -> None:
        self._file.close()


def save_tile(tile: DecodedTile, path) -> None:
    """Write a decoded tile to ``path`` (NumPy ``.npz``, uncompressed: 17 bytes a
    point for x, y, z steps, class and returns), for another process to
    :func:`load_tile` instead of decoding the LAZ again (the same points, bit
    for bit). A scratch file, not an output: the caller names and removes it."""
    with open(path, "wb") as f:
        np.savez(f, steps=tile.steps, base=tile.base, scales=tile.scales,
                 **{f"attr_{n}": v for n, v in tile.attrs.items()})


def load_tile(path) -> DecodedTile:
    """The tile :func:`save_tile` wrote to ``path``."""
    with np.load(path) as z:
        attrs = {n[5:]: z[n] for n in z.files if n.startswith("attr_")}
        return DecodedTile(z["steps"], z["base"], z["scales"], attrs)


#: points decoded at a time when a tile is read for :class:`TileReader`
READ_CHUNK = 262_144


def _read_world(path, *, chunk: int = READ_CHUNK):
    """``(world xyz (N, 3), {name: values})`` of a tile (:func:`read_tile`)."""
    tile = read_tile(path, chunk=chunk)
    return tile.world(), tile.attrs


def read_tile(path, *, chunk: int = READ_CHUNK) -> DecodedTile:
    """A tile's points as a :class:`DecodedTile`, decoded ``chunk`` points at a time.

    Only the coordinates and :data:`POINT_ATTRIBUTES` are kept (never the
    whole point record), written into arrays allocated once. Coordinates are
    snapped to the file's resolution: offset + integer x scale is rounded
    differently for different offsets, and tiles cut from one survey may
    carry different offsets; the snapped coordinate is kept as its integer
    number of resolution steps.
    """
    import laspy

    p = check_input_file(path)
    with _reading(p):  # laspy log silenced, any read error one line
        with laspy.open(p, laz_backend=laz_backend()) as f:
            n = int(f.header.point_count)
            scales = np.asarray(f.header.scales, dtype=np.float64)
            names = [d for d in POINT_ATTRIBUTES if d in set(f.header.point_format.dimension_names)]
            # the steps go straight into int32 from the header's lower corner (the
            # result's base is the true lowest step, applied at the end): no int64
            # copy of every step is held beside them; a header too far off, or a tile
            # too wide for int32, takes the int64 path
            guess = _header_steps(f.header.mins, scales)
            rel = np.empty((n, 3), dtype=np.int32 if guess is not None else np.int64)
            lo = np.full(3, np.iinfo(np.int64).max, dtype=np.int64)
            attrs: dict = {}
            i = 0
            for pts in f.chunk_iterator(chunk):
                m = min(len(pts), n - i)
                steps = np.empty((m, 3), dtype=np.int64)
                for d, axis in enumerate("xyz"):
                    w = np.asarray(pts[axis], dtype=np.float64)[:m] / scales[d]
                    if not np.isfinite(w).all():
                        raise InputError(f"{path}: point coordinates contain NaN or infinite "
                                         "values")
                    steps[:, d] = np.round(w)
                if m:
                    lo = np.minimum(lo, steps.min(axis=0))
                if guess is not None:
                    steps -= guess
                    if m and (steps.min() < _INT32[0] or steps.max() > _INT32[1]):
                        # out of int32 from the guess: the steps so far back to int64
                        wide = np.empty((n, 3), dtype=np.int64)
                        np.add(rel[:i], guess, out=wide[:i], casting="unsafe")
                        rel, steps = wide, steps + guess
                        guess = None
                rel[i:i + m] = steps
                del steps
                for d in names:
                    v = np.asarray(pts[d])[:m]
                    if d not in attrs:
                        attrs[d] = np.empty(n, dtype=v.dtype)
                    attrs[d][i:i + m] = v
                i += m
    rel = rel[:i]
    attrs = {d: (attrs[d][:i].copy() if i < n else attrs[d]) if d in attrs
             else np.zeros(i, dtype=np.uint8) for d in names}
    if not i:
        return DecodedTile(np.empty((0, 3), dtype=np.int32), np.zeros(3, dtype=np.int64),
                           scales, attrs)
    base = lo
    shift = base - (guess if guess is not None else 0)  # rel + shift: the steps from base
    top = rel.max(axis=0).astype(np.int64) - shift
    if guess is not None and int(top.max()) < 2 ** 31:
        # every step from the guess fits int32 and so does every step from the base
        # (0 <= step - base <= step - guess + |shift|): shifted in place
        np.subtract(rel, shift.astype(np.int32), out=rel, casting="unsafe")
        return DecodedTile(rel if i == n else rel.copy(), base, scales, attrs)
    wide = rel.astype(np.int64) - shift if rel.dtype != np.int64 else rel - shift
    out = np.empty((i, 3), dtype=np.int32 if int(top.max()) < 2 ** 31 else np.int64)
    np.copyto(out, wide, casting="unsafe")
    return DecodedTile(out, base.astype(np.int64), scales, attrs)


_INT32 = (int(np.iinfo(np.int32).min), int(np.iinfo(np.int32).max))


def _header_steps(mins, scales):
    """The header's lower corner in steps of the resolution (int64), or None when it is
    not usable (not finite, or beyond int64)."""
    m = np.asarray(mins, dtype=np.float64)[:3] / scales
    if not np.isfinite(m).all() or (np.abs(m) > 2.0 ** 62).any():
        return None
    return np.floor(m).astype(np.int64)


def with_neighbours(cloud, neighbours, *, buffer=50.0, crs=None):
    """``cloud`` followed by the points of ``neighbours`` within ``buffer`` metres of its extent.

    For filters that look around each point (ground, classification): a tile
    is processed with a strip of its neighbours so that its border points see
    the terrain and buildings beyond it, and only its own points (the first
    ``len(cloud)``) are kept. Attributes present in both are carried.

    Parameters
    ----------
    cloud : PointCloud
        The tile's points (its origin is kept).
    neighbours : sequence of paths
        Adjacent LAS/LAZ tiles in the same CRS (tiles outside the buffer are
        not read).

    Returns
    -------
    PointCloud
    """
    if not neighbours:
        return cloud
    if buffer < 0:
        raise InputError(f"buffer must be >= 0, got {buffer}")
    cloud.require_points()
    tiles = scan_tiles(neighbours, crs=crs, allow_empty=True)
    if crs is None:
        theirs = tiles[0].crs
        if theirs is not None and cloud.crs is None:
            raise CRSError("the neighbouring tiles have a CRS and the input has none; pass --crs")
        if theirs is None and cloud.crs is not None:
            logger.warning("the neighbouring tiles have no CRS: taken to be the input's")
            tiles = scan_tiles(neighbours, crs=cloud.crs, allow_empty=True)
        elif theirs is not None and theirs != cloud.crs:
            raise CRSError("the neighbouring tiles and the input have different CRSs; pass --crs "
                           "to force one or reproject them")
    tiles = [t for t in tiles if t.count]
    if not tiles:
        return cloud
    reader = TileReader(tiles, origin=cloud.origin)
    own_lo = cloud.to_world(cloud.xyz[:, :2].min(axis=0))
    own_hi = cloud.to_world(cloud.xyz[:, :2].max(axis=0))
    lo = own_lo - buffer / cloud.xy_unit
    hi = own_hi + buffer / cloud.xy_unit
    extra = reader.box(lo[0], lo[1], hi[0], hi[1])
    # neighbours' points inside the tile's own bounding box are left out (the list
    # may hold the tile itself: no point is taken twice; the tolerance covers the
    # snapping of the neighbours' coordinates to their file's resolution)
    tol = 1e-6  # CRS units: far below any file resolution
    w = extra.to_world(extra.xyz[:, :2]) if len(extra) else np.zeros((0, 2))
    outside = ~((w[:, 0] >= own_lo[0] - tol) & (w[:, 0] <= own_hi[0] + tol)
                & (w[:, 1] >= own_lo[1] - tol) & (w[:, 1] <= own_hi[1] + tol))
    extra = extra.subset(outside)
    logger.info("%d points of %d neighbouring tile(s) within %g m added", len(extra),
                len(neighbours), buffer)
    if len(extra) == 0:
        return cloud
    attrs = {}
    for k, own in cloud.attributes.items():
        if k in extra.attributes:
            attrs[k] = np.concatenate([own, extra.attributes[k].astype(own.dtype)])
        else:
            # a neighbour without the field (another point format): a neutral value
            fill = 1 if k in ("classification", "return_number", "number_of_returns") else 0
            logger.warning("the neighbouring tiles have no %r: their points get %d", k, fill)
            attrs[k] = np.concatenate([own, np.full(len(extra), fill, dtype=own.dtype)])
    return PointCloud(np.concatenate([cloud.xyz, extra.xyz]), cloud.origin, cloud.crs,
                      cloud.xy_unit, cloud.z_unit, attrs)


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
    """Write ``las`` to ``path`` (LAZ with lazrs when the extension says so), atomically.

    LAZ chunks are compressed on every core (lazrs's parallel writer gives the same
    bytes as its serial one, as laspy's own default does)."""
    import laspy

    laz = str(path).lower().endswith(".laz")
    with atomic_path(path) as tmp:
        las.write(str(tmp), do_compress=laz,
                  laz_backend=laspy.LazBackend.LazrsParallel if laz else None)


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
