import json

import numpy as np
import pytest
from shapely.geometry import Polygon, box


def _synthetic_inputs(tmp_path, tile_crs=True):
    """Two flat-roofed blocks and an L-shaped one on flat ground, 10 pts/m2, in RD New
    (the tile without a CRS when not ``tile_crs``)."""
    from pyproj import CRS

    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons

    rng = np.random.default_rng(7)
    ox, oy = 85000.0, 447000.0
    fps = [box(5, 5, 15, 13), box(15, 5, 25, 13),
           Polygon([(30, 5), (45, 5), (45, 10), (36, 10), (36, 20), (30, 20)])]
    heights = [9.0, 6.0, 12.0]
    xy = rng.uniform(0, 50, (25000, 2))
    z = np.zeros(len(xy))
    cls = np.full(len(xy), 2, dtype=np.uint8)
    import shapely
    for fp, h in zip(fps, heights, strict=True):
        inside = shapely.contains_xy(fp, xy[:, 0], xy[:, 1])
        z[inside] = h
        cls[inside] = 6
    z += rng.normal(0, 0.03, len(z))
    world = np.column_stack([xy + [ox, oy], z])
    cloud = PointCloud.from_world(world, crs=CRS.from_epsg(28992) if tile_crs else None,
                                  attributes={"classification": cls})
    las = tmp_path / "t.laz"
    write_points(las, cloud)
    gpkg = tmp_path / "f.gpkg"
    write_polygons(gpkg, fps, {"bag_id": ["A", "B", "C"]}, origin=(ox, oy), crs=CRS.from_epsg(28992))
    return las, gpkg, heights


def test_reconstruct_tile_without_crs_takes_the_footprints_crs(runner, tmp_path, caplog):
    """An AHN-like tile without a CRS, footprints in RD New, no --crs: the output
    carries the footprints' CRS (with a warning), not none."""
    from lidar2city.cli.main import cli

    las, gpkg, _ = _synthetic_inputs(tmp_path, tile_crs=False)
    out = tmp_path / "o.city.json"
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "taking the footprints'" in caplog.text
    assert json.loads(out.read_text())["metadata"]["referenceSystem"].endswith("/28992")


def _run_with_footprints(runner, tmp_path, fps, ids):
    """``reconstruct`` of the synthetic tile with footprints ``fps`` (local boxes) named
    ``ids``: the result and the model's CityObjects."""
    from pyproj import CRS

    from lidar2city.cli.main import cli
    from lidar2city.io.vector import write_polygons

    las, _, _ = _synthetic_inputs(tmp_path)
    src = tmp_path / "fp.gpkg"
    write_polygons(src, fps, {"bag_id": ids}, origin=(85000.0, 447000.0), crs=CRS.from_epsg(28992))
    out = tmp_path / "d.city.json"
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(src), "-o", str(out),
                              "--id-field", "bag_id"])
    assert res.exit_code == 0, res.output
    assert "3 of 3 buildings reconstructed" in res.output
    return json.loads(out.read_text())["CityObjects"]


def test_duplicate_footprints_are_modelled_with_a_warning(runner, tmp_path, caplog):
    """A footprint file holding some outlines twice: every footprint gets its model
    (ids made unique), and the run warns once that the models overlap."""
    objects = _run_with_footprints(runner, tmp_path, [box(5, 5, 15, 13), box(15, 5, 25, 13),
                                                      box(5, 5, 15, 13)], ["A", "B", "A"])
    assert "1 footprint(s) of" in caplog.text and "repeat an earlier one" in caplog.text
    assert {"A", "B", "A-2"} <= set(objects)
    assert "pair(s) of footprints" not in caplog.text  # exact repeats are said apart


def test_overlapping_footprints_are_modelled_with_a_warning(runner, tmp_path, caplog):
    """Footprints that overlap others (buffered outlines, two sources merged) were
    modelled in silence, each from the points of the overlap too; the run now says
    how many pairs overlap and by how much. Footprints sharing a wall do not count."""
    _run_with_footprints(runner, tmp_path, [box(5, 5, 15, 13), box(15, 5, 25, 13),
                                            box(12, 6, 18, 12)], ["A", "B", "C"])
    assert "2 pair(s) of footprints of" in caplog.text and "by up to 18.0 m2" in caplog.text


def test_reconstruct_formats(runner, tmp_path):
    from lidar2city.cli.main import cli

    las, gpkg, heights = _synthetic_inputs(tmp_path)
    out = tmp_path / "o.city.json"
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o", str(out),
                              "--id-field", "bag_id", "--lod", "1.2", "--lod", "1.3"])
    assert res.exit_code == 0, res.output
    assert "3 of 3 buildings reconstructed" in res.output
    doc = json.loads(out.read_text())
    b = {k: v for k, v in doc["CityObjects"].items() if v["type"] == "Building"}
    assert set(b) == {"A", "B", "C"}
    for k, h in zip("ABC", heights, strict=True):
        a = b[k]["attributes"]
        assert a["roof_height"] == pytest.approx(h, abs=0.1)
        assert abs(a["ground_height"]) < 0.1 and a["valid"] is True
    assert doc["metadata"]["referenceSystem"].endswith("/28992")
    assert doc["+lidar2city"]["configuration"]["lod1"]["lods"] == ["1.2", "1.3"]

    import pyogrio

    for name in ("o.city.jsonl", "o.obj", "o.gpkg"):
        res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg),
                                  "-o", str(tmp_path / name)])
        assert res.exit_code == 0, res.output
    layers = {row[0] for row in pyogrio.list_layers(tmp_path / "o.gpkg")}
    assert layers == {"footprints", "lod12"}
    meta, _, geom, fields = pyogrio.raw.read(tmp_path / "o.gpkg", layer="footprints")
    assert "roof_height" in list(meta["fields"]) and len(geom) == 3
    meta3, _, geom3, _ = pyogrio.raw.read(tmp_path / "o.gpkg", layer="lod12")
    assert meta3["geometry_type"] == "MultiPolygon Z" and len(geom3) == 3
    assert (tmp_path / "o.obj").read_text().count("\no ") == 3
    assert len((tmp_path / "o.city.jsonl").read_text().splitlines()) == 4


def test_reconstruct_errors(runner, tmp_path):
    from lidar2city.cli.main import cli

    las, gpkg, _ = _synthetic_inputs(tmp_path)
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(tmp_path / "none.gpkg"),
                              "-o", str(tmp_path / "o.city.json")])
    assert res.exit_code == 1 and "no such file" in res.output
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o",
                              str(tmp_path / "o.xyz")])
    assert res.exit_code == 1 and "--format" in res.output
    cfg = tmp_path / "c.toml"
    cfg.write_text("[lod1]\nroof_statistic = 140\n")
    res = runner.invoke(cli, ["reconstruct", str(las), "--footprints", str(gpkg), "-o",
                              str(tmp_path / "o.city.json"), "--config", str(cfg)])
    assert res.exit_code == 1 and "lod1.roof_statistic" in res.output


@pytest.mark.slow
def test_reconstruct_delft(runner, tmp_path, data):
    from lidar2city.cli.main import cli
    from lidar2city.tools.evaluate_model import evaluate_model
    from lidar2city.tools.validate import validate_file

    d = data / "delft"
    out = tmp_path / "delft.city.json"
    res = runner.invoke(cli, ["reconstruct", str(d / "ahn3_cropped_1.laz"), "--crs", "EPSG:7415",
                              "--footprints", str(d / "footprints_bgt.gpkg"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "132 of 132 buildings reconstructed" in res.output and "0 invalid" in res.output
    rep = validate_file(out, schema_dir=data / "cityjson" / "schemas-2.0.2")
    assert rep.valid and rep.schema_errors == [] and len(rep.objects) == 132
    kw = dict(crs="EPSG:7415", footprints=d / "footprints_bgt.gpkg", id_field="gml_id", check=False)
    _, ours = evaluate_model(out, [d / "ahn3_cropped_1.laz"], **kw)
    _, peer = evaluate_model(d / "peer_3dfier_lod1.city.json", [d / "ahn3_cropped_1.laz"], **kw)
    assert ours["measured"] == peer["measured"] == 132
    assert ours["rmse_median"] <= peer["rmse_median"]


def test_results_do_not_depend_on_tiling(tmp_path):
    """A building across a tile seam gets the same model from two tiles as from one."""
    import laspy

    from lidar2city.tools.reconstruct import reconstruct

    las, gpkg, _ = _synthetic_inputs(tmp_path)
    data = laspy.read(las)
    west = data.x < 85000.0 + 19.3  # the seam cuts building B (x 15..25)
    for name, mask in (("w.laz", west), ("e.laz", ~west)):
        part = laspy.LasData(data.header)
        part.points = data.points[mask]
        part.write(tmp_path / name)
    one = tmp_path / "one.city.json"
    two = tmp_path / "two.city.json"
    reconstruct([las], one, footprints=gpkg)
    reconstruct([tmp_path / "w.laz", tmp_path / "e.laz"], two, footprints=gpkg)
    a = json.loads(one.read_text())["CityObjects"]
    b = json.loads(two.read_text())["CityObjects"]
    assert set(a) == set(b)
    for k in a:
        for attr in ("roof_height", "ground_height", "point_count", "rmse_lod12"):
            assert a[k]["attributes"][attr] == b[k]["attributes"][attr]
