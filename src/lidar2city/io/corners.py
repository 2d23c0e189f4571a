"""Read building corners (model vertices per building) from CityJSON or OBJ files.

A minimal reader for corner metrics: per building, the distinct vertices its
geometry uses (transform applied), in the file's coordinates.
"""

from __future__ import annotations

import logging

import numpy as np

from ..errors import FileFormatError
from ._atomic import check_input_file
from .cityjson import read_cityjson

logger = logging.getLogger(__name__)

__all__ = ["read_corners", "read_cityjson_corners", "read_obj_corners"]


def _indices(boundaries, out):
    """Collect the vertex indices of nested CityJSON boundaries."""
    stack = [boundaries]
    while stack:
        b = stack.pop()
        if isinstance(b, list):
            if b and isinstance(b[0], int):
                out.extend(b)
            else:
                stack.extend(b)
        elif isinstance(b, int):
            out.append(b)


def _lod_key(lod):
    try:
        return float(str(lod))
    except ValueError:
        return -1.0


def _unique_rows(xyz, decimals=3):
    if len(xyz) == 0:
        return xyz.reshape(0, 3)
    _, first = np.unique(np.round(xyz, decimals), axis=0, return_index=True)
    return xyz[np.sort(first)]


def read_cityjson_corners(path, *, lod: str | None = None) -> dict[str, np.ndarray]:
    """Corners per building of a CityJSON file.

    Parameters
    ----------
    path : str or Path
    lod : str, optional
        Geometry LoD to read (e.g. ``"2.2"``); default the highest per object.

    Returns
    -------
    dict of str to ndarray (K, 3)
        Building id -> distinct vertices (world coordinates, transform applied).
        BuildingParts are merged into their parent building.

    Raises
    ------
    FileFormatError
        Not JSON, or not a CityJSON object.

    Notes
    -----
    The file is read with :func:`lidar2city.io.cityjson.read_cityjson`, so
    CityJSONSeq files are read too.
    """
    model = read_cityjson(path)
    verts, objects = model.vertices, model.objects
    idx_by_building: dict[str, list] = {}

    def root(oid):
        seen = set()
        while True:
            parents = objects.get(oid, {}).get("parents") or []
            if not parents or oid in seen:
                return oid
            seen.add(oid)
            oid = parents[0]

    for oid, obj in objects.items():
        if not str(obj.get("type", "")).startswith("Building"):
            continue
        geoms = obj.get("geometry") or []
        if lod is not None:
            geoms = [g for g in geoms if str(g.get("lod")) == str(lod)]
        elif geoms:
            top = max(_lod_key(g.get("lod")) for g in geoms)
            geoms = [g for g in geoms if _lod_key(g.get("lod")) == top]
        idx: list = []
        for g in geoms:
            if g.get("type") == "GeometryInstance":
                continue
            _indices(g.get("boundaries", []), idx)
        key = root(oid)
        idx_by_building.setdefault(key, []).extend(idx)
    out = {}
    for key, idx in idx_by_building.items():
        if not idx:
            continue
        ii = np.unique(np.asarray(idx, dtype=np.int64))
        if ii.max() >= len(verts) or ii.min() < 0:
            raise FileFormatError(f"{str(path)!r}: building {key} refers to a missing vertex")
        out[key] = _unique_rows(verts[ii])
    return out


def read_obj_corners(path) -> dict[str, np.ndarray]:
    """Corners per object (``o``) or group (``g``) of a Wavefront OBJ file.

    Faces before any ``o``/``g`` line belong to building ``"0"``.
    """
    p = check_input_file(path)
    verts, faces = [], {}
    current = "0"
    try:
        with open(p, encoding="utf-8") as fh:
            for line in fh:
                parts = line.split()
                if not parts:
                    continue
                tag = parts[0]
                if tag == "v":
                    verts.append([float(t) for t in parts[1:4]])
                elif tag in ("o", "g") and len(parts) > 1:
                    current = " ".join(parts[1:])
                elif tag == "f":
                    ids = []
                    for t in parts[1:]:
                        i = int(t.split("/")[0])
                        ids.append(i - 1 if i > 0 else len(verts) + i)
                    faces.setdefault(current, []).extend(ids)
    except (UnicodeDecodeError, ValueError, IndexError) as exc:
        raise FileFormatError(f"{str(p)!r} is not a readable OBJ file: {exc}") from None
    v = np.asarray(verts, dtype=np.float64).reshape(-1, 3)
    out = {}
    for name, ids in faces.items():
        ii = np.unique(np.asarray(ids, dtype=np.int64))
        if len(ii) and (ii.max() >= len(v) or ii.min() < 0):
            raise FileFormatError(f"{str(p)!r}: object {name} refers to a missing vertex")
        out[name] = _unique_rows(v[ii])
    return out


def read_corners(path, *, lod: str | None = None) -> dict[str, np.ndarray]:
    """Corners per building of a ``.json`` (CityJSON) or ``.obj`` file."""
    name = str(path).lower()
    if name.endswith(".obj"):
        return read_obj_corners(path)
    if name.endswith(".json"):
        return read_cityjson_corners(path, lod=lod)
    raise FileFormatError(f"{str(path)!r}: corners are read from .city.json or .obj files")
