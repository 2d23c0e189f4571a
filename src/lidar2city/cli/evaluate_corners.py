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

    p, r = read_corners(pred, lod=lod), read_corners(reference, lod=lod)
    _same_area(pred, reference, p, r)
    m = corner_metrics(p, r, tolerance=tolerance, by=by)
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


def _same_area(pred, reference, p, r):
    """A one-line error when the two models' corners do not overlap in plan (another
    area, or another CRS): else every figure is 0 % or nan."""
    import numpy as np

    from ..errors import InputError

    def box(corners):
        xy = [c[:, :2] for c in corners.values() if len(c)]
        return None if not xy else np.r_[np.min([a.min(axis=0) for a in xy], axis=0),
                                          np.max([a.max(axis=0) for a in xy], axis=0)]

    a, b = box(p), box(r)
    if a is not None and b is not None and (a[0] > b[2] or b[0] > a[2] or a[1] > b[3]
                                            or b[1] > a[3]):
        raise InputError(f"{pred!r} and {reference!r} do not overlap (x {a[0]:.0f}..{a[2]:.0f}, "
                         f"y {a[1]:.0f}..{a[3]:.0f} against x {b[0]:.0f}..{b[2]:.0f}, y "
                         f"{b[1]:.0f}..{b[3]:.0f}): not the same area, or not the same CRS")
