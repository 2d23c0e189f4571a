"""Read user-chosen primitives and approximate parameters per footprint (semi-automatic mode).

Accepted files (``--primitives P``):

- **CSV** with a header: ``id,primitive[,x,y,azimuth,length,width,height,roof_height,hip_length]``;
- **TOML**: an array of tables ``[[building]]`` with the same keys, or a
  table ``[buildings.<id>]`` per footprint;
- any **OGR vector** source (GPKG, GeoJSON, shapefile) with those fields; a
  point geometry gives ``x``/``y`` when the fields are absent.

``primitive`` is one of ``box, gable, hip, shed, prism``; ``x``, ``y`` are world
coordinates (the footprints' CRS units), ``azimuth`` degrees counter-clockwise
from east along the ridge / length, the other values metres. Empty values
mean "take from the footprint / points". Other fields are ignored.
"""

from __future__ import annotations

import csv
import logging
import math
import tomllib

from ..errors import FileFormatError, InputError
from ._atomic import check_input_file

logger = logging.getLogger(__name__)

__all__ = ["read_primitives", "PARAMETER_FIELDS"]

PARAMETER_FIELDS = ("x", "y", "azimuth", "length", "width", "height", "roof_height", "hip_length")
_ID_FIELDS = ("id", "identificatie", "identificatiebagpnd", "fid")


def _clean(row: dict, where: str, id_field: str | None) -> tuple[str, dict]:
    keys = {str(k).strip().lower(): v for k, v in row.items() if k is not None}
    if id_field is not None:
        idf = id_field.lower()
        if idf not in keys:
            raise InputError(f"{where}: no {id_field!r} field")
    else:
        idf = next((f for f in _ID_FIELDS if f in keys), None)
        if idf is None:
            raise InputError(f"{where}: no id field (one of {', '.join(_ID_FIELDS)})")
    fid = keys[idf]
    if fid is None or str(fid).strip() == "":
        raise InputError(f"{where}: empty id")
    kind = keys.get("primitive")
    if kind is None or str(kind).strip() == "":
        raise InputError(f"{where}: no 'primitive' value")
    spec = {"primitive": str(kind).strip().lower()}
    for name in PARAMETER_FIELDS:
        v = keys.get(name)
        if v is None or (isinstance(v, str) and v.strip() == ""):
            continue
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise InputError(f"{where}: {name} = {v!r} is not a number") from None
        if not math.isfinite(f):
            continue
        if name in ("length", "width", "height", "hip_length") and f <= 0:
            raise InputError(f"{where}: {name} must be > 0, got {f}")
        spec[name] = f
    if isinstance(fid, float) and fid.is_integer():
        fid = int(fid)
    return str(fid).strip(), spec


def read_primitives(path, *, id_field: str | None = None) -> dict[str, dict]:
    """Read a primitives file into ``{footprint id: {"primitive": kind, parameter: value}}``.

    Parameters
    ----------
    path : str or Path
        ``.csv``, ``.toml`` or an OGR vector source.
    id_field : str, optional
        Field naming the footprint id (default: the first of ``id``,
        ``identificatie``, ``identificatiebagpnd``, ``fid``).

    Raises
    ------
    FileFormatError
        Unreadable file.
    InputError
        Missing id or primitive, non-numeric parameters, duplicated ids.
    """
    p = check_input_file(path)
    suffix = p.suffix.lower()
    rows: list[tuple[str, dict]] = []
    if suffix == ".csv":
        try:
            with open(p, newline="", encoding="utf-8-sig") as fh:
                reader = csv.DictReader(fh)
                for i, row in enumerate(reader, start=2):
                    rows.append(_clean(row, f"{p.name} line {i}", id_field))
        except (UnicodeDecodeError, csv.Error) as exc:
            raise FileFormatError(f"{str(p)!r} is not a readable CSV file: {exc}") from None
    elif suffix == ".toml":
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise FileFormatError(f"{str(p)!r} is not valid TOML: {exc}") from None
        for i, row in enumerate(doc.get("building", []), start=1):
            rows.append(_clean(row, f"{p.name} [[building]] {i}", id_field))
        for key, row in (doc.get("buildings") or {}).items():
            rows.append(_clean({"id": key, **row}, f"{p.name} [buildings.{key}]", "id"))
        if not rows:
            raise InputError(f"{p.name}: no [[building]] or [buildings.<id>] tables")
    else:
        import pyogrio
        import shapely

        from .vector import no_pam

        try:
            with no_pam():
                meta, _, wkb, field_data = pyogrio.raw.read(str(p), force_2d=True)
        except Exception as exc:
            raise FileFormatError(f"{str(p)!r} is not a readable vector source: "
                                  f"{str(exc).splitlines()[0]}") from None
        names = list(meta["fields"])
        geoms = shapely.from_wkb(wkb) if wkb is not None else [None] * (len(field_data[0]) if field_data else 0)
        n = len(geoms)
        for i in range(n):
            row = {name: field_data[j][i] for j, name in enumerate(names)}
            g = geoms[i]
            if g is not None and g.geom_type == "Point" and not row.get("x") and not row.get("y"):
                row["x"], row["y"] = g.x, g.y
            rows.append(_clean(row, f"{p.name} feature {i}", id_field))
    out: dict[str, dict] = {}
    for fid, spec in rows:
        if fid in out:
            raise InputError(f"{p.name}: footprint id {fid!r} given twice")
        out[fid] = spec
    return out
