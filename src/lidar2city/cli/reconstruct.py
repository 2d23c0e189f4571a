"""``lidar2city reconstruct IN... -o OUT``."""

from __future__ import annotations

import click

from ._options import crs_option, output_option, progress


@click.command("reconstruct")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@output_option()
@click.option("--footprints", type=click.Path(dir_okay=False), default=None,
              help="Building footprints (any OGR source: GPKG, SHP, GeoJSON...).")
@click.option("--lod", "lods", multiple=True, type=click.Choice(["1.2", "1.3", "2.2"]),
              help="LoD to build (repeat for both); default from the config, else 1.2.")
@crs_option
@click.option("--config", "config", type=click.Path(dir_okay=False), default=None,
              help="Run configuration (TOML), e.g. [lod1] roof_statistic = 70.")
@click.option("--format", "fmt", type=click.Choice(["cityjson", "cityjsonseq", "obj", "gpkg"]),
              default=None, help="Output format; default from the output name.")
@click.option("--id-field", default=None, help="Footprint field holding the building id.")
@click.option("--layer", default=None, help="Footprint layer (default: the first).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar or summary.")
def command(inputs, output, footprints, lods, crs, config, fmt, id_field, layer, quiet):
    """Build 3D buildings from point cloud tiles INPUTS (read as one area).

    LoD1.2: one prism per footprint (roof at a percentile of the building
    points, ground at a low percentile of the ground points around it);
    LoD1.3: one prism per roof-height part; LoD2.2: roof facets, ridges and
    steps, one closed solid per footprint. Every footprint gets a model or a
    stated reason. Output: .city.json (CityJSON 2.0), .city.jsonl, .obj or .gpkg.
    """
    from ..tools.reconstruct import reconstruct

    bar_state = {"bar": None}

    def on_progress(done, total, result):
        bar = bar_state["bar"]
        if bar is None:
            bar = progress(length=total, label="buildings", quiet=quiet).__enter__()
            bar_state["bar"] = bar
        bar.update(1)

    try:
        summary = reconstruct(list(inputs), output, footprints=footprints, lods=lods or None,
                              crs=crs, config=config, fmt=fmt, id_field=id_field, layer=layer,
                              progress=on_progress)
    finally:
        if bar_state["bar"] is not None:
            bar_state["bar"].__exit__(None, None, None)
    if not quiet:
        for line in summary.lines():
            click.echo(line, err=True)
