"""A light reader for plain GeoPackage feature tables, with Python's own sqlite3.

Reading footprints through GDAL (pyogrio) costs ~30 MB of resident memory and
~0.1 s of import before the first feature; a GeoPackage is an SQLite file whose
features are rows and whose geometries are WKB behind a short header, so the
common case needs neither. :func:`read_gpkg_raw` returns what
``pyogrio.raw.read`` returns for the same call, or None when the file is
anything but the plain case (several layers, a field type or value it does not
map exactly as GDAL would: dates, booleans, NULL numbers, empty or NULL
geometries, a CRS without an EPSG code...): the caller then reads it with GDAL.

References
----------
OGC GeoPackage Encoding Standard 1.3, section 2.1.3 (GeoPackage binary geometry).
"""

from __future__ import annotations

import sqlite3
import struct
from pathlib import Path

import numpy as np

__all__ = ["gpkg_crs", "read_gpkg_raw"]

#: declared column type -> numpy dtype, as GDAL maps it (anything else: read with GDAL)
_TYPES = {"TEXT": object, "INTEGER": np.int64, "REAL": np.float64, "DOUBLE": np.float64}

#: envelope sizes (bytes) by the header's envelope indicator (flags bits 1-3)
_ENVELOPE = {0: 0, 1: 32, 2: 48, 3: 48, 4: 64}


def _quote(name) -> str:
    return '"' + str(name).replace('"', '""') + '"'


def _wkb(blob):
    """The WKB of one GeoPackage geometry blob, or None if it is not a plain non-empty one."""
    if not isinstance(blob, bytes) or len(blob) < 8 or blob[:2] != b"GP" or blob[2] != 0:
        return None
    flags = blob[3]
    if flags & 0b110000:  # empty geometry, or an extended (non-standard) type
        return None
    env = _ENVELOPE.get((flags >> 1) & 0b111)
    if env is None:
        return None
    return blob[8 + env:]


def read_gpkg_raw(path, *, layer=None, fids=None, skip_features=0, max_features=None):
    """``(meta, fids, wkb, field_data)`` of a plain GeoPackage layer, or None.

    Parameters
    ----------
    path : Path
        A file named ``*.gpkg``.
    layer : str, optional
        Table name; default the only feature table (a file with several: None).
    fids : sequence of int, optional
        Only these feature ids, in this order (one missing: None).
    skip_features, max_features : int, optional
        Only the features from ``skip_features`` on, at most ``max_features``.

    Returns
    -------
    tuple or None
        ``meta`` holds ``crs`` (``"EPSG:n"``) and ``fields`` (names), ``fids`` an
        int64 array, ``wkb`` a list of 2-D or 3-D WKB (the caller drops Z),
        ``field_data`` one array per field (int64, float64 or object of str), as
        ``pyogrio.raw.read`` gives them; None: read the file with GDAL.
    """
    return _opened(path, layer, lambda con: _read(con, layer, fids, skip_features, max_features))


def gpkg_crs(path, *, layer=None):
    """The CRS (``"EPSG:n"``) of a plain GeoPackage's one feature table, or None.

    Plain: the file's ``gpkg_contents`` registers one table, of features, with one
    geometry column (its layer is then the one GDAL reads, the only one that can
    hold polygons), whose spatial reference system is an EPSG code (the string
    ``pyogrio.read_info`` gives as its ``crs``). ``layer``: None or that table's
    name. None for anything else: the caller asks GDAL.
    """
    def crs(con):
        table = _plain_table(con, layer)
        return None if table is None else _epsg(con, table[1])

    return _opened(path, layer, crs)


def _opened(path, layer, query):
    """``query(connection)`` on the GeoPackage ``path`` opened read-only, or None when
    it is not a ``*.gpkg``, ``layer`` is not None or a name, or SQLite, the WKB or
    the values fail (the caller then reads the file with GDAL)."""
    p = Path(path)
    if p.suffix.lower() != ".gpkg" or (layer is not None and not isinstance(layer, str)):
        return None
    try:
        con = sqlite3.connect(f"{p.resolve().as_uri()}?mode=ro", uri=True)
    except sqlite3.Error:
        return None
    try:
        return query(con)
    except (sqlite3.Error, struct.error, ValueError, TypeError):
        return None
    finally:
        con.close()


def _plain_table(con, layer):
    """``(geometry column, srs_id)`` of the table ``layer`` (default the only one), or None
    when the file registers anything but one feature table with one geometry column."""
    contents = con.execute("SELECT table_name, data_type FROM gpkg_contents").fetchall()
    cols = con.execute("SELECT table_name, column_name, srs_id FROM gpkg_geometry_columns"
                       ).fetchall()
    if len(contents) != 1 or len(cols) != 1 or str(contents[0][1]).lower() != "features":
        return None
    table, column, srs_id = cols[0]
    if contents[0][0] != table or (layer is not None and layer != table):
        return None
    return column, srs_id


def _epsg(con, srs_id):
    """``"EPSG:n"`` of the spatial reference system ``srs_id``, or None (another authority)."""
    srs = con.execute("SELECT organization, organization_coordsys_id FROM gpkg_spatial_ref_sys "
                      "WHERE srs_id = ?", (srs_id,)).fetchall()
    if len(srs) != 1 or str(srs[0][0]).upper() != "EPSG" or int(srs[0][1]) <= 0:
        return None
    return f"EPSG:{int(srs[0][1])}"


def _read(con, layer, fids, skip_features, max_features):
    contents = con.execute("SELECT table_name, data_type FROM gpkg_contents").fetchall()
    cols = con.execute("SELECT table_name, column_name, srs_id FROM gpkg_geometry_columns"
                       ).fetchall()
    if layer is None:
        if len(contents) != 1 or len(cols) != 1:
            return None  # which layer GDAL calls the first is its business
        layer = cols[0][0]
    geom = [(c, s) for t, c, s in cols if t == layer]
    if len(geom) != 1:
        return None
    geom_col, srs_id = geom[0]
    srs = con.execute("SELECT organization, organization_coordsys_id FROM gpkg_spatial_ref_sys "
                      "WHERE srs_id = ?", (srs_id,)).fetchall()
    if len(srs) != 1 or str(srs[0][0]).upper() != "EPSG" or int(srs[0][1]) <= 0:
        return None
    crs = f"EPSG:{int(srs[0][1])}"
    info = con.execute(f"PRAGMA table_info({_quote(layer)})").fetchall()
    pk = [r[1] for r in info if r[5] == 1]
    if len(pk) != 1 or sum(r[5] > 0 for r in info) != 1:
        return None
    fid_col = pk[0]
    if next(r[2] for r in info if r[1] == fid_col).upper() != "INTEGER":
        return None
    fields, dtypes = [], []
    for _, name, decl, *_ in info:
        if name in (fid_col, geom_col):
            continue
        dtype = _TYPES.get(str(decl).upper())
        if dtype is None:
            return None
        fields.append(name)
        dtypes.append(dtype)
    select = ", ".join(_quote(c) for c in [fid_col, geom_col, *fields])
    sql = f"SELECT {select} FROM {_quote(layer)}"
    if fids is not None:
        want = [int(f) for f in np.asarray(fids, dtype=np.int64).ravel()]
        rows = {}
        for i in range(0, len(want), 500):  # SQLite's bound-parameter limit
            part = want[i:i + 500]
            q = f"{sql} WHERE {_quote(fid_col)} IN ({', '.join('?' * len(part))})"
            rows.update((r[0], r) for r in con.execute(q, part))
        if any(f not in rows for f in want):
            return None
        rows = [rows[f] for f in want]
    else:
        sql += f" ORDER BY {_quote(fid_col)}"
        if skip_features or max_features is not None:
            sql += " LIMIT ? OFFSET ?"
            lim = -1 if max_features is None else int(max_features)
            rows = con.execute(sql, (lim, int(skip_features or 0))).fetchall()
        else:
            rows = con.execute(sql).fetchall()
    wkb = [_wkb(r[1]) for r in rows]
    if any(w is None for w in wkb):
        return None
    data = []
    for j, dtype in enumerate(dtypes, start=2):
        values = [r[j] for r in rows]
        if dtype is np.float64:  # GDAL reads a NULL real as NaN
            values = [np.nan if v is None else v for v in values]
        kind = str if dtype is object else (int if dtype is np.int64 else (int, float))
        if any(v is None or not isinstance(v, kind) or isinstance(v, bool) for v in values):
            return None  # other NULLs and stray storage classes: as GDAL maps them
        arr = np.empty(len(values), dtype=object) if dtype is object else None
        if arr is not None:
            arr[:] = values
        data.append(arr if arr is not None else np.array(values, dtype=dtype))
    meta = {"crs": crs, "fields": np.array(fields, dtype=object)}
    return meta, np.array([r[0] for r in rows], dtype=np.int64), wkb, data
