"""``primitives``: one floating model (parametric primitive) per footprint.

Composes :mod:`lidar2city.fit.primitives` over a point cloud and its
footprints: selects each building's points and the ground around it, fits
the user's primitive (semi-automatic) or chooses one (automatic), and returns
a :class:`~lidar2city.datamodel.BuildingResult` per footprint with the LoD2.2
solid and the parameters with their standard deviations as attributes. A
building that cannot be modelled gets ``status="failed"`` and the reason; the
batch goes on.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..datamodel import ASPRS, BuildingResult, Footprints, PointCloud
from ..errors import FitError, InputError
from ..fit.lsm import polygon_rings, resample_rings
from ..fit.primitives import (
    PRIMITIVES,
    PrimitivesConfig,
    bilinear,
    datum_from_ground,
    fit_best,
    fit_primitive,
    main_polygon,
)

logger = logging.getLogger(__name__)

__all__ = ["reconstruct_primitives", "building_points", "write_check_images", "result_attributes"]


class _XIndex:
    """Points sorted by x for fast bounding-box queries."""

    def __init__(self, xyz):
        self.order = np.argsort(xyz[:, 0], kind="stable")
        self.xs = xyz[self.order, 0]
        self.xyz = xyz

    def query(self, xmin, ymin, xmax, ymax) -> np.ndarray:
        a = np.searchsorted(self.xs, xmin, side="left")
        b = np.searchsorted(self.xs, xmax, side="right")
        idx = self.order[a:b]
        y = self.xyz[idx, 1]
        return idx[(y >= ymin) & (y <= ymax)]

    def inside(self, geom) -> np.ndarray:
        import shapely

        idx = self.query(*geom.bounds)
        if len(idx) == 0:
            return idx
        p = self.xyz[idx]
        return idx[shapely.contains_xy(geom, p[:, 0], p[:, 1])]


def _split_classes(cloud: PointCloud):
    cls = cloud.get("classification")
    n = len(cloud)
    if cls is None:
        return np.ones(n, dtype=bool), np.zeros(n, dtype=bool), False
    cls = np.asarray(cls)
    ground = cls == ASPRS.GROUND
    building = cls == ASPRS.BUILDING
    if not building.any():
        building = ~ground & (cls != ASPRS.NOISE) & (cls != ASPRS.WATER)
    return building, ground, bool(ground.any())


def building_points(cloud: PointCloud, footprints: Footprints):
    """Per footprint, indices of its building points (class 6, else non-ground) inside it."""
    building, _, _ = _split_classes(cloud)
    bidx = np.flatnonzero(building)
    index = _XIndex(cloud.xyz[bidx])
    out = []
    for g in footprints.geometries:
        out.append(bidx[index.inside(g)] if g is not None and not g.is_empty else np.empty(0, np.int64))
    return out


def _datum(poly, cloud, gindex, gidx, allindex, dtm, cfg):
    if dtm is not None:
        samples = resample_rings(polygon_rings(poly), max(cfg.plan_interval, 1.0))
        world = cloud.to_world(samples)
        rc = dtm.world_to_pixel(world) - 0.5
        z = bilinear(dtm.array if dtm.array.ndim == 2 else dtm.array[0], rc[:, 0], rc[:, 1])
        z = z[np.isfinite(z)]
        if len(z):
            z = (z - cloud.origin[2]) * cloud.z_unit  # DTM heights in the CRS vertical unit
            return float(np.median(z)), float(1.2533 * np.std(z) / math.sqrt(len(z)))
    for scale in (1.0, 3.0):
        ring = poly.buffer(cfg.ground_buffer * scale).difference(poly)
        if gindex is not None:
            sel = gidx[gindex.inside(ring)]
            if len(sel) >= 3:
                return datum_from_ground(cloud.xyz[sel, 2], percentile=cfg.ground_percentile)
    ring = poly.buffer(cfg.ground_buffer * 3).difference(poly)
    sel = allindex.inside(ring)
    if len(sel) >= 3:
        # unclassified surroundings: a low percentile of every point around
        return datum_from_ground(cloud.xyz[sel, 2], percentile=min(cfg.ground_percentile, 5.0))
    raise FitError("no ground points or DTM around the footprint for the datum")


def result_attributes(model, cloud: PointCloud) -> dict:
    """Flat attributes of a fitted primitive: kind, parameters, std devs, fit statistics.

    ``x``, ``y``, ``z`` are converted to world coordinates (CRS units); lengths
    are metres, angles degrees.
    """
    p = dict(model.params)
    s = dict(model.std)
    if cloud is not None:
        p["x"], p["y"], p["z"] = (float(v) for v in cloud.to_world(np.array([p["x"], p["y"], p["z"]])))
        scale = cloud.unit_scale
        for k, i in (("x", 0), ("y", 1), ("z", 2)):
            if k in s:
                s[k] = s[k] / scale[i]
    attrs = {"primitive": model.kind}
    for k, v in p.items():
        attrs[f"primitive_{k}"] = float(v)
        if k in s:
            attrs[f"primitive_{k}_std"] = float(s[k])
    for k in s:
        if k not in p:
            attrs[f"primitive_{k}_std"] = float(s[k])
    for k, v in model.derived().items():
        attrs[f"primitive_{k}"] = float(v)
    for k in ("residual_rmse", "plan_rmse", "iterations", "n_points", "n_samples", "n_outline",
              "n_undetermined", "undetermined"):
        if k in model.info:
            attrs[f"primitive_{k}"] = model.info[k]
    return attrs


def _approx_local(approx: dict, cloud: PointCloud) -> dict:
    a = {k: v for k, v in approx.items() if k != "primitive" and v is not None}
    if "x" in a and "y" in a:
        a["x"], a["y"] = (float(v) for v in cloud.to_local(np.array([a["x"], a["y"]], dtype=float)))
    elif "x" in a or "y" in a:
        a.pop("x", None)
        a.pop("y", None)
    return a


def reconstruct_primitives(cloud: PointCloud, footprints: Footprints, *,
                           config: PrimitivesConfig | None = None,
                           user_primitives: dict | None = None, dtm=None,
                           progress=None) -> list[BuildingResult]:
    """Fit one primitive per footprint; return a result per footprint.

    Parameters
    ----------
    cloud : PointCloud
        Points with ``classification`` (6 building, 2 ground) when available;
        without it every point inside a footprint is a roof point and the
        datum comes from ``dtm`` or a low percentile of the points around.
    footprints : Footprints
        In the cloud's local metric frame.
    config : PrimitivesConfig, optional
    user_primitives : dict of str to dict, optional
        Semi-automatic mode: footprint id -> ``{"primitive": kind, <approx
        parameters>}`` (``x``, ``y`` in world CRS units; ``azimuth`` degrees
        counter-clockwise from east; lengths in metres), as read by
        :func:`lidar2city.io.primitives.read_primitives`. Other footprints use
        the automatic choice.
    dtm : lidar2city.io.raster.Raster, optional
        Terrain model for the datum heights (bilinear interpolation along the
        footprint outline, median), in the cloud's CRS.
    progress : callable, optional
        Called with 1 after each building.

    Returns
    -------
    list of BuildingResult
        ``solids["2.2"]`` the primitive's solid; ``attributes`` from
        :func:`result_attributes`; failed buildings with their reason.
    """
    cfg = config or PrimitivesConfig()
    user_primitives = dict(user_primitives or {})
    for fid, spec in user_primitives.items():
        kind = spec.get("primitive")
        if kind not in PRIMITIVES:
            raise InputError(f"footprint {fid}: unknown primitive {kind!r}; known: {', '.join(PRIMITIVES)}")
    building, ground, has_ground = _split_classes(cloud)
    bidx = np.flatnonzero(building)
    bindex = _XIndex(cloud.xyz[bidx])
    gidx = np.flatnonzero(ground)
    gindex = _XIndex(cloud.xyz[gidx]) if has_ground else None
    allindex = _XIndex(cloud.xyz)
    results = []
    for fid, geom in zip(footprints.ids, footprints.geometries, strict=True):
        res = BuildingResult(str(fid), footprint=geom)
        try:
            poly = main_polygon(geom)
            pts = cloud.xyz[bidx[bindex.inside(poly)]]
            context = cloud.xyz[bidx[bindex.inside(poly.buffer(cfg.outline_strip + 0.5))]]
            datum = _datum(poly, cloud, gindex, gidx, allindex, dtm, cfg)
            spec = user_primitives.get(str(fid))
            if spec is not None:
                model = fit_primitive(spec["primitive"], poly, pts, datum=datum,
                                      approx=_approx_local(spec, cloud), context=context, config=cfg)
                mode = "user"
            else:
                model, _ = fit_best(poly, pts, datum=datum, context=context, config=cfg)
                mode = "auto"
            if not model:
                raise FitError(f"{model.kind}: {model.reason}")
            res.solids["2.2"] = model.to_solid()
            res.attributes.update(result_attributes(model, cloud))
            res.attributes["primitive_choice"] = mode
            if geom.geom_type == "MultiPolygon" and len(geom.geoms) > 1:
                res.attributes["primitive_note"] = f"largest of {len(geom.geoms)} footprint parts"
        except Exception as exc:  # a batch never dies on one building
            if not isinstance(exc, (FitError, InputError)):
                logger.warning("building %s: unexpected %s", fid, type(exc).__name__, exc_info=True)
            res.status = "failed"
            res.reason = str(exc) or type(exc).__name__
            logger.info("building %s failed: %s", fid, res.reason)
        results.append(res)
        if progress is not None:
            progress(1)
    return results


def write_check_images(folder, cloud: PointCloud, results, *, ortho=None, dpi: int = 100) -> list:
    """Write a PNG per modelled building: the wire frame over its points.

    Parameters
    ----------
    folder : str or Path
        Existing output folder; files are ``<id>.png``.
    ortho : lidar2city.io.raster.Raster, optional
        An RGB(A) orthoimage in the cloud's CRS drawn under the plan view.

    Returns
    -------
    list of Path
    """
    from pathlib import Path

    from ..io.figures import write_check_image

    folder = Path(folder)
    pad = 3.0
    index = _XIndex(cloud.xyz)
    written = []
    for res in results:
        if not res.ok or "2.2" not in res.solids:
            continue
        solid = res.solids["2.2"]
        lo, hi = solid.vertices[:, :2].min(0) - pad, solid.vertices[:, :2].max(0) + pad
        pts = cloud.xyz[index.query(lo[0], lo[1], hi[0], hi[1])]
        image = None
        if ortho is not None:
            image = _crop_ortho(ortho, cloud, lo, hi)
        title = f"{res.id}: {res.attributes.get('primitive', '')}"
        rmse = res.attributes.get("primitive_residual_rmse")
        if rmse is not None:
            title += f"  roof RMSE {rmse:.2f} m"
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in res.id)
        path = folder / f"{safe}.png"
        write_check_image(path, pts, solid, footprint=res.footprint, title=title, ortho=image,
                          dpi=dpi)
        written.append(path)
    return written


def _crop_ortho(ortho, cloud, lo, hi):
    """(array (H, W, C), extent in local metres) of the orthoimage around a building."""
    corners = cloud.to_world(np.array([[lo[0], lo[1]], [hi[0], hi[1]]]))
    rc = ortho.world_to_pixel(corners)
    r0, r1 = np.sort(rc[:, 0])
    c0, c1 = np.sort(rc[:, 1])
    h, w = ortho.shape
    r0, c0 = max(int(np.floor(r0)), 0), max(int(np.floor(c0)), 0)
    r1, c1 = min(int(np.ceil(r1)), h), min(int(np.ceil(c1)), w)
    if r1 <= r0 or c1 <= c0:
        return None
    arr = ortho.array if ortho.array.ndim == 3 else ortho.array[None]
    sub = np.moveaxis(arr[:, r0:r1, c0:c1], 0, -1)
    if sub.shape[-1] == 1:
        sub = sub[..., 0]
    tl = ortho.pixel_centers(np.array([r0, r1 - 1]), np.array([c0, c1 - 1]))
    half = ortho.cell_size / 2.0
    a = cloud.to_local(tl)
    extent = (min(a[:, 0]) - half, max(a[:, 0]) + half, min(a[:, 1]) - half, max(a[:, 1]) + half)
    return sub, extent
