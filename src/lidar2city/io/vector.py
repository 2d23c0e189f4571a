"""Vector reading and writing (any OGR source) with pyogrio and shapely 2."""

from __future__ import annotations

import contextlib
import functools
import logging
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..datamodel import Footprints
from ..errors import CRSError, EmptyInputError, FileFormatError, InputError
from ._atomic import atomic_path, check_input_file

logger = logging.getLogger(__name__)

__all__ = ["footprint_layer", "no_pam", "overlapping", "read_footprints", "vector_crs", "unique",
           "repair_polygonal", "VectorLayer", "write_layers", "write_polygons", "to_local", "to_world"]


def to_local(geoms, origin, xy_unit=1.0):
    """Shift/scale shapely geometries from world (CRS units) to local metres."""
    import shapely

    o = np.asarray(origin, dtype=np.float64)
    return shapely.transform(geoms, lambda c: (c - o[: c.shape[1]]) * xy_unit, include_z=False)


def to_world(geoms, origin, xy_unit=1.0, z_unit=1.0):
    """Inverse of :func:`to_local`; z (when present) is scaled by ``z_unit``."""
    import shapely

    o = np.asarray(origin, dtype=np.float64)
    scale = np.array([xy_unit, xy_unit, z_unit])

    def f(c):
        d = c.shape[1]
        return o[:d] + c / scale[:d]

    has_z = np.any(shapely.has_z(np.atleast_1d(geoms)))
    return shapely.transform(geoms, f, include_z=bool(has_z))


#: a self-intersecting polygon is repaired to its largest part when that part holds at least
#: this share of the area (a loop or spike cut off); otherwise it is refused with the reason
KEEP_LARGEST_SHARE = 0.9


def repair_polygonal(geom, *, keep_largest_share: float = KEEP_LARGEST_SHARE):
    """Return ``(polygonal geometry or None, note)`` for one input geometry.

    Repeated closing vertices are fine as they are. An invalid geometry is
    repaired with :func:`shapely.make_valid`, keeping its polygonal parts. A
    *Polygon* must stay one polygon: when the repair splits it (a bow-tie, a
    loop), its largest part is kept if it holds at least
    ``keep_largest_share`` of the area (a small loop or spike cut off), and
    the note says so; otherwise the footprint is refused (``None``) with the
    reason, since which part is the building cannot be told. A MultiPolygon
    keeps its parts, a GeometryCollection its polygons (its points and lines
    left out, said in the note). Non-polygonal or empty input gives ``None``
    with the reason.

    Examples
    --------
    >>> from shapely.geometry import Polygon
    >>> g, note = repair_polygonal(Polygon([(0, 0), (2, 2), (2, 0), (0, 2)]))
    >>> g is None, note.startswith("self-intersecting outline splits into 2 parts")
    (True, True)
    """
    from shapely.geometry import MultiPolygon

    if geom is not None and geom.geom_type == "GeometryCollection" and not geom.is_empty:
        # an outline with its label point or centre line (some exports, overlays): its polygons
        members = list(geom.geoms)
        polys = [p for g in members if g.geom_type in ("Polygon", "MultiPolygon")
                 for p in getattr(g, "geoms", [g])]
        if not polys:
            kinds = ", ".join(sorted({g.geom_type for g in members}))
            return None, f"not a polygon (GeometryCollection of {kinds})"
        fixed, note = _repair(polys[0] if len(polys) == 1 else MultiPolygon(polys),
                              keep_largest_share=keep_largest_share)
        others = sum(g.geom_type not in ("Polygon", "MultiPolygon") for g in members)
        said = f"the polygons of a GeometryCollection ({others} other part(s) left out)"
        return fixed, "; ".join(n for n in (said, note) if n) if fixed is not None else note
    return _repair(geom, keep_largest_share=keep_largest_share)


def _repair(geom, *, keep_largest_share):
    """:func:`repair_polygonal` of anything but a GeometryCollection."""
    import shapely
    from shapely.geometry import MultiPolygon, Polygon

    if geom is None or geom.is_empty:
        return None, "empty geometry"
    if geom.geom_type not in ("Polygon", "MultiPolygon"):
        return None, f"not a polygon ({geom.geom_type})"
    if not np.isfinite(shapely.get_coordinates(geom)).all():
        return None, "coordinates not finite (NaN or infinite)"
    try:
        geom = shapely.remove_repeated_points(geom, 1e-9)
    except shapely.errors.GEOSException:  # a ring left with fewer than 3 distinct vertices
        return None, "degenerate outline (a ring of fewer than 3 distinct vertices)"
    if geom.is_valid:
        if geom.area > 0:
            return geom, ""
        return None, "zero area"
    why = shapely.is_valid_reason(geom).split("[")[0]
    try:
        fixed = shapely.make_valid(geom)
    except shapely.errors.GEOSException as exc:
        return None, f"invalid outline ({why}) that could not be repaired: {exc}"
    polys = [g for g in getattr(fixed, "geoms", [fixed]) if isinstance(g, (Polygon, MultiPolygon))]
    parts = []
    for g in polys:
        parts.extend(getattr(g, "geoms", [g]))
    parts = [p for p in parts if p.area > 0]
    if not parts:
        return None, f"invalid outline ({why}) that could not be repaired"
    if len(parts) == 1:
        return parts[0], f"repaired invalid outline ({why})"
    if geom.geom_type == "MultiPolygon":
        return MultiPolygon(parts), f"repaired invalid outline ({why})"
    areas = np.array([p.area for p in parts])
    share = float(areas.max() / areas.sum())
    if share >= keep_largest_share:
        return (parts[int(np.argmax(areas))],
                f"repaired {why.lower()}: kept the largest of {len(parts)} parts "
                f"({100 * share:.0f} % of the area)")
    return None, (f"self-intersecting outline splits into {len(parts)} parts of comparable "
                  f"size (largest {100 * share:.0f} % of the area): fix the footprint")


@contextlib.contextmanager
def no_pam():
    """GDAL's PAM off while reading with pyogrio: opening a GeoPackage that holds dataset
    metadata read-only would otherwise leave ``X.gpkg.aux.xml`` beside the user's file."""
    import pyogrio

    before = pyogrio.get_gdal_config_option("GDAL_PAM_ENABLED")
    pyogrio.set_gdal_config_options({"GDAL_PAM_ENABLED": "NO"})
    try:
        yield
    finally:
        pyogrio.set_gdal_config_options({"GDAL_PAM_ENABLED": before})


@functools.lru_cache(maxsize=32)
def _layers(path: str, stamp: tuple) -> tuple:
    """``((name, geometry type or None), ...)`` of a vector source (``stamp``: its mtime and
    size, so that a file rewritten in the same process is listed again)."""
    import pyogrio

    with no_pam():
        return tuple((str(n), None if t is None else str(t)) for n, t in pyogrio.list_layers(path))


def footprint_layer(path, layer=None):
    """The layer of ``path`` that holds the footprints: ``layer`` when given, else its only
    layer, else its only layer of polygons (beside points, lines or tables).

    OGR reads the first layer of a source when none is named: a GeoPackage whose first
    layer is roads or parcels gave models of the wrong polygons, or none, without a word.

    Raises
    ------
    InputError
        When several layers may hold polygons and none is named: the message lists them.
    FileFormatError
        If the source cannot be opened.
    """
    if layer is not None:
        return layer
    p = check_input_file(path)
    try:
        st = p.stat()
        layers = _layers(str(p), (st.st_mtime_ns, st.st_size))
    except Exception as exc:  # pyogrio.errors.DataSourceError
        raise _unreadable(p, exc) from None
    if len(layers) <= 1:
        return None
    polygonal = [n for n, t in layers if t is not None and ("Polygon" in t or t == "Unknown")]
    if len(polygonal) == 1:
        logger.info("%s: reading its only polygon layer %r", p.name, polygonal[0])
        return polygonal[0]
    listed = ", ".join(f"{n} ({t or 'no geometry'})" for n, t in layers)
    raise InputError(f"{str(p)!r} holds {len(layers)} layers ({listed}): name the footprints' "
                     f"layer with --layer NAME (reconstruct), or save it on its own: "
                     f"ogr2ogr f.gpkg {p.name} NAME")


def vector_crs(path, *, layer=None):
    """The CRS of a vector source's layer (default the first), or None when it has none.

    Raises
    ------
    FileFormatError
        If the source cannot be opened.
    """
    from pyproj import CRS

    from .gpkg import gpkg_crs

    p = check_input_file(path)
    # a plain GeoPackage's CRS read with sqlite3: GDAL (~0.05 CPU s of import, ~20 MB of
    # its code resident) is then never loaded by a run whose footprints it also reads
    # without it (:func:`lidar2city.io.gpkg.read_gpkg_raw`). A geographic one is asked to
    # GDAL, whose total bounds the check of its coordinates needs
    plain = gpkg_crs(p, layer=layer)
    if plain is not None:
        crs = CRS.from_user_input(plain)
        if not crs.is_geographic:
            return crs
    import pyogrio

    layer = footprint_layer(p, layer)
    try:
        with no_pam():
            info = pyogrio.read_info(str(p), layer=layer)
    except Exception as exc:  # pyogrio.errors.DataSourceError / DataLayerError
        raise _unreadable(p, exc) from None
    wkt = info.get("crs")
    return _declared_crs(CRS.from_user_input(wkt) if wkt else None, info.get("total_bounds"), p)


_WARNED: set = set()


def _declared_crs(crs, bounds, p):
    """``crs``, or None when it is geographic and the coordinates cannot be degrees: a
    GeoJSON without a ``crs`` member is WGS 84 to GDAL (RFC 7946), whatever its
    coordinates, and projected ones then reprojected as degrees become NaN."""
    if crs is None or not crs.is_geographic or bounds is None:
        return crs
    b = np.asarray(bounds, dtype=np.float64)
    degrees = np.abs(b[[0, 2]]).max() <= 360 and np.abs(b[[1, 3]]).max() <= 90
    if not np.isfinite(b).all() or degrees:
        return crs
    if str(p) not in _WARNED:
        _WARNED.add(str(p))
        logger.warning("%s says %s (GeoJSON's default when none is given) but its coordinates "
                       "(x %.0f..%.0f, y %.0f..%.0f) are not degrees: taken to have no CRS",
                       p.name, crs.name, b[0], b[2], b[1], b[3])
    return None


def no_usable_footprint(path, geometries, notes) -> None:
    """Raise when no footprint of the source ``path`` is a usable polygon, saying why.

    Raises
    ------
    EmptyInputError
        When every geometry is None (``notes``: the reason of each).
    """
    if len(geometries) and all(g is None for g in geometries):
        from collections import Counter

        why = "; ".join(f"{k}" + (f" (x{c})" if c > 1 else "") for k, c in Counter(notes).items())
        raise EmptyInputError(f"{str(path)!r}: none of its {len(geometries)} footprint(s) is a "
                              f"usable polygon: {why}")


def overlapping(geometries, *, min_area: float = 1.0) -> tuple:
    """Pairs of footprints that overlap by more than ``min_area`` (m2, local metres).

    Footprints sharing a wall meet along it (an overlap of about nothing); two
    that overlap more each take the points of the overlap, so their models
    overlap and their heights mix the two roofs. Outlines repeated exactly are
    left out (said apart).

    Parameters
    ----------
    geometries : sequence of shapely geometries or None

    Returns
    -------
    pairs : int
    largest : float
        The largest overlap (m2), 0.0 when none.

    Examples
    --------
    >>> from shapely import box
    >>> overlapping([box(0, 0, 4, 4), box(3, 0, 7, 4), box(7, 0, 9, 4), box(0, 0, 4, 4)])
    (2, 4.0)
    """
    import shapely

    g = np.array([x if x is not None and not x.is_empty else None for x in geometries],
                 dtype=object)
    ok = np.flatnonzero(g != None)  # noqa: E711 (element-wise)
    if len(ok) < 2:
        return 0, 0.0
    g = g[ok]
    i, j = shapely.STRtree(g).query(g, predicate="intersects")
    pair = i < j
    i, j = i[pair], j[pair]
    area = shapely.area(shapely.intersection(g[i], g[j]))
    big = (area > min_area) & ~shapely.equals_exact(g[i], g[j], tolerance=0.0)
    return int(big.sum()), float(area[big].max()) if big.any() else 0.0


def _id_text(value):
    """A footprint id as text, or None when it is missing (null, NaN, blank); a whole
    float (an integer column with nulls, read as floats) without its ``.0``."""
    if value is None:
        return None
    if isinstance(value, float | np.floating):
        if not np.isfinite(value):
            return None
        if float(value).is_integer():
            return str(int(value))
    text = str(value).strip()
    return text or None


#: footprints whose vertices are on average closer than this (m) are densified outlines
DENSE_SPACING = 0.05
#: their vertices within this distance (m) of the line through their neighbours are dropped
THIN_TOLERANCE = 0.001


def _thinned(geoms, xy_unit, p):
    """``geoms`` with the densified ones (a vertex every few cm, from shapely.segmentize or
    a raster tracer) simplified within :data:`THIN_TOLERANCE`: each vertex is a wall face
    of a model (one every cm: 10 times the time and 90 times the file of the same models)."""
    import shapely

    n = shapely.get_num_coordinates(geoms)
    with np.errstate(divide="ignore", invalid="ignore"):
        dense = (n > 8) & (shapely.length(geoms) * xy_unit / np.maximum(n, 1) < DENSE_SPACING)
    if not dense.any():
        return geoms
    geoms = np.array(geoms, dtype=object)
    thin = shapely.simplify(geoms[dense], THIN_TOLERANCE / xy_unit, preserve_topology=True)
    said = ("thinned", str(p))  # once per file, though a run reads it more than once
    if said in _WARNED:
        geoms[dense] = thin
        return geoms
    _WARNED.add(said)
    logger.warning("%d footprint(s) of %s have vertices closer than %g m on average: those within "
                   "%g m of a straight line are dropped (%d vertices -> %d)", int(dense.sum()),
                   p.name, DENSE_SPACING, THIN_TOLERANCE, int(n[dense].sum()),
                   int(shapely.get_num_coordinates(thin).sum()))
    geoms[dense] = thin
    return geoms


def read_footprints(path, *, layer=None, id_field=None, origin=(0.0, 0.0), xy_unit=1.0,
                    target_crs=None, bbox=None, fids=None, skip_features=0, max_features=None,
                    unique_ids=True, with_fids=False) -> tuple[Footprints, object]:
    """Read building footprints from any OGR source into local metric coordinates.

    Parameters
    ----------
    path : str or Path
        GPKG, shapefile, GeoJSON, SQLite...
    layer : str or int, optional
        Layer to read (default: the first).
    id_field : str, optional
        Field holding the building identifier; default: the first of
        ``identificatie``, ``identificatiebagpnd``, ``id``, ``fid``, ``OBJECTID``
        present, else the feature id.
    origin, xy_unit
        Local frame of the point cloud (world origin in CRS units, metres per unit).
    target_crs : pyproj.CRS, optional
        CRS of the point cloud; footprints in another CRS are reprojected.
    bbox : tuple, optional
        (xmin, ymin, xmax, ymax) in the source's coordinates to read only part.
    fids : sequence of int, optional
        Read only these features (OGR feature ids), in this order.
    skip_features, max_features : int, optional
        Read only the features from ``skip_features`` on, at most ``max_features``
        (a large source scanned in chunks).
    unique_ids : bool
        Suffix repeated ids (``-2``, ``-3``...) to keep them usable as keys; a
        caller reading part of a source makes them unique over the whole itself.
    with_fids : bool
        Put the OGR feature ids in ``attributes['_fid']``.

    Returns
    -------
    footprints : Footprints
        Geometries (Polygon/MultiPolygon, or None with ``attributes['_note']``
        saying why), ids and the other fields.
    crs : pyproj.CRS or None
        The source's CRS.
    """
    import shapely
    from pyproj import CRS, Transformer

    from .gpkg import read_gpkg_raw

    p = check_input_file(path)
    fids_given = fids
    # a plain GeoPackage is read with sqlite3: the same features without GDAL's memory
    raw = None if bbox is not None else read_gpkg_raw(
        p, layer=layer, fids=fids, skip_features=skip_features, max_features=max_features)
    if raw is None:
        raw = _read_ogr(p, layer=footprint_layer(p, layer), bbox=bbox, fids=fids,
                        skip_features=skip_features, max_features=max_features)
    meta, fids, wkb, field_data = raw
    if wkb is None and not meta.get("geometry_type"):
        raise FileFormatError(
            f"{str(p)!r} has no geometry: footprints are polygons (GeoPackage, Shapefile, "
            "GeoJSON, FlatGeobuf, or a CSV with a WKT column)")
    n = len(wkb) if wkb is not None else 0
    if n == 0:
        if skip_features or max_features is not None:
            return Footprints([], [], {}), None
        raise EmptyInputError(f"{str(p)!r} holds no footprints")
    geoms = shapely.from_wkb(wkb)
    src_crs = _declared_crs(CRS.from_user_input(meta["crs"]) if meta.get("crs") else None,
                            shapely.total_bounds(geoms), p)
    if shapely.has_z(geoms).any():
        geoms = shapely.force_2d(geoms)
    if target_crs is not None and src_crs is not None and not src_crs.equals(target_crs, ignore_axis_order=True):
        try:
            tr = Transformer.from_crs(src_crs, target_crs, always_xy=True)
        except Exception as exc:
            raise CRSError(f"cannot transform footprints from {src_crs.name} to {target_crs.name}: {exc}") from None
        geoms = shapely.transform(geoms, lambda c: np.column_stack(tr.transform(c[:, 0], c[:, 1])))
    geoms = _thinned(geoms, xy_unit, p)
    names = list(meta["fields"])
    fields = {name: list(values) for name, values in zip(names, field_data, strict=True)}
    if id_field is not None and id_field not in fields:
        raise InputError(f"footprint id field {id_field!r} not found; fields: {', '.join(names)}")
    if id_field is None:
        id_field = next((f for f in ("identificatie", "identificatiebagpnd", "id", "fid", "OBJECTID")
                         if f in fields), None)
    ids = [str(int(f)) for f in fids]
    if id_field:
        named = [_id_text(v) for v in fields[id_field]]
        if None in named:
            logger.warning("%d footprint(s) of %s have no %r: named by their feature id",
                           named.count(None), p.name, id_field)
        ids = [f if v is None else v for v, f in zip(named, ids, strict=True)]
    if unique_ids:
        ids = unique(ids)
    out, notes = [], []
    for g in geoms:
        fixed, note = repair_polygonal(g)
        out.append(fixed)
        notes.append(note)
        if note:
            logger.info("footprint %s", note)
    if fids_given is None and not skip_features and max_features is None:
        no_usable_footprint(p, out, notes)  # a part read (a block, a chunk) may be empty
    local = [None if g is None else to_local(g, origin, xy_unit) for g in out]
    fields["_note"] = notes
    if with_fids:
        fields["_fid"] = [int(f) for f in fids]
    return Footprints(local, ids, fields), src_crs


def _read_ogr(p, *, layer, bbox, fids, skip_features, max_features):
    """``pyogrio.raw.read`` of a vector source (2-D, with feature ids)."""
    import pyogrio

    try:
        with no_pam():
            return pyogrio.raw.read(
                str(p), layer=layer, force_2d=True, return_fids=True, bbox=bbox,
                fids=None if fids is None else np.asarray(fids, dtype=np.int64),
                skip_features=skip_features, max_features=max_features)
    except Exception as exc:  # pyogrio.errors.DataSourceError / DataLayerError
        raise _unreadable(p, exc) from None


_POLYGONS = ("footprints are polygons: GeoPackage, Shapefile, GeoJSON, FlatGeobuf, or a CSV "
             "with a WKT column")
#: leading bytes of the files a user may give where footprints are expected
_SIGNATURES = ((b"LASF", "it is a LAS/LAZ point cloud (tiles are the inputs); " + _POLYGONS),
               (b"ply", "it is a PLY point cloud; " + _POLYGONS),
               (b"II*\x00", "it is a GeoTIFF raster (a DSM goes in with --dsm); " + _POLYGONS),
               (b"MM\x00*", "it is a GeoTIFF raster (a DSM goes in with --dsm); " + _POLYGONS))


def _unreadable(p, exc) -> FileFormatError:
    """The error for a source OGR cannot open: what the file is when its first bytes
    say so (a tile, a raster, a CityJSON model), else OGR's first line."""
    try:
        with open(p, "rb") as f:
            head = f.read(256)
    except OSError:
        head = b""
    what = next((w for sig, w in _SIGNATURES if head.startswith(sig)), None)
    if what is None and head.lstrip().startswith(b"{") and b'"CityJSON"' in head:
        what = "it is a CityJSON model; " + _POLYGONS
    return FileFormatError(f"{str(p)!r} is not a readable vector source: "
                           f"{what or str(exc).splitlines()[0]}")


def unique(ids) -> list:
    """``ids`` with repeated ones suffixed ``-2``, ``-3``... in order (usable as keys)."""
    if len(set(ids)) == len(ids):
        return list(ids)
    seen: dict[str, int] = {}
    out = []
    for i in ids:
        seen[i] = seen.get(i, 0) + 1
        out.append(i if seen[i] == 1 else f"{i}-{seen[i]}")
    return out


@dataclass(eq=False)
class VectorLayer:
    """One layer to write: local geometries, per-feature fields, geometry type."""

    name: str
    geometries: list
    fields: dict = field(default_factory=dict)
    geometry_type: str = "MultiPolygon"


def _field_array(values):
    arr = np.asarray(values)
    if arr.dtype.kind in "biuf":
        return arr
    if arr.dtype.kind == "U":
        return arr.astype(object)
    return np.array([None if v is None else (v if isinstance(v, (str, int, float)) else str(v))
                     for v in values], dtype=object)


#: OGR driver by output extension (pyogrio cannot tell GeoJSON from JSONFG for .json)
DRIVERS = {".gpkg": "GPKG", ".shp": "ESRI Shapefile", ".geojson": "GeoJSON", ".json": "GeoJSON",
           ".fgb": "FlatGeobuf"}


def write_layers(path, layers, *, origin, crs, xy_unit=1.0, z_unit=1.0, driver=None,
                 metadata=None) -> None:
    """Write several layers into one vector file (GPKG default), atomically.

    Geometries are local metric shapely objects; they are converted to world
    coordinates in ``crs`` units.
    """
    import pyogrio
    import shapely

    if not layers:
        raise InputError("nothing to write")
    driver = driver or DRIVERS.get(Path(path).suffix.lower())
    with atomic_path(path) as tmp:
        for i, lyr in enumerate(layers):
            geoms = np.array(lyr.geometries, dtype=object)
            world = to_world(geoms, origin, xy_unit, z_unit) if len(geoms) else geoms
            wkb = shapely.to_wkb(world, output_dimension=3 if lyr.geometry_type.endswith("Z") or
                                 lyr.geometry_type.endswith("25D") else 2)
            names = list(lyr.fields)
            values = [_field_array(lyr.fields[k]) for k in names]
            for k, v in zip(names, values, strict=True):
                if len(v) != len(geoms):
                    raise InputError(f"field {k!r} has {len(v)} values for {len(geoms)} features")
            with warnings.catch_warnings(record=True) as said:
                warnings.simplefilter("always")
                pyogrio.raw.write(
                    str(tmp), wkb, values, names, layer=lyr.name, driver=driver,
                    geometry_type=lyr.geometry_type,
                    crs=crs.to_wkt() if crs is not None else None,
                    append=i > 0, promote_to_multi=None,
                    dataset_metadata=metadata if i == 0 and driver == "GPKG" else None,
                )
            for w in said:  # GDAL's notes (a Shapefile's field names cut to 10 characters)
                logger.warning("%s: %s", Path(path).name, w.message)


def write_polygons(path, geometries, fields=None, *, origin, crs, xy_unit=1.0, layer="footprints",
                   geometry_type="MultiPolygon") -> None:
    """Write 2-D polygons (local metric shapely) with their fields to one layer."""
    import shapely

    geoms = [shapely.geometry.MultiPolygon([g]) if g is not None and g.geom_type == "Polygon" else g
             for g in geometries]
    write_layers(path, [VectorLayer(layer, geoms, dict(fields or {}), geometry_type)],
                 origin=origin, crs=crs, xy_unit=xy_unit)
