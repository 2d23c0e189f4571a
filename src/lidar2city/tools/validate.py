"""``validate``: CityJSON schema and geometric validity of a model file, per building."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ObjectReport", "FileReport", "validate_model", "validate_file"]


@dataclass
class ObjectReport:
    """Validity of one City Object: ``issues`` as ``(lod, solid index, Issue)``."""

    id: str
    type: str
    geometries: int = 0
    issues: list = field(default_factory=list)

    @property
    def valid(self) -> bool:
        return not self.issues


@dataclass
class FileReport:
    """A validated file: schema errors (None when not checked) and per-object reports."""

    path: str
    schema_errors: list | None = None
    schema_note: str = ""
    objects: list = field(default_factory=list)

    @property
    def invalid_objects(self) -> list:
        return [o for o in self.objects if not o.valid]

    @property
    def valid(self) -> bool:
        return not self.schema_errors and not self.invalid_objects

    def summary(self) -> dict:
        codes: dict[int, int] = {}
        for o in self.invalid_objects:
            for _, _, issue in o.issues:
                codes[issue.code] = codes.get(issue.code, 0) + 1
        return {"objects": len(self.objects), "with_geometry": sum(o.geometries > 0 for o in self.objects),
                "invalid": len(self.invalid_objects),
                "schema": ("not checked" if self.schema_errors is None else
                           "valid" if not self.schema_errors else f"{len(self.schema_errors)} error(s)"),
                "codes": dict(sorted(codes.items()))}


def validate_model(model, *, planarity_tolerance=0.01, snap_tolerance=0.001,
                   overlap_tolerance=0.001) -> list[ObjectReport]:
    """Check every solid of a :class:`~lidar2city.io.cityjson.CityModel`.

    Solids (and MultiSolid / CompositeSolid members) are checked with
    :func:`lidar2city.validate.check_solid` in coordinates relative to the
    model's lower corner (CRS units: tolerances are in those units); the
    BuildingParts of a Building must not overlap (601). MultiSurface and
    CompositeSurface geometries of buildings are checked as shells too
    (closed, manifold, oriented), since LoD1/LoD2 buildings should be; those
    of other objects (terrain, roads, water) only polygon by polygon, as
    val3dity does: they do not enclose a volume.
    """
    from ..validate.solid import Issue, check_solid, parts_overlap

    origin = model.vertices.min(axis=0) if len(model.vertices) else np.zeros(3)
    reports = []
    kw = dict(planarity_tolerance=planarity_tolerance, snap_tolerance=snap_tolerance,
              overlap_tolerance=overlap_tolerance)
    for oid, obj in model.objects.items():
        rep = ObjectReport(str(oid), str(obj.get("type")))
        geoms = obj.get("geometry") or []
        rep.geometries = len(geoms)
        lods = sorted({str(g.get("lod")) for g in geoms})
        for lod in lods:
            shell = rep.type.startswith("Building") or any(
                g.get("type") not in _SURFACES for g in geoms if str(g.get("lod")) == lod)
            try:
                solids = model.solids(oid, lod=lod, include_children=False, origin=origin)
            except (TypeError, ValueError, IndexError, KeyError, AttributeError) as exc:
                # boundaries or semantics not as the schema wants: nothing to check
                rep.issues.append((lod, 0, Issue(901, None, f"geometry unreadable ({exc})")))
                continue
            for k, s in enumerate(solids):
                for issue in check_solid(s, shell=shell, **kw):
                    rep.issues.append((lod, k, issue))
        children = [c for c in obj.get("children", []) or []
                    if model.objects.get(c, {}).get("type") == "BuildingPart"]
        if len(children) > 1:
            by_lod: dict[str, list] = {}
            for c in children:
                for g in model.objects[c].get("geometry") or []:
                    by_lod.setdefault(str(g.get("lod")), []).append(c)
            for lod, ids in by_lod.items():
                parts = [s for c in ids for s in model.solids(c, lod=lod, include_children=False,
                                                                origin=origin)]
                for a, b in parts_overlap(parts, tolerance=overlap_tolerance):
                    rep.issues.append((lod, a, Issue(601, None, f"parts {a} and {b} overlap")))
        reports.append(rep)
    return reports


#: geometry types that are surfaces, not solids
_SURFACES = ("MultiSurface", "CompositeSurface")


def validate_file(path, *, schema_dir=None, schema: bool = True, **tolerances) -> FileReport:
    """Schema (when the schemas are available) and geometric validation of a CityJSON file."""
    from ..io.cityjson import read_cityjson, read_json_documents
    from ..validate.schema import find_schema_dir, schema_errors

    report = FileReport(str(path))
    if schema:
        if find_schema_dir(schema_dir) is None:
            report.schema_note = ("CityJSON schemas not found (pass --schemas DIR or set "
                                  "LIDAR2CITY_CITYJSON_SCHEMAS): schema not checked")
        else:
            docs = read_json_documents(path)
            errors = []
            for i, doc in enumerate(docs):
                for e in schema_errors(doc, schema_dir=schema_dir):
                    errors.append(e if len(docs) == 1 else f"line {i + 1}: {e}")
            if docs and docs[0].get("version") != "2.0":
                report.schema_note = f"file is CityJSON {docs[0].get('version')}; schemas are 2.0.2"
            report.schema_errors = errors
    model = read_cityjson(path)
    report.objects = validate_model(model, **tolerances)
    return report
