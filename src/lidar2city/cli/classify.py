"""``lidar2city classify IN -o OUT``."""

from __future__ import annotations

import click

from ._options import check_not_input, crs_option, engine_options, neighbours_options, run_on_tiles
from .ground import METHODS as GROUND_METHODS

NAMES = {1: "other", 2: "ground", 3: "low vegetation", 4: "medium vegetation",
         5: "high vegetation", 6: "building", 7: "noise"}


@click.command("classify")
@click.argument("input", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(),
              help="Output file; an output folder when INPUT is a folder or glob of tiles.")
@crs_option
@click.option("--ground-from-file", is_flag=True,
              help="Reuse the input's class 2 points as ground (when that class is trustworthy) "
                   "instead of running the ground filter.")
@click.option("--ground-method", type=click.Choice(GROUND_METHODS), default="smrf",
              show_default=True,
              help="Ground filter used when the ground is not taken from the file (as ground "
                   "--method).")
@click.option("--config", "config", default=None, type=click.Path(dir_okay=False),
              help="Run configuration (TOML); its [classify] table sets the parameters.")
@neighbours_options
@engine_options
def command(input, output, crs, ground_from_file, ground_method, config, neighbours, buffer,
            workers, scheduler):
    """Classify INPUT into ground (2), building (6), vegetation (3/4/5), noise (7), other (1).

    Every point is written to OUTPUT with all its attributes and its new class. INPUT may be
    a folder or a quoted glob of tiles ("tiles/*.laz"): OUTPUT is then a folder, each tile is
    classified with the strips of its neighbours (found from the tiles' bounds), one task per
    tile (--workers, --scheduler).
    """
    from ..tools.classify import classify_file

    check_not_input(output, input, neighbours)
    if run_on_tiles(classify_file, input, output, neighbours=neighbours, workers=workers,
                    scheduler=scheduler, buffer=buffer, crs=crs,
                    ground_from_file=ground_from_file, ground_method=ground_method,
                    config=config):
        return

    summary = classify_file(input, output, crs=crs, ground_from_file=ground_from_file,
                            ground_method=ground_method, config=config,
                            neighbours=neighbours, buffer=buffer)
    parts = ", ".join(f"{NAMES.get(k, k)} {v:,}" for k, v in summary["classes"].items())
    click.echo(f"{output}: {summary['points']:,} points classified in "
               f"{summary['seconds']:.1f} s ({parts})")
