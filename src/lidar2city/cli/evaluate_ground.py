"""``lidar2city evaluate ground PRED --reference REF``: ISPRS ground-filter errors."""

from __future__ import annotations

import json

import click


@click.command("ground")
@click.argument("pred", type=click.Path(dir_okay=False))
@click.option("--reference", "-r", required=True, type=click.Path(dir_okay=False),
              help="Reference LAS/LAZ with the same points, ground as class 2.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def command(pred, reference, as_json):
    """Type I, type II, total error and kappa of PRED's ground (class 2) against REFERENCE.

    Sithole & Vosselman (2004): type I = ground called object / all ground,
    type II = object called ground / all object.
    """
    from ..tools.ground import evaluate_ground_files

    e = evaluate_ground_files(pred, reference)
    if as_json:
        clean = {k: (None if isinstance(v, float) and v != v else v) for k, v in e.items()}
        click.echo(json.dumps(clean, indent=2))
        return
    ref_ground = e["ground_ground"] + e["ground_object"]
    ref_object = e["object_ground"] + e["object_object"]

    def pct(v):
        return "n/a" if v != v else f"{100.0 * v:6.2f} %"

    click.echo(f"points    {e['points']:,} (reference: {ref_ground:,} ground, {ref_object:,} object)")
    click.echo(f"type I    {pct(e['type_i'])}  ({e['ground_object']:,} ground called object)")
    click.echo(f"type II   {pct(e['type_ii'])}  ({e['object_ground']:,} object called ground)")
    click.echo(f"total     {pct(e['total'])}  ({e['ground_object'] + e['object_ground']:,} wrong)")
    click.echo(f"kappa     {pct(e['kappa'])}")
