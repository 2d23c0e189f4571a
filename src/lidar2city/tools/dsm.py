"""File-level jobs on gridded surface models: footprints and LoD1 buildings from a DSM.

``footprints_from_dsm`` reads a DSM (and optionally a DTM and an orthoimage),
segments the buildings, fits each outline (:mod:`lidar2city.fit.polygon`) and
writes a GeoPackage in the raster's CRS. ``lod1_from_dsm`` extrudes the same
outlines, or given footprints, to LoD1.2 prisms with heights from the nDSM.
``rasters_from_las`` grids a coloured point cloud into a DSM and an
orthoimage for them.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np

from ..config import field
from ..datamodel import BuildingResult
from ..errors import EmptyInputError, FitError, InputError
from ..fit.polygon import (
    PolygonFitConfig,
    fit_building_outline,
    give_overlaps,
    inset_outer_edges,
    outer_edges,
    region_polygon,
    split_overlaps,
)
from ..io.raster import Raster, check_same_grid, check_surface, read_raster, write_raster
from ..lod.prism import lod12_solids
from ..segment.dsm import (
    BuildingMaskConfig,
    DtmConfig,
    RoofRegionsConfig,
    building_mask,
    dtm_from_dsm,
    fill_nodata,
    grid_points,
    label_buildings,
    roof_regions,
    vegetation_from_colour,
)

logger = logging.getLogger(__name__)

__all__ = [
    "Lod1DsmConfig",
    "REGULARIZERS",
    "SEGMENTERS",
    "DSM_STAGES",
    "load_dsm_config",
    "building_height",
    "segment_dsm",
    "outlines_from_labels",
    "footprints_from_dsm",
    "lod1_from_dsm",
    "rasters_from_las",
    "reconstruct_from_dsm",
]


@dataclass(frozen=True)
class Lod1DsmConfig:
    """Options of the LoD1 heights from an nDSM (stage ``dsm_lod1``)."""

    roof_stat: str = field("median", "roof height statistic of the nDSM inside the outline "
                                      "(courtyards excluded): 'mean', 'median' or 'pNN' (percentile)")
    inner_margin: float = field(1.0, "pixels closer than this (m) to the outline are left out "
                                     "of the statistic (mixed wall/ground pixels)")


def _stat(values, how):
    if how == "mean":
        return float(np.mean(values))
    if how == "median":
        return float(np.median(values))
    if isinstance(how, str) and how.startswith("p"):
        try:
            q = float(how[1:])
        except ValueError:
            q = -1.0
        if 0 <= q <= 100:
            return float(np.percentile(values, q))
    raise InputError(f"roof_stat must be 'mean', 'median' or 'pNN' (0-100), got {how!r}")


def _polygon_pixels(polygon, shape, cell, *, margin=0.0):
    """Boolean mask of pixels whose centres are inside ``polygon`` (local metres)."""
    import shapely
    from affine import Affine
    from rasterio import features

    g = polygon.buffer(-margin) if margin > 0 else polygon
    if g.is_empty:
        return np.zeros(shape, dtype=bool)
    pix = shapely.transform(g, lambda c: np.column_stack([c[:, 0] / cell, -c[:, 1] / cell]))
    return features.rasterize([(pix, 1)], out_shape=shape, transform=Affine.identity(),
                              fill=0, dtype="uint8").astype(bool)


def building_height(ndsm, polygon, *, cell, roof_stat="median", inner_margin=1.0):
    """Height (m) of a building from the nDSM pixels inside its outline.

    Courtyards (the polygon's holes) are excluded by construction; pixels
    within ``inner_margin`` of the outline are left out unless that leaves none.

    Parameters
    ----------
    ndsm : ndarray, shape (H, W)
    polygon : shapely Polygon
        Local metres, the raster's top-left corner at (0, 0), y northwards.

    Returns
    -------
    float
        NaN when no valid pixel falls inside.
    """
    pix = _polygon_pixels(polygon, ndsm.shape, cell, margin=inner_margin)
    vals = ndsm[pix & np.isfinite(ndsm)]
    if len(vals) == 0:
        pix = _polygon_pixels(polygon, ndsm.shape, cell)
        vals = ndsm[pix & np.isfinite(ndsm)]
    if len(vals) == 0:
        return float("nan")
    return _stat(vals, roof_stat)


#: output precision (m) of the prism vertices (as the LoD1 writer's default)
PRECISION = 0.001

#: the configuration stages a DSM run reads (sections of a TOML run config)
DSM_STAGES = ("dsm_dtm", "dsm_roofs", "dsm_buildings", "polygon_fit", "dsm_lod1")


def load_dsm_config(path=None, **overrides) -> dict:
    """``{stage: dataclass}`` for :data:`DSM_STAGES` from a TOML run config.

    Other sections of the file are left to their own stages. ``overrides`` are
    ``{"stage.field": value}`` pairs (``None`` = not given), e.g.
    ``load_dsm_config(None, **{"dsm_roofs.min_area": 20.0})``.

    Raises
    ------
    ConfigError, FileFormatError
    """
    from ..config import build_stage, read_config
    from ..errors import ConfigError

    data = read_config(path)
    values = {stage: dict(data.get(stage, {})) for stage in DSM_STAGES}
    for key, v in overrides.items():
        if v is None:
            continue
        stage, _, name = key.partition(".")
        if stage not in values or not name:
            raise ConfigError(f"{key}: not an option of the DSM stages {', '.join(DSM_STAGES)}")
        values[stage][name] = v
    return {stage: build_stage(stage, values[stage]) for stage in DSM_STAGES}


def _configs(config):
    defaults = {"dsm_dtm": DtmConfig(), "dsm_roofs": RoofRegionsConfig(),
                "dsm_buildings": BuildingMaskConfig(),
                "polygon_fit": PolygonFitConfig(), "dsm_lod1": Lod1DsmConfig()}
    if config:
        for k, v in config.items():
            if k in defaults:
                defaults[k] = v
    return defaults


def _segment_config(cfg, method):
    return cfg["dsm_roofs"] if method == "roofs" else cfg["dsm_buildings"]


def _z_unit(raster) -> float:
    """Metres per unit of a DSM's / DTM's values: its CRS's vertical unit (feet for a
    feet CRS, as `rasterize` writes them)."""
    from ..crs import unit_factors

    return unit_factors(raster.crs)[1]


def _read_inputs(dsm, dtm, ortho):
    """The DSM, DTM (heights in metres) and orthoimage rasters, checked."""
    d = check_surface(read_raster(dsm), dsm)
    t = d.transform
    if abs(t.b) > 1e-12 or abs(t.d) > 1e-12 or t.a <= 0 or t.e >= 0:
        raise InputError(f"{dsm}: only north-up rasters are supported (transform {tuple(t)[:6]})")
    if abs(abs(t.a) - abs(t.e)) > 1e-6 * abs(t.a):
        raise InputError(f"{dsm}: pixels must be square, got {t.a} x {-t.e}")
    dt = o = None
    if dtm is not None:
        dt = read_raster(dtm)
        check_same_grid(d, dt, f"the DTM {str(dtm)!r}")
        dt = check_surface(dt, dtm)
    if ortho is not None:
        o = read_raster(ortho)
        arr = np.asarray(o.array)
        if arr.ndim != 3 or arr.shape[0] < 3:
            raise InputError(f"the orthoimage {ortho} needs 3 colour bands, got shape {arr.shape}")
        if arr.shape[1:] != d.shape or not np.allclose(tuple(o.transform)[:6], tuple(t)[:6]):
            raise InputError(f"the orthoimage {ortho} must share the DSM's grid (shape {d.shape})")
    z = _z_unit(d)
    if z != 1.0:  # heights in metres, as every threshold is
        d = dataclasses.replace(d, array=d.array * z)
        dt = None if dt is None else dataclasses.replace(dt, array=dt.array * z)
    return d, dt, o


def _segment_roofs(dsm, ndsm, *, cell, vegetation, config):
    cfg = config if isinstance(config, RoofRegionsConfig) else RoofRegionsConfig()
    return roof_regions(dsm, ndsm, cell=cell, vegetation=vegetation, **dataclasses.asdict(cfg))


def _segment_mask(dsm, ndsm, *, cell, vegetation, config):
    cfg = config if isinstance(config, BuildingMaskConfig) else BuildingMaskConfig()
    mask = building_mask(ndsm, cell=cell, vegetation=vegetation, **dataclasses.asdict(cfg))
    return label_buildings(mask)


#: segmentation name -> function(dsm, ndsm, *, cell, vegetation, config) -> (labels, n)
SEGMENTERS = {"roofs": _segment_roofs, "mask": _segment_mask}


def segment_dsm(dsm, *, cell, dtm=None, rgb=None, method="roofs", dtm_config=None,
                segment_config=None):
    """DTM (given or built), nDSM and building labels from arrays.

    ``method`` picks :data:`SEGMENTERS`: ``"roofs"`` (smooth-surface region
    growing, :func:`roof_regions`) or ``"mask"`` (nDSM threshold minus
    vegetation, morphology, connected components: :func:`building_mask`).

    Returns
    -------
    dict
        ``dtm``, ``ndsm``, ``labels``, ``n`` and ``dtm_built`` (bool).
    """
    if method not in SEGMENTERS:
        raise InputError(f"segmentation method must be one of {', '.join(SEGMENTERS)}, got {method!r}")
    dsm = np.asarray(dsm, dtype=np.float64)
    built = dtm is None
    dcfg = dataclasses.asdict(dtm_config or DtmConfig())
    if built:
        dtm, _ = dtm_from_dsm(dsm, cell=cell, **dcfg)
    else:
        dtm = np.asarray(dtm, dtype=np.float64)
        # DTM gaps (e.g. under large buildings) are interpolated from the terrain around
        gaps = np.isfinite(dsm) & ~np.isfinite(dtm)
        if gaps.any() and np.isfinite(dtm).any():
            dtm = fill_nodata(dtm, np.isfinite(dsm))
    ndsm = dsm - dtm
    veg = None
    if rgb is not None:
        min_h = getattr(segment_config, "min_height", 2.5)
        elevated = np.isfinite(ndsm) & (ndsm > min_h)
        veg = vegetation_from_colour(rgb, elevated)
    labels, n = SEGMENTERS[method](dsm, ndsm, cell=cell, vegetation=veg, config=segment_config)
    return {"dtm": dtm, "ndsm": ndsm, "labels": labels, "n": n, "dtm_built": built}


def _raw_outline(region_mask, *, cell, offset, config=None):
    """The region's pixel polygon as it is (``regularize="none"``)."""
    import shapely
    from shapely.geometry.polygon import orient

    rows, cols = np.nonzero(region_mask)
    r0, c0 = rows.min(), cols.min()
    poly = region_polygon(region_mask[r0:rows.max() + 1, c0:cols.max() + 1])
    if poly.geom_type != "Polygon":
        poly = max(poly.geoms, key=lambda g: g.area)
    x0, y0 = offset
    poly = shapely.transform(poly, lambda c: np.column_stack([x0 + (c[:, 0] + c0) * cell,
                                                              y0 - (c[:, 1] + r0) * cell]))
    return orient(poly, 1.0), "pixels", {"cost": float("nan"), "error": 0.0,
                                         "complexity": len(poly.exterior.coords) - 1}


#: outline method name -> function(region_mask, *, cell, offset, config) -> (polygon, type, info)
REGULARIZERS = {
    "fit": lambda m, *, cell, offset, config=None: fit_building_outline(
        m, cell=cell, offset=offset, config=config),
    "none": _raw_outline,
}


def outlines_from_labels(labels, ndsm, *, cell, regularize="fit", fit_config=None,
                         lod1_config=None, progress=None):
    """Fit an outline and a height to every labelled region (local metres, y north).

    A region that fails gets ``status="failed"`` and the reason; the batch
    continues. With ``regularize="fit"`` a region touching other regions is
    fitted together with their pixels within ``fit_config.shared_margin``
    (rounded to the nearest whole number of cells): the shared wall of two row houses split at a
    height step is placed by both fits, without a gap between the outlines;
    where two such outlines share their main axis (within 3 degrees) their
    overlap is then split along it (:func:`~lidar2city.fit.polygon.split_overlaps`),
    and other overlaps go to the region owning their pixels while the other
    outline stays on its axes (``fit_config.overlap_aligned``) or gains at most
    a small notch off them (``fit_config.overlap_notch``,
    :func:`~lidar2city.fit.polygon.give_overlaps`). Each fitted outline's edges
    facing the background move in by ``fit_config.outline_inset``
    (:func:`~lidar2city.fit.polygon.inset_outer_edges`).

    Returns
    -------
    list of BuildingResult
        ``footprint`` (shapely Polygon, local metres, the raster's top-left
        corner at (0, 0)), ``attributes`` with ``shape_type``, ``area``,
        ``height``, ``cost``, ``fit_error``, ``n_vertices``, ``pixels``.
    """
    from scipy import ndimage
    from shapely.geometry.polygon import orient

    if regularize not in REGULARIZERS:
        raise InputError(f"regularize must be one of {', '.join(REGULARIZERS)}, got {regularize!r}")
    fn = REGULARIZERS[regularize]
    lc = lod1_config or Lod1DsmConfig()
    # touching regions share their wall: each fit sees its neighbours' pixels within
    # shared_margin (rounded to whole cells: none on 2 m rasters) as its own, so no gap
    # opens between the two outlines
    margin = (fit_config or PolygonFitConfig()).shared_margin if regularize == "fit" else 0.0
    grow = int(np.floor(float(margin) / float(cell) + 0.5)) if margin > 0 else 0
    inset = float((fit_config or PolygonFitConfig()).outline_inset) if regularize == "fit" else 0.0
    if not inset >= 0:
        raise InputError(f"polygon_fit.outline_inset must be >= 0 m, got {inset}")
    objects = ndimage.find_objects(labels)
    total = len(objects)
    out, region_ids = [], []
    for i, sl in enumerate(objects, start=1):
        if sl is None:
            continue
        rid = f"b{i}"
        # a margin of one pixel (plus the shared-wall growth) around the region keeps its
        # bbox local
        pad = 1 + grow
        r0, r1 = max(sl[0].start - pad, 0), min(sl[0].stop + pad, labels.shape[0])
        c0, c1 = max(sl[1].start - pad, 0), min(sl[1].stop + pad, labels.shape[1])
        win = labels[r0:r1, c0:c1]
        sub = win == i
        n_own = int(sub.sum())
        if grow:
            sub = sub | (ndimage.binary_dilation(sub, iterations=grow) & (win > 0) & (win != i))
        res = BuildingResult(rid)
        try:
            poly, kind, info = fn(sub, cell=cell, offset=(c0 * cell, -r0 * cell), config=fit_config)
            if poly.is_empty or not poly.is_valid:
                raise FitError("the fitted outline is empty or invalid")
            if inset > 0:
                poly = orient(inset_outer_edges(poly, outer_edges(poly, labels, i, cell=cell),
                                                inset), 1.0)
            h = building_height(ndsm, poly, cell=cell, roof_stat=lc.roof_stat,
                                inner_margin=lc.inner_margin)
            res.footprint = poly
            res.attributes = {
                "shape_type": kind, "area": float(poly.area), "height": h,
                "cost": float(info.get("cost", np.nan)), "fit_error": float(info.get("error", np.nan)),
                "n_vertices": int(len(poly.exterior.coords) - 1), "pixels": n_own,
            }
        except (FitError, EmptyInputError) as exc:
            res.status, res.reason = "failed", str(exc)
            logger.info("building %s: %s", rid, exc)
        except Exception as exc:  # a batch never dies on one building
            res.status, res.reason = "failed", f"{type(exc).__name__}: {exc}"
            logger.warning("building %s failed unexpectedly", rid, exc_info=True)
        out.append(res)
        region_ids.append(i)
        if progress is not None:
            progress(i, total)
    if grow:
        _split_shared_walls(out, region_ids, labels, ndsm, cell=cell, lod1_config=lc,
                            min_aligned=(fit_config or PolygonFitConfig()).overlap_aligned,
                            max_notch=(fit_config or PolygonFitConfig()).overlap_notch)
    return out


def _split_shared_walls(results, region_ids, labels, ndsm, *, cell, lod1_config,
                        min_aligned=0.9, max_notch=0.0):
    """Split the overlaps the shared-wall margin leaves between outlines: along the common
    axis of outlines on one axis, to the region owning the pixels for the others."""
    from shapely.geometry.polygon import orient

    ok = [r for r in results if r.ok]
    ids = [i for r, i in zip(results, region_ids, strict=True) if r.ok]
    polys = split_overlaps([r.footprint for r in ok])
    if min_aligned <= 1.0:
        polys = give_overlaps(polys, labels, ids, cell=cell,
                              min_aligned=min_aligned, max_notch=max_notch)
    for r, poly in zip(ok, polys, strict=True):
        if poly is r.footprint:
            continue
        poly = orient(poly, 1.0)
        r.footprint = poly
        r.attributes.update(
            area=float(poly.area), n_vertices=int(len(poly.exterior.coords) - 1),
            height=building_height(ndsm, poly, cell=cell, roof_stat=lod1_config.roof_stat,
                                   inner_margin=lod1_config.inner_margin))


def _world_geoms(results, origin, xy_unit):
    from ..io.vector import to_world

    return [to_world(r.footprint, origin, xy_unit) if r.footprint is not None else None
            for r in results]


def footprints_from_dsm(dsm, *, dtm=None, ortho=None, output, regularize="fit", dtm_out=None,
                        config=None, figure=None, progress=None, segmentation="roofs") -> dict:
    """Building footprints from a DSM (and optionally a DTM and an orthoimage) to a GPKG.

    Parameters
    ----------
    dsm, dtm, ortho : str or Path
        Rasters GDAL reads, on one grid; the orthoimage needs 3 colour bands.
        Without a DTM one is built from the DSM (:func:`dtm_from_dsm`).
    output : str or Path
        GeoPackage (layer ``footprints``) in the DSM's CRS with ``id``,
        ``shape_type``, ``area`` (m2), ``height`` (m), ``cost``, ``fit_error``,
        ``n_vertices``, ``status``, ``reason``.
    regularize : {"fit", "none"}
        Outline method (:data:`REGULARIZERS`).
    dtm_out : str or Path, optional
        Write the DTM used (given or built) as a GeoTIFF.
    config : dict, optional
        ``{stage: dataclass}`` for the stages ``dsm_dtm``, ``dsm_roofs``,
        ``dsm_buildings``, ``polygon_fit``, ``dsm_lod1`` (others ignored).
    figure : str or Path, optional
        PNG of the outlines over the nDSM coloured by shape type.
    progress : callable(done, total), optional
        Called after each building.
    segmentation : {"roofs", "mask"}
        Building segmentation (:data:`SEGMENTERS`).

    Returns
    -------
    dict
        Counts, shape types, timings and the output paths.
    """
    t0 = time.perf_counter()
    cfg = _configs(config)
    d, dt, o = _read_inputs(dsm, dtm, ortho)
    cell = d.cell_size
    rgb = None if o is None else np.asarray(o.array)[:3].astype(np.float64)
    seg = segment_dsm(d.array, cell=cell, dtm=None if dt is None else dt.array, rgb=rgb,
                      method=segmentation, dtm_config=cfg["dsm_dtm"],
                      segment_config=_segment_config(cfg, segmentation))
    if dtm_out is not None:
        write_raster(dtm_out, Raster(seg["dtm"] / _z_unit(d), d.transform, d.crs,
                                     np.isfinite(seg["dtm"])))
    results = outlines_from_labels(seg["labels"], seg["ndsm"], cell=cell, regularize=regularize,
                                   fit_config=cfg["polygon_fit"], lod1_config=cfg["dsm_lod1"],
                                   progress=progress)
    origin = np.array([d.transform.c, d.transform.f])
    _write_footprints(output, results, origin, d.crs, d.xy_unit)
    if figure is not None:
        _figure(figure, d, seg["ndsm"], results, origin)
    kinds: dict[str, int] = {}
    for r in results:
        if r.ok:
            kinds[r.attributes["shape_type"]] = kinds.get(r.attributes["shape_type"], 0) + 1
    return {
        "buildings": sum(r.ok for r in results), "failed": sum(not r.ok for r in results),
        "shape_types": kinds, "dtm": "built from the DSM" if seg["dtm_built"] else str(dtm),
        "cell_m": cell, "crs": d.crs.to_string() if d.crs is not None else None,
        "output": str(output), "dtm_out": None if dtm_out is None else str(dtm_out),
        "figure": None if figure is None else str(figure),
        "seconds": round(time.perf_counter() - t0, 2),
    }


def _write_footprints(output, results, origin, crs, xy_unit):
    from ..io.vector import write_polygons

    keys = ["shape_type", "area", "height", "cost", "fit_error", "n_vertices"]
    fields = {"id": [r.id for r in results]}
    for k in keys:
        vals = [r.attributes.get(k) for r in results]
        if k in ("area", "height", "cost", "fit_error"):
            vals = np.array([np.nan if v is None else float(v) for v in vals])
        elif k == "n_vertices":
            vals = np.array([-1 if v is None else int(v) for v in vals])
        else:
            vals = ["" if v is None else str(v) for v in vals]
        fields[k] = vals
    fields["status"] = [r.status for r in results]
    fields["reason"] = [r.reason for r in results]
    write_polygons(output, [r.footprint for r in results], fields, origin=origin, crs=crs,
                   xy_unit=xy_unit)


def _figure(path, raster, ndsm, results, origin):
    from ..io.plots import plot_outlines

    t = raster.transform
    h, w = raster.shape
    extent = (t.c, t.c + w * t.a, t.f + h * t.e, t.f)
    ok = [r for r in results if r.ok]
    geoms = _world_geoms(ok, origin, raster.xy_unit)
    plot_outlines(path, ndsm, extent, geoms, [r.attributes["shape_type"] for r in ok],
                  title=f"{len(ok)} buildings")


def lod1_from_dsm(dsm, *, dtm=None, ortho=None, footprints=None, regularize="fit", config=None,
                  progress=None, segmentation="roofs", layer=None, id_field=None) -> dict:
    """LoD1.2 buildings from a DSM: fitted outlines (or given footprints) extruded.

    The ground height is the median DTM inside the outline, the roof the ground
    plus the nDSM statistic ``dsm_lod1.roof_stat`` (courtyards excluded).

    Parameters
    ----------
    footprints : str or Path, optional
        Vector footprints (any OGR source, any CRS: reprojected to the DSM's);
        default: outlines fitted to the segmented DSM.
    layer, id_field : optional
        Layer and id field of ``footprints`` (see :func:`lidar2city.io.vector.read_footprints`).

    Returns
    -------
    dict
        ``buildings`` (list of :class:`BuildingResult` with ``solids["1.2"]``,
        local metres), ``origin`` (world, CRS units, z 0), ``crs``, ``xy_unit``,
        ``z_unit`` (metres per unit of the raster values: the CRS's vertical unit) and counts.
    """
    t0 = time.perf_counter()
    cfg = _configs(config)
    d, dt, o = _read_inputs(dsm, dtm, ortho)
    cell = d.cell_size
    origin = np.array([d.transform.c, d.transform.f])
    lc = cfg["dsm_lod1"]
    if footprints is None:
        rgb = None if o is None else np.asarray(o.array)[:3].astype(np.float64)
        seg = segment_dsm(d.array, cell=cell, dtm=None if dt is None else dt.array, rgb=rgb,
                          method=segmentation, dtm_config=cfg["dsm_dtm"],
                          segment_config=_segment_config(cfg, segmentation))
        results = outlines_from_labels(seg["labels"], seg["ndsm"], cell=cell,
                                       regularize=regularize, fit_config=cfg["polygon_fit"],
                                       lod1_config=lc, progress=progress)
        dtm_arr, ndsm = seg["dtm"], seg["ndsm"]
    else:
        from ..io.vector import read_footprints

        fp, _ = read_footprints(footprints, origin=origin, xy_unit=d.xy_unit, target_crs=d.crs,
                                layer=layer, id_field=id_field)
        if dt is None:
            dtm_arr, _ = dtm_from_dsm(d.array, cell=cell, **dataclasses.asdict(cfg["dsm_dtm"]))
        else:
            dtm_arr = dt.array
        ndsm = d.array - dtm_arr
        results = []
        for i, (g, fid) in enumerate(zip(fp.geometries, fp.ids, strict=True), start=1):
            r = BuildingResult(str(fid), footprint=g)
            if g is None:
                r.status, r.reason = "failed", fp.attributes["_note"][i - 1] or "no geometry"
            else:
                poly = g if g.geom_type == "Polygon" else max(g.geoms, key=lambda p: p.area)
                r.footprint = poly
                r.attributes = {"height": building_height(ndsm, poly, cell=cell,
                                                          roof_stat=lc.roof_stat,
                                                          inner_margin=lc.inner_margin),
                                "area": float(poly.area)}
            results.append(r)
            if progress is not None:
                progress(i, len(fp))
        if not any(r.ok and _polygon_pixels(r.footprint, d.shape, cell).any() for r in results) \
                and any(g is not None for g in fp.geometries):
            raise EmptyInputError(f"none of the {len(fp)} footprints of {str(footprints)!r} meets "
                                  "the DSM's extent (check both CRSs)")
    for r in results:
        if not r.ok:
            continue
        h = r.attributes.get("height", float("nan"))
        pix = _polygon_pixels(r.footprint, d.shape, cell) & np.isfinite(dtm_arr)
        if not np.isfinite(h) or not pix.any():
            r.status, r.reason = "failed", "no valid DSM/DTM pixel inside the outline"
            continue
        if h <= 0:
            r.status, r.reason = "failed", f"height {h:.2f} m is not above the terrain"
            continue
        ground = float(np.median(dtm_arr[pix]))
        try:
            solids = lod12_solids(r.footprint, ground, ground + h, grid=PRECISION)
        except InputError as exc:
            r.status, r.reason = "failed", str(exc)
            continue
        r.solids["1.2"] = solids[0] if len(solids) == 1 else solids
        r.attributes.update({"ground_z": ground, "roof_z": ground + h})
    return {
        "buildings": results, "origin": np.array([origin[0], origin[1], 0.0]), "crs": d.crs,
        "xy_unit": d.xy_unit, "z_unit": _z_unit(d),
        "ok": sum(r.ok for r in results), "failed": sum(not r.ok for r in results),
        "seconds": round(time.perf_counter() - t0, 2),
    }


def rasters_from_las(paths, *, cell, dsm_out, ortho_out=None, crs=None) -> dict:
    """Grid a point cloud into a DSM GeoTIFF and, with RGB, an orthoimage GeoTIFF.

    The DSM holds the highest point per cell (heights in the CRS's vertical units,
    as `rasterize` writes them and the DSM methods read them); the orthoimage the
    colour of that point (3 bands, uint16 as stored in LAS). Both are in the
    cloud's CRS with ``cell`` metres pixels.
    """
    from affine import Affine

    from ..io.las import read_points

    cloud = read_points(paths, crs=crs)
    cloud.require_points()
    rgb = None
    if all(k in cloud.attributes for k in ("red", "green", "blue")):
        rgb = np.column_stack([cloud.attributes[k] for k in ("red", "green", "blue")])
    elif ortho_out is not None:
        raise InputError("the point cloud has no red/green/blue attributes for an orthoimage")
    g = grid_points(cloud.xyz, rgb, cell=cell)
    u = cloud.xy_unit
    x0w = cloud.origin[0] + g["x0"] / u
    y0w = cloud.origin[1] + g["y0"] / u
    transform = Affine(cell / u, 0.0, x0w, 0.0, -cell / u, y0w)
    dsm = g["dsm"] / cloud.z_unit + cloud.origin[2]
    write_raster(dsm_out, Raster(dsm, transform, cloud.crs, np.isfinite(dsm)))
    if ortho_out is not None and g["values"] is not None:
        vals = np.nan_to_num(g["values"], nan=0.0)
        write_raster(ortho_out, Raster(vals, transform, cloud.crs, np.isfinite(g["values"]).all(axis=0)),
                     dtype="uint16", nodata=0)
    return {"points": len(cloud), "shape": g["dsm"].shape, "cell_m": cell,
            "dsm": str(dsm_out), "ortho": None if ortho_out is None else str(ortho_out)}


def reconstruct_from_dsm(dsm, output, *, dtm=None, ortho=None, footprints=None, fmt=None,
                         config=None, regularize="fit", progress=None, segmentation="roofs",
                         layer=None, id_field=None):
    """LoD1.2 buildings from a DSM written as CityJSON / CityJSONSeq / OBJ / GPKG.

    :func:`lod1_from_dsm` (fitted outlines, or ``footprints`` extruded) written
    through :func:`lidar2city.tools.reconstruct.write_buildings` in the DSM's
    CRS, the format from ``fmt`` or the output name. The resolved DSM stages
    go into the output's metadata.

    Returns
    -------
    ReconstructSummary
    """
    from types import SimpleNamespace

    from ..config import resolved_dict
    from .reconstruct import ReconstructSummary, format_from_name, write_buildings

    t0 = time.perf_counter()
    fmt = format_from_name(output, fmt)  # fail on an unknown format before any work
    cfg = _configs(config)
    res = lod1_from_dsm(dsm, dtm=dtm, ortho=ortho, footprints=footprints, regularize=regularize,
                        config=cfg, progress=progress, segmentation=segmentation, layer=layer,
                        id_field=id_field)
    frame = SimpleNamespace(origin=res["origin"], crs=res["crs"], xy_unit=res["xy_unit"],
                            z_unit=res["z_unit"])
    results = res["buildings"]
    write_buildings(output, results, frame, fmt=fmt, configuration=resolved_dict(cfg),
                    lods=("1.2",))
    summary = ReconstructSummary(str(output), total=len(results), lods=("1.2",), format=fmt)
    for r in results:
        if r.ok:
            summary.done += 1
        else:
            summary.failed += 1
            summary.reasons[r.reason] += 1
    summary.seconds = time.perf_counter() - t0
    return summary
