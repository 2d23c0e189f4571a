"""``lidar2city rasterize IN... -o OUT.tif --product P``: rasters from LAS/LAZ tiles."""

from __future__ import annotations

import click

from ._options import RASTER_SUFFIXES, check_not_input, check_suffix, crs_option, output_option

PRODUCTS = ("dsm", "dtm", "ndsm", "intensity", "rgb")  # keys of tools.rasterize.PRODUCTS


@click.command("rasterize")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option()
@click.option("--product", type=click.Choice(PRODUCTS), default="dsm", show_default=True,
              help="dsm: highest return per cell; dtm: ground interpolated; ndsm: dsm - dtm; "
                   "intensity: mean intensity; rgb: mean colour (3 bands).")
@click.option("--cell", type=float, default=0.5, show_default=True,
              help="Cell size in metres; the grid's edges are multiples of it.")
@click.option("--ground", type=click.Choice(("auto", "classified", "filter")), default="auto",
              show_default=True,
              help="DTM ground points: class 2 (auto: when the tiles have some) or the ground filter.")
@click.option("--max-gap", type=float, default=None,
              show_default="none: all filled from the nearest",
              help="Empty cells farther than this (m) from a filled one stay nodata.")
@crs_option
@click.option("--no-crs", "allow_no_crs", is_flag=True,
              help="Tiles without a CRS and no --crs: write the raster without one (cells and "
                   "heights taken as metres) instead of stopping.")
def command(inputs, output, product, cell, ground, max_gap, crs, allow_no_crs):
    """Grid the points of INPUTS (tiles of one area) into one GeoTIFF product."""
    from ..tools.rasterize import rasterize_files

    check_not_input(output, inputs)
    check_suffix(output, RASTER_SUFFIXES, "rasters")
    if not cell > 0:
        raise click.BadParameter("must be > 0", param_hint="--cell")
    if max_gap is not None and not max_gap >= 0:
        raise click.BadParameter("must be >= 0", param_hint="--max-gap")
    s = rasterize_files(list(inputs), output, product=product, cell=cell, crs=crs, ground=ground,
                        max_gap=max_gap, allow_no_crs=allow_no_crs)
    h, w = s["shape"]
    extra = f", ground from {s['ground']}" if s["ground"] else ""
    click.echo(f"{output}: {product} {w} x {h} cells of {cell:g} m from {s['points']:,} points{extra}",
               err=True)
