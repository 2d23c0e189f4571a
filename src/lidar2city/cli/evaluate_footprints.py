"""``lidar2city evaluate footprints PRED --reference REF``."""

from __future__ import annotations

import json

import click

from ._options import crs_option


def _extent(ctx, param, value):
    if value is None:
        return None
    try:
        parts = [float(v) for v in value.split(",")]
    except ValueError:
        parts = []
    if len(parts) != 4:
        raise click.BadParameter("expected XMIN,YMIN,XMAX,YMAX")
    return tuple(parts)


@click.command("footprints")
@click.argument("pred", type=click.Path(dir_okay=False))
@click.option("--reference", "-r", required=True, type=click.Path(dir_okay=False),
              help="Reference footprints (any OGR source).")
@crs_option
@click.option("--min-iou", type=float, default=0.5, show_default=True,
              help="IoU for a one-to-one object match.")
@click.option("--extent", callback=_extent, default=None, metavar="XMIN,YMIN,XMAX,YMAX",
              help="Area the data covers (reference CRS): predictions cut by its border are "
                   "left out, with the reference footprints they cover.")
@click.option("--hull-margin", type=float, default=None, metavar="M",
              help="Clip predictions to the reference's convex hull buffered by M metres "
                   "(when the reference covers only part of the data).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def command(pred, reference, crs, min_iou, extent, hull_margin, as_json):
    """Compare predicted footprints PRED with reference footprints.

    Per-area completeness / correctness / quality (IoU of all footprints),
    one-to-one object matches at IoU >= --min-iou, mean IoU, Hausdorff
    distance, and the share of outline length within 3 degrees of each
    polygon's dominant axes.
    """
    from ..tools.evaluate import evaluate_footprints

    rep = evaluate_footprints(pred, reference, crs=crs, min_iou=min_iou, extent=extent,
                              hull_margin=hull_margin)
    if as_json:
        click.echo(json.dumps(rep, indent=2))
        return
    a, o, p = rep["area"], rep["objects"], rep["protocol"]
    click.echo(f"footprints {pred} vs {reference}")
    if p["pred_cut"] or p["ref_cut"] or p["area"] is not None:
        click.echo(f"  protocol      {p['pred_cut']} cut predictions and {p['ref_cut']} references "
                   "left out" + (f"; area {p['area']:.0f} m2" if p["area"] is not None else ""))
    click.echo(f"  per area      completeness {a['completeness']:.3f}  correctness "
               f"{a['correctness']:.3f}  quality {a['quality']:.3f}")
    click.echo(f"  per object    {o['matched']} matched of {o['n_pred']} predicted / "
               f"{o['n_ref']} reference at IoU >= {min_iou:g}: precision {o['precision']:.3f}  "
               f"recall {o['recall']:.3f}")
    click.echo(f"  IoU           mean of matches {o['mean_iou']:.3f}  mean best per reference "
               f"{o['mean_best_iou']:.3f}")
    if o["hausdorff_mean"] is None:
        click.echo("  Hausdorff     no match")
    else:
        click.echo(f"  Hausdorff     mean {o['hausdorff_mean']:.2f} m  median "
                   f"{o['hausdorff_median']:.2f} m (matched pairs)")
    click.echo(f"  alignment     {100 * rep['alignment']['aligned_share']:.1f} % of outline length "
               "within 3 deg of the dominant axes")
    if "pixels" in rep:
        px = rep["pixels"]
        click.echo(f"  pixels        overall accuracy {px['overall_accuracy']:.3f}  kappa "
                   f"{px['kappa']:.3f}  producer's {px['producers_accuracy']:.3f}  user's "
                   f"{px['users_accuracy']:.3f} ({px['cell']:g} m cells)")
