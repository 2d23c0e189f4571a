"""``lidar2city evaluate model MODEL --points IN...``."""

from __future__ import annotations

import json

import click

from ._options import crs_option


@click.command("model")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--points", multiple=True, required=True, type=click.Path(dir_okay=False),
              help="Point cloud tile(s) with a building class (repeat for several).")
@crs_option
@click.option("--footprints", type=click.Path(dir_okay=False), default=None,
              show_default="each building's own projection",
              help="Measure the points inside these footprints (matched by id or overlap).")
@click.option("--id-field", default=None, help="Footprint field holding the building id.")
@click.option("--lod", default=None, show_default="the highest per building",
              help="LoD to evaluate.")
@click.option("--json", "as_json", is_flag=True, help="Print per-building rows and the summary as JSON.")
def command(model, points, crs, footprints, id_field, lod, as_json):
    """Per-building RMSE (3-D point to model surface), coverage and validity of MODEL.

    MODEL is a CityJSON file (1.0 to 2.0, ours or a peer's); the building
    points (class 6) inside each footprint are measured against the
    building's triangulated surface.
    """
    from ..tools.evaluate_model import evaluate_model

    rows, summary = evaluate_model(model, list(points), crs=crs, footprints=footprints,
                                   id_field=id_field, lod=lod)
    if as_json:
        click.echo(json.dumps({"summary": summary, "buildings": rows}, indent=2))
        return
    click.echo(f"{'building':<40} {'points':>7} {'rmse':>8} {'coverage':>8}  valid")
    for r in rows:
        rm = f"{r['rmse']:.3f}" if r["rmse"] is not None else "-"
        cv = f"{r['coverage']:.2f}" if r["coverage"] is not None else "-"
        ok = {True: "yes", False: f"no ({r['errors']})", None: r["errors"] or "-"}[r["valid"]]
        click.echo(f"{str(r['id'])[:40]:<40} {r['points']:>7} {rm:>8} {cv:>8}  {ok}")
    click.echo(f"{summary['buildings']} buildings, {summary['measured']} measured: RMSE median "
               f"{summary['rmse_median']} m, mean {summary['rmse_mean']} m, p90 {summary['rmse_p90']} m; "
               f"coverage median {summary['coverage_median']}; valid {summary['valid']}, "
               f"invalid {summary['invalid']} ({summary['seconds']} s)")
