"""``lidar2city info FILE``."""

from __future__ import annotations

import json

import click

from ._options import crs_option

ASPRS_NAMES = {0: "created", 1: "unclassified", 2: "ground", 3: "low vegetation",
               4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "noise",
               9: "water", 17: "bridge", 26: "civil structure"}


@click.command("info")
@click.argument("file", type=click.Path(dir_okay=False))
@crs_option
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
def command(file, crs, as_json):
    """Summarise a LAS/LAZ FILE: points, bounds, CRS, units, density, classes, returns."""
    from ..tools.info import las_info

    info = las_info(file, crs=crs)
    if as_json:
        click.echo(json.dumps(info, indent=2))
        return
    click.echo(f"{info['path']}: LAS {info['version']}, point format {info['point_format']}")
    click.echo(f"  points   {info['points']:,}")
    if info["bounds"]:
        b = info["bounds"]
        xy = 7 if info.get("note") else 2  # degrees: 1e-7 is about a centimetre
        click.echo(f"  bounds   x {b[0]:.{xy}f} .. {b[3]:.{xy}f}   y {b[1]:.{xy}f} .. "
                   f"{b[4]:.{xy}f}   z {b[2]:.2f} .. {b[5]:.2f}")
    click.echo(f"  crs      {info['crs_name'] or 'none (pass --crs)'}")
    if info.get("note"):
        click.echo(f"  units    degrees: {info['note']}")
    else:
        click.echo(f"  units    {info['xy_unit_m']:g} m per horizontal unit, "
                   f"{info['z_unit_m']:g} m per vertical unit")
        far = (f" ({info['far_points']:,} point(s) far from the rest left out)"
               if info.get("far_points") else "")
        click.echo(f"  density  {info['density_pts_m2']:.2f} pts/m2{far}")
    if info["classes"]:
        click.echo("  classes  " + ", ".join(
            f"{k} {ASPRS_NAMES.get(k, '?')}: {v:,}" for k, v in info["classes"].items()))
    if info["returns"]:
        click.echo("  returns  " + ", ".join(
            f"{k} return(s): {v:,}" for k, v in info["returns"].items()))
