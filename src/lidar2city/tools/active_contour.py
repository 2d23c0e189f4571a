"""File-level jobs of the active-contour method: outlines from a DSM, and weight tuning."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError

logger = logging.getLogger(__name__)

__all__ = ["load_scene_inputs", "reference_mask", "footprints_active_contour", "tune",
           "resolve_weights", "scoring_domain"]


def load_scene_inputs(dsm, *, dtm=None, ortho=None) -> dict:
    """Read a DSM, its DTM (or derive one) and an optional orthoimage on the same grid.

    Returns
    -------
    dict
        ``raster`` (the DSM :class:`~lidar2city.io.raster.Raster`), ``dsm`` and
        ``ndsm`` arrays (m, NaN for nodata), ``ortho`` array or None, ``cell`` (m).

    Raises
    ------
    InputError
        Grids differ, or no DTM is given and none can be derived.
    """
    from ..io.raster import check_same_grid, check_surface, read_raster

    d = read_raster(dsm)
    if d.array.ndim != 2:
        raise InputError(f"{str(dsm)!r}: the DSM must have one band")
    d = check_surface(d, dsm)
    from ..crs import unit_factors

    z_unit = unit_factors(d.crs)[1]
    zs = d.array * z_unit
    cell = d.cell_size
    if dtm is None:
        from ..segment.dsm import dtm_from_dsm

        ground = dtm_from_dsm(zs, cell=cell)
        if isinstance(ground, tuple):  # (dtm, ground mask)
            ground = ground[0]
        logger.info("no DTM given: derived one from the DSM")
    else:
        t = read_raster(dtm)
        check_same_grid(d, t, f"DTM {str(dtm)!r}")
        t = check_surface(t, dtm)
        ground = t.array * z_unit
    ndsm = zs - ground
    o = None
    if ortho is not None:
        orr = read_raster(ortho)
        check_same_grid(d, orr, f"orthoimage {str(ortho)!r}")
        o = np.asarray(orr.array, dtype=np.float64)
    return {"raster": d, "dsm": zs, "ndsm": ndsm, "ortho": o, "cell": cell}


def reference_mask(reference, raster) -> np.ndarray:
    """Rasterise reference footprints (any OGR source) onto a raster's grid (pixel centres)."""
    from ..contour.raster import PixelFrame, rasterize_polygons
    from ..io.vector import read_footprints

    origin = (raster.transform.c, raster.transform.f)
    fp, _ = read_footprints(reference, origin=origin, xy_unit=raster.xy_unit, target_crs=raster.crs)
    frame = PixelFrame(raster.transform, origin=origin, xy_unit=raster.xy_unit)
    mask = rasterize_polygons(fp.geometries, raster.shape, frame)
    if not mask.any():
        raise InputError(f"no reference footprint of {str(reference)!r} covers the DSM")
    return mask


def resolve_weights(weights) -> dict | None:
    """Weights from None (defaults), a mapping, or a TOML file path."""
    if weights is None or isinstance(weights, dict):
        return weights
    from ..io.weights import read_weights

    return read_weights(weights)


def footprints_active_contour(dsm, *, output, dtm=None, ortho=None, weights=None, config=None,
                              callback=None) -> dict:
    """Building outlines by active contours from a DSM, written to a GeoPackage.

    Parameters
    ----------
    dsm, dtm, ortho : path
        Rasters on one grid; without ``dtm`` one is derived from the DSM.
    output : path
        Vector file (GPKG) in the DSM's CRS, one polygon per building with
        ``area_m2``.
    weights : None, dict or path
        The five weights, or a TOML file written by ``lidar2city tune``.
    config : ActiveContourConfig, optional

    Returns
    -------
    dict
        ``buildings`` (count), ``weights`` used, ``output``.
    """
    from ..contour.outlines import WEIGHT_NAMES, ActiveContourConfig, active_contour_outlines
    from ..io.vector import write_polygons

    cfg = config or ActiveContourConfig()
    w = resolve_weights(weights)
    if w is not None:
        cfg = cfg.with_weights(w)
    inp = load_scene_inputs(dsm, dtm=dtm, ortho=ortho)
    r = inp["raster"]
    origin = (r.transform.c, r.transform.f)
    polys = active_contour_outlines(inp["dsm"], inp["ndsm"], ortho=inp["ortho"], cell=inp["cell"],
                                    transform=r.transform, origin=origin, xy_unit=r.xy_unit,
                                    config=cfg, callback=callback)
    if not polys:
        logger.warning("no building found")
    fields = {"id": np.arange(1, len(polys) + 1, dtype=np.int64),
              "area_m2": np.array([round(p.area, 2) for p in polys], dtype=np.float64)}
    write_polygons(output, polys, fields, origin=origin, crs=r.crs, xy_unit=r.xy_unit)
    used = {k: getattr(cfg, k) for k in WEIGHT_NAMES}
    return {"buildings": len(polys), "weights": used, "output": str(output)}


def scoring_domain(reference_mask, objects, kind="reference", *, cell, buffer=10.0,
                   edge_margin=6.0, piece_distance=6.0) -> np.ndarray:
    """The pixels a reference footprint set is scored on.

    ``"reference"`` (:func:`~lidar2city.contour.raster.reference_neighbourhood_domain`):
    ``buffer`` metres around the reference buildings, minus the above-ground
    pieces (cut at necks, centres ``piece_distance`` metres apart) holding no
    reference pixel -- for reference sets that leave out buildings inside
    their extent. ``"bbox"`` (:func:`~lidar2city.contour.raster.evaluation_domain`):
    the reference's bounding box, minus a border margin and the objects cut by
    the raster edge -- for complete reference sets. Lengths are in metres
    (``cell`` is the pixel size), so rasters of any resolution are scored on
    the same ground: on a 2 m raster these are the 5, 3 and 3 pixels of the
    first protocol.
    """
    from ..contour.raster import evaluation_domain, reference_neighbourhood_domain

    if not cell > 0:
        raise InputError(f"cell must be > 0, got {cell!r}")
    if kind == "reference":
        return reference_neighbourhood_domain(
            reference_mask, objects, buffer=buffer / cell,
            edge_margin=int(round(edge_margin / cell)),
            min_distance=max(1, int(round(piece_distance / cell))))
    if kind == "bbox":
        return evaluation_domain(reference_mask, objects)
    raise InputError(f"unknown scoring domain {kind!r}; expected 'reference' or 'bbox'")


def tune(dsm, *, reference, output, dtm=None, ortho=None, seed=0, population=30, generations=15,
         n_jobs=1, objective="cost", config=None, figure=None, callback=None,
         domain="reference", scale="log") -> dict:
    """Learn the five weights on a DSM with reference footprints; write them as TOML.

    The cost is scored on :func:`scoring_domain` ``domain``: by default the
    surroundings of the reference buildings (reference sets seldom hold every
    building of their extent); ``"bbox"`` for a complete reference.

    Returns
    -------
    dict
        ``weights``, ``cost``, ``default_cost`` (the default weights' cost on the
        same pixels), ``history`` (per generation), ``stopped``.
    """
    from ..contour.outlines import WEIGHT_NAMES, ActiveContourConfig, normalize_weights
    from ..io.weights import write_weights
    from ..tune.ga import _init_worker, tune_weights, weights_cost

    cfg = config or ActiveContourConfig()
    if Path(output).suffix.lower() != ".toml":
        raise InputError(f"the weights output must be a .toml file, got {str(output)!r}")
    inp = load_scene_inputs(dsm, dtm=dtm, ortho=ortho)
    ref = reference_mask(reference, inp["raster"])
    objects = np.nan_to_num(inp["ndsm"], nan=0.0) > cfg.min_height
    kind = domain
    domain = scoring_domain(ref, objects, kind, cell=inp["cell"])
    weights, history = tune_weights(inp["dsm"], inp["ndsm"], ref, ortho=inp["ortho"], cell=inp["cell"],
                                    domain=domain, config=cfg, population=population,
                                    generations=generations, seed=seed, n_jobs=n_jobs,
                                    objective=objective, scale=scale, callback=callback)
    cost = history[-1]["best_cost"] if history else float("nan")
    # the defaults' cost on the same pixels: tuning must not be worse
    from ..contour.outlines import prepare_scene
    from ..contour.raster import PixelFrame

    scene = prepare_scene(inp["dsm"], inp["ndsm"], ortho=inp["ortho"], cell=inp["cell"], config=cfg)
    _init_worker(scene, PixelFrame(cell=inp["cell"]), ref, domain, cfg, objective)
    default = normalize_weights({k: getattr(cfg, k) for k in WEIGHT_NAMES})
    default_cost = weights_cost(list(default.values()))
    if default_cost < cost:
        logger.warning("the default weights (cost %.5f) beat the tuned ones (%.5f) on the "
                       "training pixels; keeping the defaults", default_cost, cost)
        weights, cost = default, default_cost
    write_weights(output, weights, metadata={
        "objective": objective, "cost": round(cost, 6), "default_cost": round(default_cost, 6),
        "seed": seed, "domain": kind, "scale": scale,
        "population": population, "generations": len(history) - 1,
        "stopped": "converged" if history and history[-1]["same"] >= 0.95 else "generations",
        "dsm": str(dsm), "reference": str(reference)})
    if figure is not None:
        from ..io.contour_plots import plot_ga_history

        plot_ga_history(figure, history)
    return {"weights": weights, "cost": cost, "default_cost": default_cost, "history": history,
            "output": str(output)}
