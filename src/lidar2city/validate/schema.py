"""CityJSON schema validation against the official JSON schemas (resolved locally).

The official CityJSON 2.0.2 schemas (cityjson/specs, CC0) are shipped in the
package (``lidar2city/validate/schemas-2.0.2``); ``schema_dir`` or
``$LIDAR2CITY_CITYJSON_SCHEMAS`` name another folder of them. All references
between the schema files are resolved from that folder; nothing is fetched
from the network and no data folder is needed.

Error messages name the rule that fails and where (``CityObjects/b1/geometry/0:
type 'MultiSolid' is not one of the types allowed here (MultiSurface,
CompositeSurface, Solid, CompositeSolid)``), never the geometry itself.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..errors import FileFormatError

__all__ = ["find_schema_dir", "schema_validator", "schema_errors"]

_MAIN = "cityjson.schema.json"
#: the schemas shipped with the package
SHIPPED = Path(__file__).resolve().parent / "schemas-2.0.2"


def find_schema_dir(schema_dir=None) -> Path | None:
    """The folder holding ``cityjson.schema.json``: ``schema_dir``, else
    ``$LIDAR2CITY_CITYJSON_SCHEMAS``, else the schemas shipped with the package.

    Raises
    ------
    FileFormatError
        When ``schema_dir`` (or the environment variable) names a folder
        without the schemas.
    """
    given = schema_dir if schema_dir is not None else os.environ.get("LIDAR2CITY_CITYJSON_SCHEMAS")
    if given:
        if not (Path(given) / _MAIN).is_file():
            raise FileFormatError(f"{str(given)!r} holds no {_MAIN}")
        return Path(given)
    return SHIPPED if (SHIPPED / _MAIN).is_file() else None


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


def _where(err, prefix=()):
    return "/".join(str(p) for p in (*prefix, *err.absolute_path)) or "(root)"


def _short(value, limit=60) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _rule(err) -> str:
    """What rule ``err`` breaks, in a line that never prints a whole geometry."""
    kind = err.validator
    if kind == "oneOf" and isinstance(err.instance, dict) and "type" in err.instance:
        # each alternative fixes "type" with a const (behind a $ref): the consts missed
        allowed = [c.validator_value for c in err.context
                   if c.validator == "const" and list(c.relative_path) == ["type"]]
        if allowed and err.instance.get("type") not in allowed:
            return (f"type {err.instance.get('type')!r} is not one of the types allowed here "
                    f"({', '.join(allowed)})")
        from jsonschema.exceptions import best_match

        best = best_match(err.context) if err.context else None
        if best is not None:
            return (f"matches none of the allowed forms; as {err.instance.get('type')}: "
                    f"{_where(best)}: {_rule(best)}")
    if kind in ("oneOf", "anyOf"):
        return "matches none of the allowed forms"
    if kind == "type":
        return f"{_short(err.instance)} is not of type {err.validator_value!r}"
    if kind in ("const", "enum"):
        return f"{_short(err.instance)} is not {kind} {_short(err.validator_value)}"
    if kind == "required":
        return err.message
    if kind == "additionalProperties":
        return err.message[:200]
    msg = err.message
    return f"{kind}: {msg[:200] + '...' if len(msg) > 200 else msg}"


def _format(err, prefix=()):
    return f"{_where(err, prefix)}: {_rule(err)}"


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
