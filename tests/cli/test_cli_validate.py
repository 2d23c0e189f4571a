import json

import numpy as np
from shapely.geometry import box

from lidar2city.datamodel import BuildingResult
from lidar2city.io.cityjson import write_cityjson
from lidar2city.lod.prism import prism_solid


def _write(path):
    rs = [BuildingResult("a", solids={"1.2": prism_solid(box(0, 0, 5, 5), 0.0, 4.0)}),
          BuildingResult("b", solids={"1.2": prism_solid(box(5, 0, 9, 5), 0.0, 7.0)})]
    write_cityjson(path, rs, origin=np.array([1000.0, 2000.0, 0.0]))


def test_validate_valid_and_invalid(runner, tmp_path, data):
    from lidar2city.cli.main import cli

    p = tmp_path / "m.city.json"
    _write(p)
    sd = str(data / "cityjson" / "schemas-2.0.2")
    res = runner.invoke(cli, ["validate", str(p), "--schemas", sd])
    assert res.exit_code == 0, res.output
    assert "VALID - schema valid" in res.output
    doc = json.loads(p.read_text())
    shell = doc["CityObjects"]["b"]["geometry"][0]["boundaries"][0]
    shell[2][0] = shell[2][0][::-1]  # flip a wall
    p.write_text(json.dumps(doc))
    res = runner.invoke(cli, ["validate", str(p), "--schemas", sd, "--json"])
    assert res.exit_code == 1
    out = json.loads(res.output)
    assert out["valid"] is False and out["summary"]["invalid"] == 1
    assert out["objects"][0]["id"] == "b" and out["objects"][0]["errors"][0]["code"] == 307
    doc["CityObjects"]["b"]["type"] = "Bulding"
    p.write_text(json.dumps(doc))
    res = runner.invoke(cli, ["validate", str(p), "--schemas", sd])
    assert res.exit_code == 1 and "schema: " in res.output


def test_validate_not_cityjson(runner, tmp_path):
    from lidar2city.cli.main import cli

    p = tmp_path / "x.json"
    p.write_text("[1, 2]")
    res = runner.invoke(cli, ["validate", str(p), "--no-schema"])
    assert res.exit_code == 1 and res.output.startswith("Error:")
