"""``lidar2city ground IN -o OUT``: ground filtering of a LAS/LAZ tile."""

from __future__ import annotations

import click

from ._options import crs_option, neighbours_options, output_option

METHODS = ("pmf", "smrf", "smrf_refined")  # keys of lidar2city.ground.GROUND_METHODS (kept literal for start-up speed)


@click.command("ground")
@click.argument("input", type=click.Path(dir_okay=False))
@output_option()
@click.option("--method", type=click.Choice(METHODS), default=None,
              help="Ground filter (default smrf_refined, or ground.method of --config).")
@click.option("--dtm", "dtm", type=click.Path(dir_okay=False), default=None,
              help="Also write a DTM GeoTIFF interpolated from the ground points (holes filled).")
@click.option("--cell", type=float, default=None,
              help="DTM cell size in metres (default 1, or ground.dtm_cell of --config).")
@crs_option
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Run configuration TOML; its [ground] table sets the filter parameters.")
@neighbours_options
def command(input, output, method, dtm, cell, crs, config, neighbours, buffer):
    """Classify ground (ASPRS 2) and the rest (1) in INPUT; write every point to OUTPUT."""
    from ..tools.ground import ground_file

    if cell is not None and not cell > 0:
        raise click.BadParameter("must be > 0", param_hint="--cell")
    summary = ground_file(input, output, dtm_path=dtm, config=config, method=method,
                          dtm_cell=cell, crs=crs, neighbours=neighbours, buffer=buffer)
    click.echo(f"{output}: {summary['ground']:,} of {summary['points']:,} points ground "
               f"({100.0 * summary['ground'] / summary['points']:.1f} %, {summary['method']})",
               err=True)
    if dtm:
        h, w = summary["dtm_shape"]
        click.echo(f"{dtm}: DTM {w} x {h} cells of {summary['dtm_cell']:g} m", err=True)
