"""``evaluate model``: how well a 3-D building model fits the points, per building.

For each Building of a CityJSON file (ours or a peer's, 1.0 to 2.0): the
building points (class 6 by default) inside its footprint, their RMSE of 3-D
distances to the building's triangulated surface (point to mesh, as 3DBAG
roofer's ``rf_rmse``), the share of the footprint covered by points, and the
geometric validity of its solids.

Footprints are the building's own (the horizontal projection of its model)
unless given: then the points inside each given footprint are measured
against the model building matched by id (the footprint id, or any of its
fields equal to the object id) or, failing that, by the largest footprint
overlap (IoU >= ``min_iou``).
"""

from __future__ import annotations

import logging
import time

import numpy as np

logger = logging.getLogger(__name__)

__all__ = ["model_footprint", "evaluate_buildings", "evaluate_model", "summarise"]


def model_footprint(solids):
    """Horizontal projection (shapely, local metres) of solids: the union of their faces."""
    import shapely

    from ..lod.mesh import solid_mesh

    tris = []
    for s in solids:
        t, _ = solid_mesh(s)
        c = np.asarray(s.vertices)[t][:, :, :2]
        area = (c[:, 1, 0] - c[:, 0, 0]) * (c[:, 2, 1] - c[:, 0, 1]) - \
            (c[:, 2, 0] - c[:, 0, 0]) * (c[:, 1, 1] - c[:, 0, 1])
        c = c[np.abs(area) > 1e-9]
        if len(c):
            tris.append(shapely.polygons(np.concatenate([c, c[:, :1]], axis=1)))
    if not tris:
        return None
    return shapely.union_all(np.concatenate(tris), grid_size=1e-4).buffer(0)


def evaluate_buildings(model, xyz, *, origin, unit_scale=(1.0, 1.0, 1.0), footprints=None,
                       lod=None, coverage_cell=1.0, min_iou=0.5, check=True) -> list[dict]:
    """Per-building RMSE, coverage and validity rows.

    Parameters
    ----------
    model : CityModel
    xyz : ndarray, shape (N, 3)
        Building points, local metres (``(world - origin) * unit_scale``).
    origin, unit_scale
        The local frame of ``xyz``.
    footprints : Footprints, optional
        Point sets to measure (see module doc); default the model's own.
    lod : str, optional
        LoD to evaluate (default the highest per building).
    """
    import shapely

    from ..lod.mesh import solid_triangles
    from ..metrics.model import footprint_coverage, point_mesh_distance, rmse
    from ..tools.reconstruct import PointGrid
    from ..validate.solid import check_solid

    grid = PointGrid(xyz[:, :2], cell=10.0)
    ids = model.buildings()
    solids = {b: model.solids(b, lod=lod, origin=origin, unit_scale=unit_scale) for b in ids}
    feet = {b: model_footprint(s) for b, s in solids.items()}
    rows = []
    if footprints is None:
        targets = [(b, feet[b], b, "own") for b in ids]
    else:
        objs = [b for b in ids if feet[b] is not None]
        tree = shapely.STRtree([feet[b] for b in objs])
        by_attr: dict[str, str] = {}
        for b in ids:
            by_attr[b] = b
        targets = []
        fields = footprints.attributes
        for i, (fid, g) in enumerate(zip(footprints.ids, footprints.geometries, strict=True)):
            match, how = None, ""
            candidates = [fid] + [str(v[i]) for k, v in fields.items() if not k.startswith("_")]
            for c in candidates:
                if c in by_attr:
                    match, how = c, "id"
                    break
            if match is None and g is not None:
                best = 0.0
                for j in tree.query(g):
                    f = feet[objs[j]]
                    inter = g.intersection(f).area
                    iou = inter / max(g.union(f).area, 1e-12)
                    if iou > best:
                        best, match = iou, objs[j]
                if best < min_iou:
                    match = None
                how = "overlap" if match else ""
            targets.append((fid, g, match, how))
            if match is None:
                logger.info("footprint %s: no matching building in the model", fid)
    for name, foot, obj, how in targets:
        row = {"id": name, "object": obj, "match": how, "points": 0, "rmse": None, "coverage": None,
               "valid": None, "errors": ""}
        if obj is None or foot is None or not solids.get(obj):
            row["errors"] = "no model"
            rows.append(row)
            continue
        x0, y0, x1, y1 = foot.bounds
        idx = grid.query(x0, y0, x1, y1)
        idx = idx[shapely.contains_xy(foot, xyz[idx, 0], xyz[idx, 1])]
        pts = xyz[idx]
        row["points"] = len(pts)
        row["coverage"] = round(footprint_coverage(foot, pts[:, :2], cell=coverage_cell), 4)
        if len(pts):
            row["rmse"] = round(rmse(point_mesh_distance(pts, solid_triangles(solids[obj]))), 4)
        if check:
            codes = sorted({i.code for s in solids[obj] for i in check_solid(s)})
            row["valid"] = not codes
            row["errors"] = " ".join(map(str, codes))
        rows.append(row)
    return rows


def summarise(rows) -> dict:
    """Median / mean RMSE, coverage and validity counts of :func:`evaluate_buildings` rows."""
    r = np.array([row["rmse"] for row in rows if row["rmse"] is not None], dtype=float)
    cov = np.array([row["coverage"] for row in rows if row["coverage"] is not None], dtype=float)
    return {
        "buildings": len(rows),
        "with_model": sum(row["object"] is not None and row["errors"] != "no model" for row in rows),
        "measured": int(len(r)),
        "rmse_median": round(float(np.median(r)), 4) if len(r) else None,
        "rmse_mean": round(float(np.mean(r)), 4) if len(r) else None,
        "rmse_p90": round(float(np.percentile(r, 90)), 4) if len(r) else None,
        "coverage_median": round(float(np.median(cov)), 4) if len(cov) else None,
        "valid": sum(row["valid"] is True for row in rows),
        "invalid": sum(row["valid"] is False for row in rows),
    }


def evaluate_model(model_path, points, *, crs=None, footprints=None, id_field=None, lod=None,
                   building_classes=(6,), check=True) -> tuple[list[dict], dict]:
    """Read a model file and point tiles; return per-building rows and a summary."""
    from ..crs import parse_crs, unit_factors
    from ..errors import InputError
    from ..io.cityjson import read_cityjson
    from ..io.las import read_points
    from ..io.vector import read_footprints

    t0 = time.perf_counter()
    model = read_cityjson(model_path)
    cloud = read_points(points, crs=crs)
    cloud.require_points()
    cls = cloud.get("classification")
    if cls is None or not np.isin(cls, building_classes).any():
        raise InputError("the points have no building class: run lidar2city classify first")
    xyz = cloud.xyz[np.isin(cls, building_classes)]
    crs_obj = cloud.crs if cloud.crs is not None else parse_crs(crs)
    xy_unit, z_unit = unit_factors(crs_obj) if crs_obj is not None else (1.0, 1.0)
    fps = None
    if footprints is not None:
        fps, _ = read_footprints(footprints, id_field=id_field, origin=cloud.origin[:2],
                                 xy_unit=cloud.xy_unit, target_crs=cloud.crs)
    rows = evaluate_buildings(model, xyz, origin=cloud.origin, unit_scale=(xy_unit, xy_unit, z_unit),
                              footprints=fps, lod=lod, check=check)
    summary = summarise(rows)
    if summary["with_model"] and not any(row["points"] for row in rows):
        raise InputError(f"none of the model's {summary['with_model']} building(s) has a building "
                         "point of the tiles inside it: do the tiles cover the model, in its CRS?")
    summary["seconds"] = round(time.perf_counter() - t0, 2)
    return rows, summary
