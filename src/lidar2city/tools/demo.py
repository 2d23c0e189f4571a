"""``demo``: a synthetic town, reconstructed end to end and compared with its truth.

The town (:func:`lidar2city.synthetic.make_town`) is written as a raw LAZ tile
(no classes) with its map footprints; lidar2city then filters the ground,
classifies buildings and vegetation, traces and regularises footprints, builds
LoD1.2 and LoD2.2 models, validates them and reports how close each step is to
the truth.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..datamodel import ASPRS

logger = logging.getLogger(__name__)

__all__ = ["DemoReport", "run_demo"]


@dataclass
class DemoReport:
    """What the demo made and measured."""

    outputs: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    buildings: list = field(default_factory=list)
    seconds: float = 0.0

    def lines(self) -> list[str]:
        m = self.metrics
        out = [
            f"synthetic town: {m['points']:,} points, {m['n_buildings']} buildings "
            f"({', '.join(f'{k} {v}' for k, v in sorted(m['roof_types'].items()))}), "
            f"{m['n_trees']} trees",
            f"ground filter:   total error {100 * m['ground']['total']:.2f} %, kappa "
            f"{100 * m['ground']['kappa']:.1f} %",
            f"classification:  building F1 {m['building_f1']:.3f}, vegetation F1 {m['vegetation_f1']:.3f}",
            f"footprints:      quality (IoU of all) {m['footprints']['quality']:.3f}, "
            f"{m['footprints']['matched']}/{m['n_buildings']} matched at IoU >= 0.5, "
            f"{100 * m['footprints']['aligned']:.1f} % of outline within 3 deg of the axes",
            f"LoD1.2:          median RMSE {m['lod12_rmse']:.3f} m",
            f"LoD2.2:          median RMSE {m['lod22_rmse']:.3f} m, roof type right "
            f"{m['roof_type_right']}/{m['n_buildings']}, ridge height error median "
            f"{m['ridge_error']:.3f} m",
            f"validity:        {m['valid']}/{m['n_solids']} solids valid"
            + ("" if m.get("schema") is None else f", CityJSON schema {'valid' if m['schema'] else 'INVALID'}"),
            "outputs:         " + ", ".join(str(p) for p in self.outputs.values()),
            f"done in {self.seconds:.1f} s",
        ]
        return out


def _f1(pred, ref):
    tp = np.count_nonzero(pred & ref)
    p = tp / max(np.count_nonzero(pred), 1)
    r = tp / max(np.count_nonzero(ref), 1)
    return 2 * p * r / (p + r) if p + r else 0.0


def run_demo(outdir, *, seed: int = 0, size=(200.0, 150.0), density: float = 10.0,
             schemas=None, progress=None) -> DemoReport:
    """Generate, reconstruct, validate and compare a synthetic town; write results to ``outdir``.

    Parameters
    ----------
    outdir : path
        Folder for the outputs (created if missing).
    seed : int
        Seed of the town.
    size : (float, float)
        Extent (m).
    density : float
        Points per square metre.
    schemas : path, optional
        Folder of the CityJSON 2.0 schemas; default found as ``lidar2city validate``
        finds them (the check is skipped when there are none).
    progress : callable, optional
        ``progress(step_name)`` before each step.
    """
    import shapely

    from ..classify import classify_points
    from ..footprints import extract_footprints
    from ..ground import ground_mask
    from ..io.las import write_points
    from ..io.vector import write_polygons
    from ..lod.lod1 import Lod1Config
    from ..metrics.footprints import area_metrics, axis_alignment, match_objects
    from ..metrics.ground import ground_errors
    from ..metrics.model import model_rmse
    from ..roof.building import Lod22Config
    from ..synthetic import make_town
    from ..io._atomic import make_output_dir
    from ..validate.solid import check_solid
    from .reconstruct import reconstruct_buildings, write_buildings

    def step(name):
        logger.info(name)
        if progress is not None:
            progress(name)

    t0 = time.perf_counter()
    out = make_output_dir(outdir)
    report = DemoReport()
    step("generating the town")
    town = make_town(size=size, density=density, seed=seed)
    cloud = town.cloud
    truth = cloud.get("classification")
    n = len(cloud)
    raw = cloud.with_attributes(classification=np.full(n, ASPRS.UNCLASSIFIED, dtype=np.uint8))
    report.outputs["raw tile"] = out / "town.laz"
    write_points(report.outputs["raw tile"], raw)
    report.outputs["map footprints"] = out / "footprints.gpkg"
    write_polygons(report.outputs["map footprints"], town.footprints.geometries,
                   {"id": town.footprints.ids, **town.footprints.attributes},
                   origin=cloud.origin, crs=cloud.crs)

    step("ground filtering")
    ground = ground_mask(raw.xyz)
    valid = truth != ASPRS.NOISE
    g_err = ground_errors(ground[valid], truth[valid] == ASPRS.GROUND)

    step("building / vegetation classification")
    classes = classify_points(raw.xyz, ground, return_number=raw.get("return_number"),
                              number_of_returns=raw.get("number_of_returns"))
    classified = raw.with_attributes(classification=classes)
    report.outputs["classified tile"] = out / "town_classified.laz"
    write_points(report.outputs["classified tile"], classified)
    veg = (ASPRS.LOW_VEGETATION, ASPRS.MEDIUM_VEGETATION, ASPRS.HIGH_VEGETATION)

    step("footprints from the points")
    fps = extract_footprints(classified.xyz, classes, regularize="snake")
    polys = [f.polygon for f in fps]
    report.outputs["footprints from points"] = out / "footprints_from_points.gpkg"
    write_polygons(report.outputs["footprints from points"], polys,
                   {k: [f.attributes.get(k) for f in fps] for k in ("area", "direction", "n_vertices")},
                   origin=cloud.origin, crs=cloud.crs)
    am = area_metrics(polys, town.footprints.geometries)
    mo = match_objects(polys, town.footprints.geometries)

    step("LoD1.2 and LoD2.2 models")
    cfg = Lod1Config(lods=("1.2",))
    results = reconstruct_buildings(classified, town.footprints, config=cfg, lod22=Lod22Config(),
                                    building=classes == ASPRS.BUILDING, ground=classes == ASPRS.GROUND)
    report.outputs["models"] = out / "town.city.json"
    write_buildings(report.outputs["models"], results, classified, lods=("1.2", "2.2"),
                    configuration={"demo": {"seed": seed, "size": list(size), "density": density}},
                    attributes={k: v for k, v in town.footprints.attributes.items()})

    step("validation and comparison with the truth")
    bxyz = cloud.xyz[truth == ASPRS.BUILDING]
    rm12, rm22, ridge_err, n_valid, n_solids, right = [], [], [], 0, 0, 0
    expected = {"gable": "gable", "hip": "hip", "flat": "flat", "shed": "shed", "L": "flat",
                "courtyard": "flat", "stepped": "flat"}
    for b, r in zip(town.buildings, results, strict=True):
        inside = shapely.contains_xy(b.footprint, bxyz[:, 0], bxyz[:, 1])
        pts = bxyz[inside]
        row = {"id": b.id, "truth": b.roof_type, "status": r.status}
        for lod, store in (("1.2", rm12), ("2.2", rm22)):
            solids = r.solids.get(lod)
            if solids is None:
                continue
            solids = solids if isinstance(solids, list) else [solids]
            for s in solids:
                n_solids += 1
                n_valid += not check_solid(s)
            e = model_rmse(pts, solids)
            store.append(e)
            row[f"rmse_{lod}"] = round(float(e), 3)
        found = r.attributes.get("roof_type")
        row["roof_type"] = found
        right += found == expected[b.roof_type]
        true_top = np.nanmax(b.roof_z(pts[:, :2])) if len(pts) else np.nan
        if "ridge_height" in r.attributes and np.isfinite(true_top):
            ridge_err.append(abs(r.attributes["ridge_height"] - true_top))
            row["ridge_error"] = round(float(ridge_err[-1]), 3)
        report.buildings.append(row)
    from ..io.cityjson import read_json_documents
    from ..validate.schema import find_schema_dir, schema_errors

    schema_dir = find_schema_dir(schemas)
    schema_ok = None
    if schema_dir is not None:
        (doc,) = read_json_documents(report.outputs["models"])
        schema_ok = not schema_errors(doc, schema_dir=schema_dir)
    types: dict = {}
    for b in town.buildings:
        types[b.roof_type] = types.get(b.roof_type, 0) + 1
    report.metrics = {
        "points": n,
        "n_buildings": len(town.buildings),
        "n_trees": town.n_trees,
        "roof_types": types,
        "ground": g_err,
        "building_f1": _f1(classes == ASPRS.BUILDING, truth == ASPRS.BUILDING),
        "vegetation_f1": _f1(np.isin(classes, veg), np.isin(truth, veg)),
        "footprints": {"quality": am["quality"], "matched": mo["matched"],
                       "aligned": axis_alignment(polys)["aligned_share"]},
        "lod12_rmse": float(np.median(rm12)) if rm12 else float("nan"),
        "lod22_rmse": float(np.median(rm22)) if rm22 else float("nan"),
        "roof_type_right": right,
        "ridge_error": float(np.median(ridge_err)) if ridge_err else float("nan"),
        "valid": n_valid,
        "n_solids": n_solids,
        "schema": schema_ok,
    }
    report.seconds = time.perf_counter() - t0
    return report
