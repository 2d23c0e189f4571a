"""``lidar2city footprints IN... -o OUT.gpkg`` and ``lidar2city footprints --dsm DSM.tif -o OUT.gpkg``."""

from __future__ import annotations

import click

from ._options import (RASTER_SUFFIXES, VECTOR_SUFFIXES, check_not_input, check_output, check_suffix,
                       crs_option, engine_options, output_option)

#: outline regularisers of point-cloud footprints (``lidar2city.footprints.REGULARIZERS``)
REGULARIZER_NAMES = ("none", "snake", "fit")
#: outline methods of DSM footprints (``lidar2city.tools.dsm.REGULARIZERS``, and the
#: active contours of ``lidar2city.tools.active_contour``)
DSM_REGULARIZER_NAMES = ("fit", "none", "active-contour")
_CHOICES = tuple(dict.fromkeys(REGULARIZER_NAMES + DSM_REGULARIZER_NAMES))

#: options that only make sense for one kind of input (option name -> parameter)
_POINT_ONLY = {"--cell": "cell", "--edge-offset": "edge_offset", "--crs": "crs",
               "--block-size": "block_size"}
_DSM_ONLY = {"--dtm": "dtm", "--ortho": "ortho", "--dtm-out": "dtm_out", "--figure": "figure",
             "--weights": "weights"}


@click.command("footprints")
@click.argument("inputs", nargs=-1, required=False, type=click.Path())
@output_option()
@click.option("--dsm", type=click.Path(dir_okay=False), default=None,
              help="Segment the buildings from this DSM raster instead of point clouds.")
@click.option("--dtm", type=click.Path(dir_okay=False), default=None,
              show_default="built from the DSM",
              help="With --dsm: terrain raster on the DSM's grid.")
@click.option("--ortho", type=click.Path(dir_okay=False), default=None,
              help="With --dsm: RGB orthoimage on the DSM's grid (vegetation by colour).")
@click.option("--dtm-out", type=click.Path(dir_okay=False), default=None, callback=check_output,
              help="With --dsm: write the DTM used (given or built) as a GeoTIFF.")
@click.option("--figure", type=click.Path(dir_okay=False), default=None, callback=check_output,
              help="With --dsm: PNG of the outlines over the nDSM coloured by shape type.")
@click.option("--regularize", type=click.Choice(_CHOICES), default=None,
              show_default="none for point clouds (or footprints.regularize of --config), "
                           "fit with --dsm",
              help="Outline method. Point clouds: none, snake or fit; --dsm: fit, none or "
                   "active-contour.")
@click.option("--weights", type=click.Path(dir_okay=False), default=None,
              show_default="the shipped tuned weights",
              help="With --dsm --regularize active-contour: the five weights (TOML written by "
                   "lidar2city tune).")
@crs_option
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Run config (TOML): [footprints] for point clouds; [dsm_dtm], [dsm_roofs], "
                   "[polygon_fit], [dsm_lod1] with --dsm.")
@click.option("--cell", type=float, default=None, show_default="1.5 x the building point spacing",
              help="Grid cell (m).")
@click.option("--min-area", type=float, default=None,
              show_default="4 for point clouds, 30 with --dsm, or the --config value",
              help="Smallest building (m2).")
@click.option("--edge-offset", type=float, default=None,
              show_default="0, or footprints.edge_offset of --config",
              help="Outline offset (m); negative shrinks (roof overhang).")
@click.option("--block-size", type=click.FloatRange(min=50.0), default=None,
              show_default="1000",
              help="With a folder or glob of tiles: side (m) of the blocks traced one by one.")
@engine_options
def command(inputs, output, dsm, dtm, ortho, dtm_out, figure, regularize, weights, crs,
            config_path, cell, min_area, edge_offset, block_size, workers, scheduler):
    """Building footprints into a GeoPackage, from classified LAS/LAZ tiles INPUTS or a DSM.

    \b
    lidar2city footprints TILE.laz [TILE.laz...] -o OUT.gpkg [--regularize none|snake|fit]
    lidar2city footprints TILES/ -o OUT.gpkg [--workers N | --scheduler ADDRESS]
    lidar2city footprints --dsm DSM.tif [--dtm DTM.tif] [--ortho RGB.tif] -o OUT.gpkg
                          [--regularize fit|none] [--dtm-out DTM.tif] [--figure PNG]

    Point clouds: one polygon per building block (holes for courtyards), in the
    input CRS, with area (m2), dominant direction (deg), vertex count, mean
    deviation (m), point count and the snake's reduction counts. A folder or
    quoted glob of tiles is traced block by block (--block-size), on N local
    processes (--workers) or a Dask cluster (--scheduler), with the same bytes.

    DSM: buildings segmented from the DSM (nDSM above the DTM, vegetation by
    colour with --ortho), each outline the simplest regular polygon that fits
    (rectangle, trapezoids, union of rectangles or polygon), in the raster's
    CRS, with shape_type, area, height (m above the DTM), fit cost and error.
    """
    from ..errors import InputError

    check_not_input((output, dtm_out, figure), inputs, dsm, dtm, ortho, weights)
    check_suffix(output, VECTOR_SUFFIXES, "footprints")
    check_suffix(dtm_out, RASTER_SUFFIXES, "rasters")
    check_suffix(figure, (".png",), "figures")
    values = {"cell": cell, "edge_offset": edge_offset, "crs": crs, "dtm": dtm, "ortho": ortho,
              "dtm_out": dtm_out, "figure": figure, "weights": weights, "block_size": block_size}
    if dsm is None:
        if not inputs:
            raise InputError("give point-cloud INPUTS or --dsm DSM.tif (see lidar2city footprints "
                             "--help)")
        given = [o for o, k in _DSM_ONLY.items() if values[k] is not None]
        if given:
            raise InputError(f"{given[0]} needs --dsm (it does not apply to point clouds)")
        _points(inputs, output, regularize, crs, config_path, cell, min_area, edge_offset,
                block_size=block_size, workers=workers, scheduler=scheduler)
        return
    if workers != 1 or scheduler is not None:
        raise InputError("--workers and --scheduler apply to a folder or glob of tiles")
    if inputs:
        raise InputError("give either point-cloud INPUTS or --dsm, not both")
    given = [o for o, k in _POINT_ONLY.items() if values[k] is not None]
    if given:
        raise InputError(f"{given[0]} applies to point clouds, not to --dsm")
    regularize = regularize or "fit"
    if regularize not in DSM_REGULARIZER_NAMES:
        raise InputError(f"--regularize {regularize} works on point clouds; with --dsm use "
                         f"{' or '.join(DSM_REGULARIZER_NAMES)}")
    if regularize == "active-contour":
        for opt, v in (("--dtm-out", dtm_out), ("--figure", figure), ("--min-area", min_area)):
            if v is not None:
                raise InputError(f"{opt} goes with --regularize fit or none")
        _active_contour(dsm, output, dtm=dtm, ortho=ortho, weights=weights,
                        config_path=config_path)
        return
    if weights is not None:
        raise InputError("--weights goes with --regularize active-contour")
    _dsm(dsm, output, dtm=dtm, ortho=ortho, dtm_out=dtm_out, figure=figure,
         regularize=regularize, config_path=config_path, min_area=min_area)


def _points(inputs, output, regularize, crs, config_path, cell, min_area, edge_offset, *,
            block_size, workers, scheduler):
    from ..errors import InputError
    from ..io.tiles import is_tile_set
    from ..tools.footprints import footprints_job, footprints_on_tiles, load_footprints_config
    from ._options import EngineProgress, progress, progress_callback

    cfg = load_footprints_config(config_path, regularize=regularize, cell=cell,
                                 min_area=min_area, edge_offset=edge_offset)
    if any(is_tile_set(p) for p in inputs):  # block by block, on the engine
        if workers != 1 and scheduler is not None:
            raise InputError("give either --workers (a local cluster) or --scheduler, not both")
        with EngineProgress("blocks", "footprints") as bar:
            def on_block(done, total, found):
                bar.blocks(done, total)
                bar.items(found, None)

            summary = footprints_on_tiles(list(inputs), output, crs=crs, config=cfg,
                                          block_size=block_size or 1000.0, workers=workers,
                                          scheduler=scheduler, progress=on_block)
    else:
        for opt, v in (("--workers", workers != 1), ("--scheduler", scheduler),
                       ("--block-size", block_size)):
            if v:
                raise InputError(f"{opt} applies to a folder or glob of tiles")
        with progress(length=1, label="footprints") as bar:
            callback = progress_callback(bar)

            summary = footprints_job(list(inputs), output, crs=crs, config=cfg,
                                     callback=callback)
    click.echo(f"{summary['buildings']} footprints, {summary['area']:.0f} m2 "
               f"-> {summary['output']}"
               + (f" ({summary['unregularised']} unregularised)" if summary["unregularised"] else ""))
    failed = summary.get("failed_blocks")
    if failed:
        click.echo(f"  {len(failed)} block(s) failed twice, no footprint traced there: "
                   + ", ".join(f"cell {c}" for c in failed), err=True)
        raise click.exceptions.Exit(1)


def _dsm(dsm, output, *, dtm, ortho, dtm_out, figure, regularize, config_path, min_area):
    from ..tools.dsm import footprints_from_dsm, load_dsm_config
    from ._options import progress, progress_callback

    cfg = load_dsm_config(config_path, **{"dsm_roofs.min_area": min_area})
    with progress(length=1, label="outlines") as bar:
        callback = progress_callback(bar)

        s = footprints_from_dsm(dsm, dtm=dtm, ortho=ortho, output=output, regularize=regularize,
                                dtm_out=dtm_out, config=cfg, figure=figure, progress=callback)
    kinds = ", ".join(f"{n} {k}" for k, n in sorted(s["shape_types"].items()))
    click.echo(f"{s['buildings']} footprints ({kinds or 'none'}), {s['failed']} failed, "
               f"DTM {s['dtm']} -> {s['output']}")
    for extra in ("dtm_out", "figure"):
        if s[extra]:
            click.echo(f"  {extra.replace('_', ' ')}: {s[extra]}")


def _active_contour(dsm, output, *, dtm, ortho, weights, config_path):
    from ..config import stage_config
    from ..tools.active_contour import footprints_active_contour

    cfg = stage_config("active_contour", config_path)
    s = footprints_active_contour(dsm, output=output, dtm=dtm, ortho=ortho, weights=weights,
                                  config=cfg)
    click.echo(f"{s['buildings']} footprints (active contours) -> {s['output']}")
