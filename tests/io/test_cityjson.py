import json

import numpy as np
import pytest
from pyproj import CRS
from shapely.geometry import box

from lidar2city.datamodel import BuildingResult
from lidar2city.io.cityjson import read_cityjson, write_cityjson, write_cityjsonseq
from lidar2city.lod import Lod1Config, reconstruct_building
from lidar2city.validate import check_solid

ORIGIN = np.array([85000.0, 447000.0, 0.0])


def _results():
    rng = np.random.default_rng(0)
    fp = box(0, 0, 20, 12)
    xy = rng.uniform([0, 0], [20, 12], (3000, 2))
    pts = np.column_stack([xy, np.where(xy[:, 0] < 8, 15.0, 6.0)])
    ring = fp.buffer(3).difference(fp)
    g = rng.uniform(-3, 23, (3000, 2))
    import shapely
    g = g[shapely.contains_xy(ring, g[:, 0], g[:, 1])]
    ground = np.column_stack([g, np.zeros(len(g))])
    ok = reconstruct_building(fp, pts, ground, config=Lod1Config(lods=("1.2", "1.3")), id="b1")
    bad = reconstruct_building(box(40, 0, 45, 5), pts, ground, id="b2")
    return [ok, bad]


def test_write_read_round_trip(tmp_path, data):
    from lidar2city.validate.schema import schema_errors

    res = _results()
    assert res[0].ok and res[1].reason == "no points"
    path = tmp_path / "x.city.json"
    write_cityjson(path, res, origin=ORIGIN, crs=CRS.from_epsg(7415), configuration={"lod1": {"a": 1}},
                   attributes={"name": ["one", "two"]})
    doc = json.loads(path.read_text())
    assert schema_errors(doc, schema_dir=data / "cityjson" / "schemas-2.0.2") == []
    assert doc["version"] == "2.0" and doc["transform"]["scale"] == [0.001] * 3
    assert doc["metadata"]["referenceSystem"] == "https://www.opengis.net/def/crs/EPSG/0/7415"
    assert doc["+lidar2city"]["configuration"] == {"lod1": {"a": 1}}
    assert all(isinstance(i, int) for v in doc["vertices"] for i in v)
    b1 = doc["CityObjects"]["b1"]
    assert b1["attributes"]["name"] == "one" and len(b1["children"]) == 2
    for c in b1["children"]:
        assert doc["CityObjects"][c]["type"] == "BuildingPart"
        assert doc["CityObjects"][c]["parents"] == ["b1"]
    b2 = doc["CityObjects"]["b2"]
    assert "geometry" not in b2 and b2["attributes"]["reason"] == "no points"
    sem = b1["geometry"][0]["semantics"]
    assert {s["type"] for s in sem["surfaces"]} == {"GroundSurface", "WallSurface", "RoofSurface"}

    model = read_cityjson(path)
    assert model.buildings() == ["b1", "b2"]
    s12 = model.solids("b1", lod="1.2", include_children=False, origin=ORIGIN)
    assert len(s12) == 1 and check_solid(s12[0]) == []
    assert np.allclose(np.sort(s12[0].vertices, axis=0), np.sort(res[0].solids["1.2"].vertices, axis=0),
                       atol=5e-4)
    parts = model.solids("b1", lod="1.3", origin=ORIGIN)
    assert len(parts) == 2 and all(check_solid(p) == [] for p in parts)


def test_cityjsonseq(tmp_path, data):
    from lidar2city.validate.schema import schema_errors

    res = _results()
    path = tmp_path / "x.city.jsonl"
    write_cityjsonseq(path, res, origin=ORIGIN, crs=CRS.from_epsg(7415))
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert lines[0]["type"] == "CityJSON" and [f["id"] for f in lines[1:]] == ["b1", "b2"]
    sd = data / "cityjson" / "schemas-2.0.2"
    assert all(schema_errors(doc, schema_dir=sd) == [] for doc in lines)
    model = read_cityjson(path)
    assert len(model.solids("b1", lod="1.2", include_children=False)) == 1


def test_read_peer_cityjson_10(data):
    model = read_cityjson(data / "delft" / "peer_3dfier_lod1.city.json")
    assert model.version == "1.0" and len(model.buildings()) == 160
    solids = model.solids(model.buildings()[0])
    assert solids and len(solids[0].surfaces) > 4


def test_failed_only_document_is_valid(tmp_path, data):
    from lidar2city.validate.schema import schema_errors

    r = BuildingResult("x", status="failed", reason="no points")
    path = tmp_path / "f.city.json"
    write_cityjson(path, [r], origin=ORIGIN)
    doc = json.loads(path.read_text())
    assert doc["vertices"] == [] and schema_errors(doc, schema_dir=data / "cityjson" / "schemas-2.0.2") == []


def test_not_cityjson(tmp_path):
    from lidar2city.errors import FileFormatError

    p = tmp_path / "a.json"
    p.write_text('{"type": "FeatureCollection"}')
    with pytest.raises(FileFormatError):
        read_cityjson(p)
