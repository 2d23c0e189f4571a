"""``lidar2city validate FILE``."""

from __future__ import annotations

import json

import click


@click.command("validate")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--schemas", "schema_dir", type=click.Path(file_okay=False), default=None,
              show_default="$LIDAR2CITY_CITYJSON_SCHEMAS, else the CityJSON 2.0.2 schemas "
                           "shipped with lidar2city",
              help="Folder of the CityJSON 2.0 schemas.")
@click.option("--no-schema", is_flag=True, help="Only the geometric checks.")
@click.option("--planarity", default=0.01, show_default=True,
              help="Planarity tolerance (CRS units) of the faces.")
@click.option("--snap", default=0.001, show_default=True,
              help="Vertices closer than this are one (CRS units).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON report.")
@click.option("--all", "show_all", is_flag=True, help="List valid objects too.")
def command(file, schema_dir, no_schema, planarity, snap, as_json, show_all):
    """Validate a CityJSON FILE: schema and val3dity-like geometric checks.

    Every solid must be a closed 2-manifold shell of planar, outward-oriented,
    non-degenerate, non-intersecting faces; building parts must not overlap.
    Exits with status 1 when the file is invalid.
    """
    from ..tools.validate import validate_file

    report = validate_file(file, schema_dir=schema_dir, schema=not no_schema,
                           planarity_tolerance=planarity, snap_tolerance=snap)
    summary = report.summary()
    if as_json:
        click.echo(json.dumps({
            "file": report.path, "valid": report.valid, "summary": summary,
            "schema_errors": report.schema_errors, "schema_note": report.schema_note,
            "objects": [{"id": o.id, "type": o.type, "valid": o.valid,
                         "errors": [{"lod": lod, "solid": k, "code": i.code, "name": i.name,
                                     "surface": i.surface, "detail": i.detail}
                                    for lod, k, i in o.issues]}
                        for o in report.objects if show_all or not o.valid]}, indent=2))
    else:
        if report.schema_note:
            click.echo(f"note: {report.schema_note}")
        if report.schema_errors:
            click.echo(f"schema: {len(report.schema_errors)} error(s)")
            for e in report.schema_errors[:20]:
                click.echo(f"  {e}")
        for o in report.objects:
            if o.valid and not show_all:
                continue
            state = "valid" if o.valid else "INVALID"
            click.echo(f"{o.type} {o.id}: {state}")
            for lod, k, issue in o.issues:
                click.echo(f"  LoD{lod} solid {k}: {issue}")
        codes = ", ".join(f"{c} x{n}" for c, n in summary["codes"].items())
        click.echo(f"{report.path}: {'VALID' if report.valid else 'INVALID'} - schema "
                   f"{summary['schema']}; {summary['objects']} objects "
                   f"({summary['with_geometry']} with geometry), {summary['invalid']} invalid"
                   + (f" [{codes}]" if codes else ""))
    if not report.valid:
        raise SystemExit(1)
