"""read_cityjson_corners reads through io.cityjson.read_cityjson (CityJSON and CityJSONSeq)."""

import json

import numpy as np

from lidar2city.io.corners import read_corners


def _square(z):
    return [[0, 0, z], [1000, 0, z], [1000, 1000, z], [0, 1000, z]]


def test_corners_of_cityjson_and_cityjsonseq_agree(tmp_path):
    transform = {"scale": [0.01, 0.01, 0.01], "translate": [100.0, 200.0, 0.0]}
    b = {"type": "Building", "geometry": [{"type": "MultiSurface", "lod": "1.2",
                                           "boundaries": [[[0, 1, 2, 3]]]}]}
    doc = {"type": "CityJSON", "version": "2.0", "transform": transform,
           "CityObjects": {"b1": b}, "vertices": _square(500)}
    one = tmp_path / "one.city.json"
    one.write_text(json.dumps(doc))
    header = {"type": "CityJSON", "version": "2.0", "transform": transform,
              "CityObjects": {}, "vertices": []}
    feature = {"type": "CityJSONFeature", "id": "b1", "CityObjects": {"b1": b},
               "vertices": _square(500)}
    seq = tmp_path / "seq.city.jsonl.json"
    seq.write_text(json.dumps(header) + "\n" + json.dumps(feature) + "\n")
    a, s = read_corners(one), read_corners(seq)
    expected = np.array([[100, 200, 5], [110, 200, 5], [110, 210, 5], [100, 210, 5.0]])
    assert set(a) == set(s) == {"b1"}
    np.testing.assert_allclose(a["b1"], expected)
    np.testing.assert_allclose(s["b1"], expected)
