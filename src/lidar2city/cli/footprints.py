"""``lidar2city footprints IN... -o OUT.gpkg``."""

from __future__ import annotations

import click

from ._options import crs_option, output_option

REGULARIZER_NAMES = ("none", "snake")


@click.command("footprints")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option()
@click.option("--regularize", type=click.Choice(REGULARIZER_NAMES), default=None,
              help="Outline regulariser (default: none, or the config's).")
@crs_option
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="Run config (TOML); its [footprints] section sets the options.")
@click.option("--cell", type=float, default=None, help="Grid cell (m); default from the spacing.")
@click.option("--min-area", type=float, default=None, help="Smallest building (m2).")
@click.option("--edge-offset", type=float, default=None,
              help="Outline offset (m); negative shrinks (roof overhang).")
def command(inputs, output, regularize, crs, config_path, cell, min_area, edge_offset):
    """Building footprints from classified LAS/LAZ tiles INPUTS into a GeoPackage.

    One polygon per building block (holes for courtyards), in the input CRS,
    with area (m2), dominant direction (deg), vertex count, mean deviation (m),
    point count and the snake's reduction counts (type_i .. type_iv).
    """
    from ..tools.footprints import footprints_job, load_footprints_config
    from ._options import progress

    cfg = load_footprints_config(config_path, regularize=regularize, cell=cell,
                                 min_area=min_area, edge_offset=edge_offset)
    with progress(length=1, label="footprints") as bar:
        state = {"done": 0}

        def callback(done, total):
            bar.length = total
            bar.update(done - state["done"])
            state["done"] = done

        summary = footprints_job(list(inputs), output, crs=crs, config=cfg, callback=callback)
    click.echo(f"{summary['buildings']} footprints, {summary['area']:.0f} m2 "
               f"-> {summary['output']}"
               + (f" ({summary['unregularised']} unregularised)" if summary["unregularised"] else ""))
