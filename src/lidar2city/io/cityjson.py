"""CityJSON 2.0 (``.city.json``) and CityJSONSeq (``.city.jsonl``) writing and reading.

Writing: one ``Building`` per :class:`~lidar2city.datamodel.BuildingResult`
with its attributes (failed buildings too, without geometry, with
``status`` and ``reason``); the LoD1.2 and LoD2.2 models are the Building's
``Solid``; LoD1.3 parts, and the solids of a multi-part footprint (CityJSON
2.0 allows no ``MultiSolid`` on a Building), are ``BuildingPart`` children
(``"parents"`` / ``"children"``), one ``Solid`` each. Surfaces carry CityJSON semantics (GroundSurface, WallSurface,
RoofSurface). Vertices are quantised integers with a ``transform``
(``scale`` 0.001 CRS units, ``translate`` the local origin) and shared
between solids. The CRS goes to ``metadata.referenceSystem`` as an OGC URL.

The lidar2city version and the resolved configuration are stored in the
root property ``"+lidar2city"``: CityJSON 2.0 allows extra root
properties whose names start with ``+`` and its schema accepts them, while
``metadata`` is limited to its six ISO 19115 properties.

Reading accepts CityJSON 1.0, 1.1 and 2.0 (with or without ``transform``)
and CityJSONSeq; geometries become :class:`~lidar2city.datamodel.Solid`
(surfaces and rings of vertex indices) in world coordinates.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..datamodel import Solid, Surface
from ..errors import FileFormatError, InputError
from ._atomic import atomic_path, check_input_file

logger = logging.getLogger(__name__)

__all__ = ["CityModel", "cityjson_document", "cityjson_features", "write_cityjson",
           "write_cityjsonseq", "read_cityjson", "read_json_documents", "object_solids", "SEMANTIC_TYPES"]

#: The semantic surface types written by lidar2city.
SEMANTIC_TYPES = ("GroundSurface", "WallSurface", "RoofSurface")


def _json_value(v):
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        f = float(v)
        return f if np.isfinite(f) else None
    if isinstance(v, (np.bool_,)):
        return bool(v)
    if isinstance(v, np.ndarray):
        return [_json_value(x) for x in v.tolist()]
    if isinstance(v, (list, tuple)):
        return [_json_value(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _json_value(x) for k, x in v.items()}
    if v is None or isinstance(v, (str, int, bool)):
        return v
    return str(v)


class _VertexPool:
    """Quantised integer vertices shared between all geometries of a document."""

    def __init__(self, scale_local):
        self.scale_local = np.asarray(scale_local, dtype=np.float64)  # local metres per integer
        self.chunks: list[np.ndarray] = []
        self.count = 0

    def add(self, local_xyz) -> np.ndarray:
        q = np.round(np.asarray(local_xyz, dtype=np.float64) / self.scale_local).astype(np.int64)
        idx = np.arange(self.count, self.count + len(q))
        self.chunks.append(q)
        self.count += len(q)
        return idx

    def finish(self):
        """Deduplicated vertices and the old -> new index map."""
        if not self.chunks:
            return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
        allq = np.concatenate(self.chunks)
        uniq, inverse = np.unique(allq, axis=0, return_inverse=True)
        return uniq, inverse.ravel()


def _solid_boundaries(solid: Solid, index: np.ndarray):
    """Raw (pre-dedup) boundaries + semantic values of one solid (one outer shell)."""
    shell, values = [], []
    for s in solid.surfaces:
        shell.append([index[np.asarray(r, dtype=np.int64)] for r in s.rings])
        values.append(SEMANTIC_TYPES.index(s.semantic) if s.semantic in SEMANTIC_TYPES else None)
    return [shell], [values]


def _remap(boundaries, inverse):
    if isinstance(boundaries, np.ndarray):
        return inverse[boundaries].tolist()  # Python ints
    return [_remap(b, inverse) for b in boundaries]


def _geometry(solids, lod: str, pool: _VertexPool):
    """A raw CityJSON geometry (Solid or MultiSolid) for one or several solids."""
    if isinstance(solids, Solid):
        solids = [solids]
    bounds, values = [], []
    for s in solids:
        b, v = _solid_boundaries(s, pool.add(s.vertices))
        bounds.append(b)
        values.append(v)
    surfaces = [{"type": t} for t in SEMANTIC_TYPES]
    if len(solids) == 1:
        return {"type": "Solid", "lod": lod, "boundaries": bounds[0],
                "semantics": {"surfaces": surfaces, "values": values[0]}}
    return {"type": "MultiSolid", "lod": lod, "boundaries": bounds,
            "semantics": {"surfaces": surfaces, "values": values}}


def _building_objects(result, pool, extra_attributes=None):
    """CityObjects (raw boundaries) of one BuildingResult: the Building and its parts."""
    attrs = {k: _json_value(v) for k, v in (extra_attributes or {}).items()}
    attrs.update({k: _json_value(v) for k, v in result.attributes.items()})
    attrs["status"] = result.status
    if result.reason:
        attrs["reason"] = result.reason
    bid = str(result.id)
    building: dict[str, Any] = {"type": "Building", "attributes": attrs}
    objects = {bid: building}
    geoms = []
    parts_by_lod = dict(result.parts)
    for lod, solids in sorted(result.solids.items()):
        if isinstance(solids, (list, tuple)) and len(solids) == 1:
            solids = solids[0]
        if isinstance(solids, (list, tuple)):
            if solids:  # a multi-part footprint: one BuildingPart per solid
                parts_by_lod[lod] = list(parts_by_lod.get(lod, [])) + list(solids)
        elif solids is not None:
            geoms.append(_geometry(solids, lod, pool))
    if geoms:
        building["geometry"] = geoms
    children = []
    for lod, parts in sorted(parts_by_lod.items()):
        for k, part in enumerate(parts):
            pid = f"{bid}-lod{lod.replace('.', '')}-part{k + 1}"
            z = np.asarray(part.vertices)[:, 2]
            objects[pid] = {
                "type": "BuildingPart", "parents": [bid],
                "attributes": {"lod": lod, "roof_height": round(float(z.max()), 3),
                               "ground_height": round(float(z.min()), 3)},
                "geometry": [_geometry(part, lod, pool)],
            }
            children.append(pid)
    if children:
        building["children"] = children
    return objects


def _finish_objects(objects, pool):
    verts, inverse = pool.finish()
    for obj in objects.values():
        for g in obj.get("geometry", []):
            g["boundaries"] = _remap(g["boundaries"], inverse)
    return verts


def _header(origin, crs, xy_unit, z_unit, *, scale, extent_local, configuration, title):
    from .. import __version__
    from ..crs import ogc_url

    origin = np.asarray(origin, dtype=np.float64).reshape(3)
    doc: dict[str, Any] = {
        "type": "CityJSON",
        "version": "2.0",
        "transform": {"scale": [scale, scale, scale], "translate": [float(v) for v in origin]},
        "metadata": {},
    }
    url = ogc_url(crs)
    if url:
        doc["metadata"]["referenceSystem"] = url
    elif crs is not None:
        logger.warning("the CRS has no EPSG code: metadata.referenceSystem not written")
    if title:
        doc["metadata"]["title"] = title
    if extent_local is not None:
        unit = np.array([xy_unit, xy_unit, z_unit])
        lo = origin + np.asarray(extent_local[:3]) / unit
        hi = origin + np.asarray(extent_local[3:]) / unit
        doc["metadata"]["geographicalExtent"] = [round(float(v), 3) for v in (*lo, *hi)]
    doc["+lidar2city"] = {"version": __version__,
                          "configuration": _json_value(configuration or {})}
    return doc


def _extent(results):
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for r in results:
        for s in _all_solids(r):
            v = np.asarray(s.vertices)
            if len(v):
                lo = np.minimum(lo, v.min(axis=0))
                hi = np.maximum(hi, v.max(axis=0))
    return None if not np.all(np.isfinite(lo)) else np.concatenate([lo, hi])


def _all_solids(result):
    for solids in result.solids.values():
        if isinstance(solids, Solid):
            yield solids
        elif solids:
            yield from solids
    for parts in result.parts.values():
        yield from parts


def _scale_local(scale, xy_unit, z_unit):
    return np.array([scale * xy_unit, scale * xy_unit, scale * z_unit])


def cityjson_document(results, *, origin, crs=None, xy_unit=1.0, z_unit=1.0, scale=0.001,
                      configuration=None, attributes=None, title=None) -> dict:
    """A CityJSON 2.0 document (dict) of building results.

    Parameters
    ----------
    results : sequence of BuildingResult
        Models in local metric coordinates.
    origin : array_like, shape (3,)
        World coordinates (CRS units) of the local origin; the ``translate``.
    crs : pyproj.CRS, optional
    xy_unit, z_unit : float
        Metres per CRS unit.
    scale : float
        Quantisation step in CRS units (0.001: millimetres in a metric CRS).
    configuration : dict, optional
        Resolved configuration, stored under ``"+lidar2city"``.
    attributes : dict of str to list, optional
        Extra per-building attributes (e.g. the footprint source's fields),
        aligned with ``results``.
    """
    results = list(results)
    pool = _VertexPool(_scale_local(scale, xy_unit, z_unit))
    objects: dict[str, Any] = {}
    for i, r in enumerate(results):
        extra = {k: v[i] for k, v in (attributes or {}).items()}
        objects.update(_building_objects(r, pool, extra))
    verts = _finish_objects(objects, pool)
    doc = _header(origin, crs, xy_unit, z_unit, scale=scale, extent_local=_extent(results),
                  configuration=configuration, title=title)
    doc["CityObjects"] = objects
    doc["vertices"] = verts.tolist()
    return doc


def cityjson_features(results, *, scale=0.001, xy_unit=1.0, z_unit=1.0, attributes=None):
    """Yield one CityJSONFeature dict per building (its own vertex list)."""
    for i, r in enumerate(results):
        pool = _VertexPool(_scale_local(scale, xy_unit, z_unit))
        extra = {k: v[i] for k, v in (attributes or {}).items()}
        objects = _building_objects(r, pool, extra)
        verts = _finish_objects(objects, pool)
        yield {"type": "CityJSONFeature", "id": str(r.id), "CityObjects": objects,
               "vertices": verts.tolist()}


def write_cityjson(path, results, **kwargs) -> None:
    """Write a ``.city.json`` file atomically; keywords as :func:`cityjson_document`."""
    doc = cityjson_document(results, **kwargs)
    # json.dumps runs the C encoder; json.dump streams through the pure-Python one
    text = json.dumps(doc, separators=(",", ":"))
    del doc
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(text)


def write_cityjsonseq(path, results, *, origin, crs=None, xy_unit=1.0, z_unit=1.0, scale=0.001,
                      configuration=None, attributes=None, title=None) -> None:
    """Write a CityJSONSeq ``.city.jsonl`` file: a header line, then one feature per building."""
    results = list(results)
    head = _header(origin, crs, xy_unit, z_unit, scale=scale, extent_local=_extent(results),
                   configuration=configuration, title=title)
    head["CityObjects"] = {}
    head["vertices"] = []
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as f:
        f.write(json.dumps(head, separators=(",", ":")) + "\n")
        for feat in cityjson_features(results, scale=scale, xy_unit=xy_unit, z_unit=z_unit,
                                      attributes=attributes):
            f.write(json.dumps(feat, separators=(",", ":")) + "\n")


# --------------------------------------------------------------------------- reading


@dataclass(eq=False)
class CityModel:
    """A CityJSON file in memory: world vertices and the raw City Objects.

    ``vertices`` are world coordinates (transform applied), shape (N, 3);
    ``objects`` the ``CityObjects`` dict as in the file (boundaries index
    ``vertices``); ``crs`` the ``referenceSystem`` string (or None).
    """

    version: str
    vertices: np.ndarray
    objects: dict
    metadata: dict = field(default_factory=dict)
    crs: str | None = None
    extra: dict = field(default_factory=dict)
    transform: dict | None = None

    def buildings(self) -> list[str]:
        """Ids of the top-level Building objects."""
        return [k for k, o in self.objects.items() if o.get("type") == "Building"]

    def solids(self, object_id: str, *, lod: str | None = None, include_children: bool = True,
               origin=None, unit_scale=(1.0, 1.0, 1.0)) -> list[Solid]:
        """See :func:`object_solids`."""
        return object_solids(self, object_id, lod=lod, include_children=include_children,
                             origin=origin, unit_scale=unit_scale)


def _apply_transform(vertices, transform):
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if transform:
        v = v * np.asarray(transform.get("scale", [1, 1, 1]), dtype=np.float64) + \
            np.asarray(transform.get("translate", [0, 0, 0]), dtype=np.float64)
    return v


def read_json_documents(path) -> list[dict]:
    """The raw JSON objects of a CityJSON file (one) or CityJSONSeq file (header + features).

    Raises
    ------
    FileFormatError
        When the file is not JSON / JSON Lines.
    """
    p = check_input_file(path)
    other = _NOT_CITYJSON.get(p.suffix.lower())
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise FileFormatError(f"{str(p)!r} is not CityJSON: {other}" if other
                              else f"{str(p)!r} cannot be read: {exc}") from None
    try:
        return [json.loads(text)]
    except json.JSONDecodeError:
        if other:
            raise FileFormatError(f"{str(p)!r} is not CityJSON: {other}") from None
        pass
    try:
        return [json.loads(line) for line in text.splitlines() if line.strip()]
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"{str(p)!r} is not JSON: {exc}") from None


#: what a model file of another format given where CityJSON is read is, and what to do
_NOT_CITYJSON = {
    ext: f"it is {what}, read here as CityJSON (.city.json / .city.jsonl): make the model "
         "with -o NAME.city.json"
    for ext, what in ((".obj", "an OBJ mesh"), (".gpkg", "a GeoPackage"),
                      (".las", "a point cloud"), (".laz", "a point cloud"),
                      (".tif", "a raster"), (".ply", "a point cloud"))}


def read_cityjson(path) -> CityModel:
    """Read a CityJSON (1.0 / 1.1 / 2.0) or CityJSONSeq file.

    Raises
    ------
    FileFormatError
        When the file is not JSON or not CityJSON.
    """
    p = check_input_file(path)
    docs = read_json_documents(p)
    doc = docs[0] if docs else {}
    lines = docs if len(docs) > 1 else None
    if not isinstance(doc, dict) or doc.get("type") != "CityJSON":
        raise FileFormatError(f"{str(p)!r} is not a CityJSON file (no \"type\": \"CityJSON\")")
    transform = doc.get("transform")
    objects = dict(doc.get("CityObjects") or {})
    verts = [_apply_transform(doc.get("vertices") or [], transform)]
    count = len(verts[0])
    for feat in (lines or [])[1:]:
        if feat.get("type") != "CityJSONFeature":
            continue
        fv = _apply_transform(feat.get("vertices") or [], transform)
        for oid, obj in (feat.get("CityObjects") or {}).items():
            for g in obj.get("geometry", []):
                g["boundaries"] = _shift(g.get("boundaries", []), count)
            objects[oid] = obj
        verts.append(fv)
        count += len(fv)
    meta = doc.get("metadata") or {}
    extra = {k: v for k, v in doc.items() if k.startswith("+")}
    return CityModel(str(doc.get("version", "")), np.concatenate(verts), objects, meta,
                     meta.get("referenceSystem"), extra, transform)


def _shift(b, offset):
    if isinstance(b, list):
        return [_shift(x, offset) for x in b]
    return int(b) + offset


def _surfaces_of(boundaries, gtype, semantics):
    """Flatten a geometry into shells of Surfaces (one list per shell / solid)."""
    def sem(path):
        if not semantics:
            return ""
        vals = semantics.get("values")
        for k in path:
            if vals is None:
                return ""
            vals = vals[k]
        if vals is None:
            return ""
        surfs = semantics.get("surfaces", [])
        return surfs[vals].get("type", "") if 0 <= vals < len(surfs) else ""

    shells = []
    if gtype in ("MultiSurface", "CompositeSurface"):
        shells.append([Surface([np.asarray(r, dtype=np.int64) for r in poly], sem((i,)))
                       for i, poly in enumerate(boundaries)])
    elif gtype == "Solid":
        # exterior shell only (inner shells are cavities; LoD1/2 buildings have none)
        shells.append([Surface([np.asarray(r, dtype=np.int64) for r in poly], sem((0, i)))
                       for i, poly in enumerate(boundaries[0])])
    elif gtype in ("MultiSolid", "CompositeSolid"):
        for s, solid in enumerate(boundaries):
            shells.append([Surface([np.asarray(r, dtype=np.int64) for r in poly], sem((s, 0, i)))
                           for i, poly in enumerate(solid[0])])
    return shells


def object_solids(model: CityModel, object_id: str, *, lod: str | None = None,
                  include_children: bool = True, origin=None,
                  unit_scale=(1.0, 1.0, 1.0)) -> list[Solid]:
    """The solids (or surface sets) of a City Object, optionally with its children's.

    Parameters
    ----------
    model : CityModel
    object_id : str
    lod : str, optional
        Only geometries of this LoD (``"1"``, ``"1.2"``, ``"1.3"``...); default:
        the highest LoD the object (and its children) has.
    include_children : bool
        Add the geometries of child objects (BuildingParts).
    origin, unit_scale
        Convert world vertices to local metric ``(world - origin) * unit_scale``.

    Returns
    -------
    list of Solid
        One per solid (MultiSolid members separately); a MultiSurface gives one
        Solid-like surface set that need not be closed.
    """
    if object_id not in model.objects:
        raise InputError(f"no City Object {object_id!r}")
    ids = [object_id]
    if include_children:
        ids += list(model.objects[object_id].get("children", []))
    geoms = []
    for oid in ids:
        for g in model.objects.get(oid, {}).get("geometry", []) or []:
            geoms.append(g)
    if not geoms:
        return []
    if lod is None:
        def _lodkey(g):
            try:
                return float(str(g.get("lod", 0)))
            except ValueError:
                return 0.0
        best = max(_lodkey(g) for g in geoms)
        geoms = [g for g in geoms if _lodkey(g) == best]
    else:
        geoms = [g for g in geoms if str(g.get("lod")) == str(lod)]
    out = []
    verts = model.vertices
    if origin is not None:
        verts = (verts - np.asarray(origin, dtype=np.float64)) * np.asarray(unit_scale)
    for g in geoms:
        for shell in _surfaces_of(g.get("boundaries", []), g.get("type"), g.get("semantics")):
            if not shell:
                continue
            used = np.unique(np.concatenate([r for s in shell for r in s.rings]))
            if len(used) and (used[0] < 0 or used[-1] >= len(verts)):
                raise InputError(f"City Object {object_id!r}: vertex index {int(used[-1])} out of range "
                                 f"(the file has {len(verts)} vertices)")
            surfaces = [Surface([np.searchsorted(used, r) for r in s.rings], s.semantic)
                        for s in shell]
            out.append(Solid(verts[used], surfaces))
    return out
