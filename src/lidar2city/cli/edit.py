"""``lidar2city edit MODEL --points TILE... --building ID (--primitive KIND | --footprint F)``."""

from __future__ import annotations

import click

from ._options import crs_option


@click.command("edit")
@click.argument("model", type=click.Path(dir_okay=False))
@click.option("--points", "points", multiple=True, required=True, type=click.Path(dir_okay=False),
              help="A LAS/LAZ tile the model was built from (repeatable).")
@click.option("--building", required=True, help="Id of the building to correct.")
@click.option("--primitive", type=click.Choice(["auto", "box", "gable", "hip", "shed", "prism"]),
              default=None, help="Refit the building as this primitive by least squares "
                                 "(auto: chosen by BIC).")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="With --primitive: an approximate parameter of a user-placed primitive "
                   "(x, y in CRS units; azimuth degrees from east; length, width, height, "
                   "roof_height, hip_length in metres), repeatable.")
@click.option("--footprint", "footprint_file", type=click.Path(dir_okay=False), default=None,
              help="GeoJSON file with the edited outline (one Polygon, model CRS): re-run "
                   "the building's reconstruction from it.")
@click.option("--edits", required=True, type=click.Path(dir_okay=False),
              help="EDITS.json the edit is appended to (created when absent); "
                   "`reconstruct --edits` re-applies it.")
@click.option("--footprints", default=None, type=click.Path(dir_okay=False),
              show_default="the model's LoD1.2 ground outline",
              help="The footprint file given to reconstruct.")
@click.option("--id-field", default=None, help="Footprint field holding the building id.")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              show_default="MODEL, replaced atomically",
              help="Write the corrected model here.")
@crs_option
def command(model, points, building, primitive, params, footprint_file, edits, footprints,
            id_field, output, crs):
    """Correct one building of MODEL and record the edit in EDITS.json.

    \b
    lidar2city edit m.city.json --points t.laz --building 42 --primitive gable --edits E.json
    lidar2city edit m.city.json --points t.laz --building 42 --footprint fp.geojson --edits E.json

    The same refit as the viewer's and as `reconstruct --edits E.json`, which
    reproduces the corrected models. The model is written only when it validates.
    """
    from ..errors import InputError
    from ..tools.edit import EditSession

    if (primitive is None) == (footprint_file is None):
        raise InputError("give either --primitive KIND or --footprint POLY.geojson")
    if params and primitive is None:
        raise InputError("--param goes with --primitive")
    approx = {}
    for p in params:
        name, sep, value = p.partition("=")
        try:
            approx[name.strip()] = float(value)
        except ValueError:
            raise InputError(f"--param {p!r}: expected NAME=NUMBER") from None
        if not sep:
            raise InputError(f"--param {p!r}: expected NAME=NUMBER")
    session = EditSession(model, points, footprints=footprints, crs=crs, id_field=id_field)
    outline = _read_outline(footprint_file) if footprint_file is not None else None
    edit = session.make_edit(building, primitive=primitive, approximate=approx, footprint=outline)
    result = session.refit(edit)
    out = session.save(result, edit, output=output, edits=edits)
    rmse = result.attributes.get("rmse_lod22", result.attributes.get("primitive_residual_rmse"))
    fallback = result.attributes.get("lod22_fallback")
    click.echo(f"building {edit.building}: {edit.describe()}"
               + (f", RMSE {rmse:.3f} m" if isinstance(rmse, (int, float)) else "")
               + (f" (LoD2.2 fallback: {fallback})" if fallback else "")
               + f" -> {out}; edit appended to {edits}", err=True)


def _read_outline(path) -> dict:
    """The one polygon of a GeoJSON file (geometry, Feature or FeatureCollection), unrepaired."""
    import json

    from ..errors import FileFormatError, InputError
    from ..io._atomic import check_input_file

    p = check_input_file(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise FileFormatError(f"{str(p)!r} is not GeoJSON: {exc}") from None
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        feats = doc.get("features") or []
        if len(feats) != 1:
            raise InputError(f"{str(p)!r}: expected one feature (the outline), found {len(feats)}")
        doc = feats[0]
    if isinstance(doc, dict) and doc.get("type") == "Feature":
        doc = doc.get("geometry")
    if not isinstance(doc, dict) or doc.get("type") not in ("Polygon", "MultiPolygon"):
        raise InputError(f"{str(p)!r}: the outline must be a GeoJSON Polygon")
    return doc
