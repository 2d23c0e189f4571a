"""``lidar2city footprints``: synthetic tiles end to end, and bad input."""

from __future__ import annotations

import numpy as np
import pytest
import shapely


def _tile(path, *, classes=True, crs="EPSG:28992"):
    from lidar2city.crs import parse_crs
    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import write_points

    rng = np.random.default_rng(0)
    xx, yy = np.meshgrid(np.arange(0, 50, 0.3), np.arange(0, 40, 0.3))
    xy = np.column_stack([xx.ravel(), yy.ravel()]) + rng.uniform(-0.1, 0.1, (xx.size, 2))
    house = shapely.Polygon([(5, 5), (30, 5), (30, 15), (18, 15), (18, 32), (5, 32)])
    inside = shapely.contains_xy(house, xy[:, 0], xy[:, 1])
    world = np.column_stack([xy + [85000.0, 447000.0], np.where(inside, 9.0, 0.5)])
    cls = np.where(inside, 6, 2) if classes else np.ones(len(xy))
    cloud = PointCloud.from_world(world, crs=parse_crs(crs) if crs else None,
                                  attributes={"classification": cls.astype(np.uint8)})
    write_points(path, cloud)
    return shapely.affinity.translate(house, 85000.0, 447000.0)


def test_footprints_writes_a_geopackage(runner, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    house = _tile(tmp_path / "t.laz")
    out = tmp_path / "fp.gpkg"
    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "1 footprints" in res.output
    fp, crs = read_footprints(out)
    assert crs.to_epsg() == 28992
    assert len(fp) == 1
    g = fp.geometries[0]
    assert g.intersection(house).area / g.union(house).area > 0.95
    for name in ("area", "direction", "n_vertices", "type_iv", "mean_deviation", "n_points"):
        assert name in fp.attributes
    assert fp.attributes["area"][0] == pytest.approx(g.area, rel=1e-6)
    assert fp.attributes["n_points"][0] > 4000
    assert fp.attributes["status"][0] == "ok"


def test_footprints_config_file_and_options(runner, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    _tile(tmp_path / "t.laz")
    (tmp_path / "run.toml").write_text("[footprints]\nedge_offset = -0.5\n\n[ground]\ncell = 1.0\n")
    out = tmp_path / "fp.gpkg"
    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(out),
                              "--config", str(tmp_path / "run.toml"), "--min-area", "10"])
    assert res.exit_code == 0, res.output
    shrunk = read_footprints(out)[0].attributes["area"][0]
    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(out)])
    full = read_footprints(out)[0].attributes["area"][0]
    assert full - shrunk == pytest.approx(0.5 * 2 * (25 + 27), rel=0.1)


def test_footprints_bad_input(runner, tmp_path):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["footprints", str(tmp_path / "none.laz"), "-o", str(tmp_path / "o.gpkg")])
    assert res.exit_code == 1
    assert res.output.startswith("Error:") and len(res.output.strip().splitlines()) == 1

    (tmp_path / "bad.toml").write_text("[footprints]\ncell = -2\n")
    _tile(tmp_path / "t.laz")
    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(tmp_path / "o.gpkg"),
                              "--config", str(tmp_path / "bad.toml")])
    assert res.exit_code == 1 and "footprints.cell" in res.output

    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(tmp_path / "o.gpkg"),
                              "--regularize", "magic"])
    assert res.exit_code == 2
    assert not (tmp_path / "o.gpkg").exists()


def test_cli_choices_are_the_regularizers():
    from lidar2city.cli.footprints import REGULARIZER_NAMES
    from lidar2city.footprints import REGULARIZERS

    assert set(REGULARIZER_NAMES) == set(REGULARIZERS)


def test_footprints_metadata_holds_the_resolved_config(runner, tmp_path):
    import json

    import pyogrio

    from lidar2city.cli.main import cli

    _tile(tmp_path / "t.laz")
    out = tmp_path / "fp.gpkg"
    assert runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(out)]).exit_code == 0
    meta = pyogrio.read_info(out)["dataset_metadata"]
    assert json.loads(meta["lidar2city_config"])["footprints"]["regularize"] == "none"
    resolved = json.loads(meta["lidar2city_footprints_resolved"])
    assert resolved["point_spacing"] == pytest.approx(0.3, rel=0.05)
    assert resolved["cell"] == pytest.approx(1.5 * resolved["point_spacing"], rel=1e-3)


def test_footprints_fit_regulariser_on_points(runner, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    house = _tile(tmp_path / "t.laz")
    out = tmp_path / "fp.gpkg"
    res = runner.invoke(cli, ["footprints", str(tmp_path / "t.laz"), "-o", str(out),
                              "--regularize", "fit"])
    assert res.exit_code == 0, res.output
    fp, _ = read_footprints(out)
    (g,) = fp.geometries
    assert fp.attributes["status"][0] == "ok"
    assert fp.attributes["n_vertices"][0] == 6  # the L as a union of two rectangles
    assert g.intersection(house).area / g.union(house).area > 0.95


def test_footprints_from_a_raw_tile(runner, tmp_path):
    """Without a building class the points are ground-filtered and classified first."""
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints

    house = _tile(tmp_path / "u.laz", classes=False)
    out = tmp_path / "o.gpkg"
    res = runner.invoke(cli, ["footprints", str(tmp_path / "u.laz"), "-o", str(out)])
    assert res.exit_code == 0, res.output
    fps, _ = read_footprints(out)
    (g,) = [g for g in fps.geometries if g is not None]  # world coordinates (origin 0)
    assert g.intersection(house).area / g.union(house).area > 0.9
