"""``lidar2city reconstruct IN... -o OUT`` and ``lidar2city reconstruct --dsm DSM.tif -o OUT``."""

from __future__ import annotations

import logging

import click

from ._options import (EngineProgress, check_not_input, crs_option, engine_options, output_option,
                       progress, progress_callback)

logger = logging.getLogger(__name__)


@click.command("reconstruct")
@click.argument("inputs", nargs=-1, required=False, type=click.Path())
@output_option()
@click.option("--dsm", type=click.Path(dir_okay=False), default=None,
              help="Build LoD1.2 prisms from this DSM raster instead of point clouds.")
@click.option("--dtm", type=click.Path(dir_okay=False), default=None,
              show_default="built from the DSM",
              help="With --dsm: terrain raster on the DSM's grid.")
@click.option("--ortho", type=click.Path(dir_okay=False), default=None,
              help="With --dsm: RGB orthoimage on the DSM's grid (vegetation by colour).")
@click.option("--footprints", type=click.Path(dir_okay=False), default=None,
              help="Building footprints (any OGR source: GPKG, SHP, GeoJSON...).")
@click.option("--lod", "lods", multiple=True, type=click.Choice(["1.2", "1.3", "2.2"]),
              show_default="1.2, or lod1.lods of --config",
              help="LoD to build (repeat for several).")
@crs_option
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Run configuration (TOML), e.g. [lod1] roof_statistic = 70.")
@click.option("--format", "fmt", type=click.Choice(["cityjson", "cityjsonseq", "obj", "gpkg"]),
              default=None, show_default="from the output name", help="Output format.")
@click.option("--id-field", default=None, help="Footprint field holding the building id.")
@click.option("--layer", default=None, show_default="the first", help="Footprint layer.")
@click.option("--method", type=click.Choice(["roof", "primitives"]), default="roof",
              show_default=True,
              help="LoD2.2 from the roof topology (facets, snake, intersection edges) or from "
                   "floating primitives (box, gable, hip, shed, prism) fitted by least squares.")
@click.option("--primitives", "primitives_file", type=click.Path(dir_okay=False), default=None,
              help="With --method primitives: CSV, TOML or vector file naming a primitive and "
                   "approximate parameters per footprint id (semi-automatic).")
@click.option("--check-images", type=click.Path(file_okay=False), default=None,
              help="With --method primitives: folder for a PNG per building (wire frame over "
                   "its points).")
@click.option("--block-size", type=click.FloatRange(min=50.0), default=None,
              show_default="1000; with footprints on classified points halved while a block "
                           "would read over 2 M points",
              help="Side (m) of the processing blocks (grid on the CRS origin): memory is "
                   "bounded by a few tiles and results do not depend on the tiling.")
@click.option("--edits", type=click.Path(dir_okay=False), default=None,
              help="EDITS.json written by `lidar2city edit` or the viewer: re-apply every edit "
                   "(needs --footprints).")
@engine_options(auto=True)
@click.option("--resume", is_flag=True,
              help="Continue an interrupted run from its journal (OUT.journal): blocks already "
                   "done are kept, the output is the same bytes as an uninterrupted run.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar or summary.")
def command(inputs, output, dsm, dtm, ortho, footprints, lods, crs, config, fmt, id_field, layer,
            method, primitives_file, check_images, block_size, edits, workers, scheduler, resume,
            quiet):
    """Build 3D buildings from point cloud tiles INPUTS (one area, block by block) or from a DSM.

    INPUTS are LAS/LAZ files, folders of tiles or quoted glob patterns ("tiles/*.laz").

    \b
    lidar2city reconstruct TILE.laz [TILE.laz...] [--footprints FP] [--lod ...] -o OUT
    lidar2city reconstruct --dsm DSM.tif [--dtm DTM.tif] [--ortho RGB.tif]
                           [--footprints FP] [--lod 1.2] -o OUT

    LoD1.2: one prism per footprint (roof at a percentile of the building
    points, ground at a low percentile of the ground points around it);
    LoD1.3: one prism per roof-height part; LoD2.2: roof facets, ridges and
    steps, one closed solid per footprint. Every footprint gets a model or a
    stated reason. Output: .city.json (CityJSON 2.0), .city.jsonl, .obj or .gpkg.

    With --dsm (LoD1.2 only): the buildings segmented from the DSM and fitted
    with regular outlines, or the --footprints given, extruded from the median
    DTM inside to the median nDSM (config [dsm_lod1]), in the raster's CRS.
    """
    from ..errors import InputError

    check_not_input(output, inputs, dsm, dtm, ortho, footprints, primitives_file, edits)
    if dsm is None:
        if not inputs:
            raise InputError("give point-cloud INPUTS or --dsm DSM.tif (see lidar2city reconstruct "
                             "--help)")
        for opt, v in (("--dtm", dtm), ("--ortho", ortho)):
            if v is not None:
                raise InputError(f"{opt} needs --dsm (it does not apply to point clouds)")
    else:
        if inputs:
            raise InputError("give either point-cloud INPUTS or --dsm, not both")
        if method != "roof" or primitives_file or check_images or edits:
            raise InputError("--method, --primitives, --check-images and --edits apply to point "
                             "clouds")
        if any(lod != "1.2" for lod in lods):
            raise InputError("--dsm builds LoD1.2 only; drop --lod or use --lod 1.2")
        if workers not in (1, "auto") or scheduler is not None or resume:
            raise InputError("--workers, --scheduler and --resume apply to point clouds")
        if crs is not None:
            raise InputError("--crs does not apply to --dsm (the raster's own CRS is used; "
                             "footprints are reprojected to it)")
        if footprints is None and (id_field is not None or layer is not None):
            raise InputError("--id-field and --layer need --footprints")
        _dsm(dsm, output, dtm=dtm, ortho=ortho, footprints=footprints, config=config, fmt=fmt,
             quiet=quiet, layer=layer, id_field=id_field)
        return

    from .main import _STANDALONE

    if _STANDALONE and (lods or config is None):  # the LoDs, hence the worker's imports, known
        # a command of its own: the server its local cluster's workers are forked from
        # starts now, its imports beside this process's (in a test runner's process the
        # cluster starts it, and ends it with itself)
        from ..tools.engine import start_worker_server, worker_modules

        start_worker_server(workers, scheduler, worker_modules(lods, method))

    from ..tools.reconstruct import reconstruct

    if (workers == "auto" and not _STANDALONE
            and click.get_current_context().get_parameter_source("workers")
            == click.core.ParameterSource.DEFAULT):
        # the command run inside another program (click's CliRunner in a test, a script
        # calling cli() around its own timers): its threads, its outputs and what it
        # measures are its own, so the default runs in its process; an explicit
        # --workers auto there is auto_workers' choice
        logger.info("--workers auto: 1 (the command runs inside another program; give "
                    "--workers to fork)")
        workers = 1
    if workers not in (1, "auto") and scheduler is not None:
        raise InputError("give either --workers (a local cluster) or --scheduler, not both")
    # bars over blocks and buildings on a terminal (buildings without a total when traced)
    with EngineProgress("blocks", "buildings", quiet=quiet) as bar:
        summary = reconstruct(list(inputs), output, footprints=footprints, lods=lods or None,
                              crs=crs, config=config, fmt=fmt, id_field=id_field, layer=layer,
                              progress=lambda done, total, result: bar.items(done, total),
                              block_progress=bar.blocks, method=method,
                              primitives=primitives_file, check_images=check_images,
                              block_size=block_size, workers=workers, scheduler=scheduler,
                              resume=resume, edits=edits)
    if not quiet:
        for line in summary.lines():
            click.echo(line, err=True)


def _dsm(dsm, output, *, dtm, ortho, footprints, config, fmt, quiet, layer, id_field):
    from ..tools.dsm import load_dsm_config, reconstruct_from_dsm

    cfg = load_dsm_config(config)
    with progress(length=1, label="buildings", quiet=quiet) as bar:
        callback = progress_callback(bar)

        summary = reconstruct_from_dsm(dsm, output, dtm=dtm, ortho=ortho, footprints=footprints,
                                       fmt=fmt, config=cfg, progress=callback, layer=layer,
                                       id_field=id_field)
    if not quiet:
        for line in summary.lines():
            click.echo(line, err=True)
