"""``lidar2city evaluate corners PRED --reference REF``: corner correctness, completeness, RMSE."""

from __future__ import annotations

import json

import click


@click.command("corners")
@click.argument("pred", type=click.Path(dir_okay=False))
@click.option("--reference", "-r", "reference", required=True, type=click.Path(dir_okay=False),
              help="Reference models (.city.json or .obj).")
@click.option("--tolerance", default=0.5, show_default=True, type=click.FloatRange(min=0, min_open=True),
              help="Largest 3-D distance of a corner match (file units, normally metres).")
@click.option("--match", "by", type=click.Choice(["auto", "id", "overlap"]), default="auto",
              show_default=True,
              help="Pair buildings by id, by plan overlap, or by id when any are shared.")
@click.option("--lod", default=None, show_default="the highest",
              help="CityJSON geometry LoD to compare.")
@click.option("--per-building", is_flag=True, help="Also list each building's figures.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def command(pred, reference, tolerance, by, lod, per_building, as_json):
    """Compare the corners of PRED building models with those of a reference.

    Corners are matched one-to-one within --tolerance; prints vertex
    correctness (matched / predicted), completeness (matched / reference) and
    the mean and RMSE of the X, Y, Z differences (predicted - reference).
    """
    from ..io.corners import read_corners
    from ..metrics.corners import corner_metrics

    m = corner_metrics(read_corners(pred, lod=lod), read_corners(reference, lod=lod),
                       tolerance=tolerance, by=by)
    if as_json:
        d = m.as_dict()
        if not per_building:
            d.pop("per_building")
        click.echo(json.dumps(d, indent=2))
        return
    click.echo(f"buildings  {m.buildings_paired} paired of {m.buildings_predicted} predicted, "
               f"{m.buildings_reference} reference")
    click.echo(f"corners    {m.n_matched} matched of {m.n_predicted} predicted, "
               f"{m.n_reference} reference (tolerance {m.tolerance:g})")
    click.echo(f"correctness  {100 * m.correctness:.1f} %   completeness  {100 * m.completeness:.1f} %")
    click.echo(f"mean   X {m.mean_x:+.3f}  Y {m.mean_y:+.3f}  Z {m.mean_z:+.3f}")
    click.echo(f"RMSE   X {m.rmse_x:.3f}  Y {m.rmse_y:.3f}  Z {m.rmse_z:.3f}  XY {m.rmse_xy:.3f}")
    if per_building:
        for b in m.per_building:
            click.echo(f"  {b['predicted']} ~ {b['reference']}: {b['n_matched']}/{b['n_predicted']}"
                       f" of {b['n_reference']}  RMSE XY {b['rmse_xy']:.3f} Z {b['rmse_z']:.3f}")
