"""CityJSON schema validation against the official JSON schemas (resolved locally).

The CityJSON 2.0.2 schemas (cityjson/specs, CC0) are not shipped inside the
package: they are looked up in ``schema_dir`` when given, else in
``$LIDAR2CITY_CITYJSON_SCHEMAS``, else in
``$LIDAR2CITY_DATA/cityjson/schemas-2.0.2`` (default data folder:
``../shared/data`` beside the checkout). All references between the schema
files are resolved from that folder; nothing is fetched from the network.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import FileFormatError

__all__ = ["find_schema_dir", "schema_validator", "schema_errors"]

_MAIN = "cityjson.schema.json"


def find_schema_dir(schema_dir=None) -> Path | None:
    """The folder holding ``cityjson.schema.json`` (see module doc), or None."""
    candidates = []
    if schema_dir is not None:
        candidates.append(Path(schema_dir))
    if os.environ.get("LIDAR2CITY_CITYJSON_SCHEMAS"):
        candidates.append(Path(os.environ["LIDAR2CITY_CITYJSON_SCHEMAS"]))
    if os.environ.get("LIDAR2CITY_DATA"):
        candidates.append(Path(os.environ["LIDAR2CITY_DATA"]) / "cityjson" / "schemas-2.0.2")
    here = Path(__file__).resolve()
    for up in here.parents[2:6]:
        candidates.append(up.parent / "shared" / "data" / "cityjson" / "schemas-2.0.2")
        candidates.append(up / "shared" / "data" / "cityjson" / "schemas-2.0.2")
    for c in candidates:
        if (c / _MAIN).is_file():
            return c
    if schema_dir is not None:
        raise FileFormatError(f"{str(schema_dir)!r} holds no {_MAIN}")
    return None


_CACHE: dict = {}


def schema_validator(schema_dir=None, *, main: str = _MAIN):
    """A jsonschema Draft 7 validator of CityJSON with every schema file registered.

    Raises
    ------
    FileFormatError
        When no schema folder is found.
    """
    import jsonschema
    from referencing import Registry, Resource
    from referencing.jsonschema import DRAFT7

    d = find_schema_dir(schema_dir)
    if d is None:
        raise FileFormatError("CityJSON schemas not found: pass --schemas DIR or set "
                              "LIDAR2CITY_CITYJSON_SCHEMAS to the schemas-2.0.2 folder")
    key = (str(d), main)
    if key in _CACHE:
        return _CACHE[key]
    resources = []
    docs = {}
    for f in sorted(d.glob("*.json")):
        doc = json.loads(f.read_text(encoding="utf-8"))
        docs[f.name] = doc
        res = Resource.from_contents(doc, default_specification=DRAFT7)
        resources.append((doc.get("$id", f.name), res))
        resources.append((f.name, res))
    registry = Registry().with_resources(resources)
    validator = jsonschema.Draft7Validator(docs[main], registry=registry)
    _CACHE[key] = validator
    _CACHE[("registry", str(d))] = registry
    return validator


def _object_validator(schema_dir, main, ref):
    """A validator of one City Object type (``cityobjects.schema.json#/Building``...)."""
    import jsonschema

    key = (str(find_schema_dir(schema_dir)), main, ref)
    if key not in _CACHE:
        base = schema_validator(schema_dir, main=main)
        root = base.schema.get("$id", "")
        target = root.rsplit("/", 1)[0] + "/" + ref if "/" in root else ref
        registry = _CACHE[("registry", str(find_schema_dir(schema_dir)))]
        _CACHE[key] = jsonschema.Draft7Validator({"$ref": target}, registry=registry)
    return _CACHE[key]


def _format(err, prefix=()):
    where = "/".join(str(p) for p in (*prefix, *err.absolute_path)) or "(root)"
    msg = err.message
    return f"{where}: {msg[:300] + '...' if len(msg) > 300 else msg}"


def schema_errors(doc, *, schema_dir=None, limit: int = 20) -> list[str]:
    """Schema errors of a CityJSON document (dict), as readable strings (empty: valid).

    A CityJSONFeature (``"type": "CityJSONFeature"``) is checked against
    ``cityjsonfeature.schema.json``. City Objects are checked one by one
    against the schema of their ``type`` (what the schema's ``oneOf`` over
    the types amounts to, since each type fixes ``type`` with a ``const``),
    which is much faster and gives clearer messages.
    """
    main = "cityjsonfeature.schema.json" if doc.get("type") == "CityJSONFeature" else _MAIN
    v = schema_validator(schema_dir, main=main)
    objects = doc.get("CityObjects")
    out = []
    if isinstance(objects, dict):
        refs = v.schema["properties"]["CityObjects"]["additionalProperties"]["oneOf"]
        names = {r["$ref"].rsplit("/", 1)[-1]: r["$ref"] for r in refs}
        shallow = dict(doc)
        shallow["CityObjects"] = {}
        out += [_format(e) for e in v.iter_errors(shallow)]
        for oid, obj in objects.items():
            t = obj.get("type") if isinstance(obj, dict) else None
            if isinstance(t, str) and t in names:
                ref = names[t]
            elif isinstance(t, str) and t.startswith("+"):
                ref = names.get("ExtensionObject")
            else:
                out.append(f"CityObjects/{oid}: {t!r} is not a CityJSON City Object type")
                continue
            out += [_format(e, ("CityObjects", oid))
                    for e in _object_validator(schema_dir, main, ref).iter_errors(obj)]
            if len(out) >= limit:
                break
    else:
        out += [_format(e) for e in v.iter_errors(doc)]
    return out[:limit]
