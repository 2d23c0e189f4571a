"""``lidar2city ground IN -o OUT``: ground filtering of a LAS/LAZ tile."""

from __future__ import annotations

import click

from ._options import check_not_input, crs_option, engine_options, neighbours_options, run_on_tiles

METHODS = ("pmf", "ptd", "smrf", "smrf_refined", "smrf_segments", "smrf_vote")  # keys of lidar2city.ground.GROUND_METHODS (kept literal for start-up speed)


@click.command("ground")
@click.argument("input", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(),
              help="Output file; an output folder when INPUT is a folder or glob of tiles.")
@click.option("--method", "--ground-method", "method", type=click.Choice(METHODS), default=None,
              show_default="smrf_vote, or ground.method of --config",
              help="Ground filter (also spelt --ground-method, as in classify).")
@click.option("--dtm", "dtm", type=click.Path(), default=None,
              help="Also write a DTM GeoTIFF interpolated from the ground points (holes filled); "
                   "a folder of DTMs (TILE.tif) for a folder of tiles.")
@click.option("--cell", type=float, default=None,
              show_default="1, or ground.dtm_cell of --config",
              help="DTM cell size in metres.")
@crs_option
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Run configuration TOML; its [ground] table sets the filter parameters.")
@neighbours_options
@engine_options
def command(input, output, method, dtm, cell, crs, config, neighbours, buffer, workers, scheduler):
    """Classify ground (ASPRS 2) and the rest (1) in INPUT; write every point to OUTPUT.

    INPUT may be a folder or a quoted glob of tiles ("tiles/*.laz"): OUTPUT is then a folder,
    each tile is filtered with the strips of its neighbours (found from the tiles' bounds),
    one task per tile (--workers, --scheduler).
    """
    from ..tools.ground import ground_file

    check_not_input((output, dtm), input, neighbours)
    if cell is not None and not cell > 0:
        raise click.BadParameter("must be > 0", param_hint="--cell")
    if run_on_tiles(ground_file, input, output, neighbours=neighbours, workers=workers,
                    scheduler=scheduler, buffer=buffer, crs=crs, config=config, method=method,
                    dtm_cell=cell, extra=None if dtm is None else {"dtm_path": (dtm, ".tif")}):
        return
    summary = ground_file(input, output, dtm_path=dtm, config=config, method=method,
                          dtm_cell=cell, crs=crs, neighbours=neighbours, buffer=buffer)
    click.echo(f"{output}: {summary['ground']:,} of {summary['points']:,} points ground "
               f"({100.0 * summary['ground'] / summary['points']:.1f} %, {summary['method']})",
               err=True)
    if dtm:
        h, w = summary["dtm_shape"]
        click.echo(f"{dtm}: DTM {w} x {h} cells of {summary['dtm_cell']:g} m", err=True)
