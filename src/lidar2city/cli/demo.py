"""``lidar2city demo``: the whole pipeline on a synthetic town with known truth."""

from __future__ import annotations

import click


@click.command("demo")
@click.option("-o", "--output", "outdir", default="lidar2city-demo", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the outputs.")
@click.option("--seed", default=0, show_default=True, help="Seed of the synthetic town.")
@click.option("--density", default=10.0, show_default=True, help="Points per square metre.")
@click.option("--schemas", default=None, type=click.Path(file_okay=False),
              show_default="the CityJSON 2.0.2 schemas shipped with lidar2city",
              help="Folder of the CityJSON 2.0 schemas for the schema check.")
def command(outdir, seed, density, schemas):
    """Build a synthetic town, reconstruct it end to end and compare with its truth.

    From a raw tile (no classes): ground filter, building / vegetation
    classification, footprints regularised by the 2-D snake, LoD1.2 and LoD2.2
    models in CityJSON, validated; then how close each step is to the truth.
    """
    from ..tools.demo import run_demo

    def step(name):
        click.echo(f"- {name}", err=True)

    report = run_demo(outdir, seed=seed, density=density, schemas=schemas, progress=step)
    for line in report.lines():
        click.echo(line)
