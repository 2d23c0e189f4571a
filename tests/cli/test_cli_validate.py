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


def test_validate_an_obj_or_gpkg_output_says_what_it_takes(runner, tmp_path):
    """`validate` on the OBJ or GeoPackage that `reconstruct` wrote: one line saying the
    file is not CityJSON and how to get one, not a JSON or UTF-8 decoding error."""
    from pyproj import CRS

    from lidar2city.cli.main import cli
    from lidar2city.io.obj import write_obj
    from lidar2city.io.vector import write_polygons

    rs = [BuildingResult("a", solids={"1.2": prism_solid(box(0, 0, 5, 5), 0.0, 4.0)})]
    write_obj(tmp_path / "m.obj", rs, origin=[1000.0, 2000.0, 0.0])
    write_polygons(tmp_path / "m.gpkg", [box(0, 0, 5, 5)], {"id": ["a"]}, origin=(1000.0, 2000.0),
                   crs=CRS.from_epsg(28992))
    for name, what in (("m.obj", "an OBJ mesh"), ("m.gpkg", "a GeoPackage")):
        res = runner.invoke(cli, ["validate", str(tmp_path / name)])
        assert res.exit_code == 1, res.output
        assert res.output.strip().splitlines() == [
            f"Error: {str(tmp_path / name)!r} is not CityJSON: it is {what}, read here as "
            "CityJSON (.city.json / .city.jsonl): make the model with -o NAME.city.json"]
