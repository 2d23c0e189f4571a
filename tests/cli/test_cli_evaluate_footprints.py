"""``lidar2city evaluate footprints``: exact scores on constructed polygons, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely


def _write(path, polys, crs="EPSG:28992", origin=(85000.0, 447000.0)):
    from lidar2city.crs import parse_crs
    from lidar2city.io.vector import write_polygons

    write_polygons(path, polys, {"name": [f"p{i}" for i in range(len(polys))]},
                   origin=np.array(origin), crs=parse_crs(crs))


def test_evaluate_footprints_scores(runner, tmp_path):
    from lidar2city.cli.main import cli

    ref = [shapely.box(0, 0, 10, 10), shapely.box(20, 0, 30, 10)]
    pred = [shapely.box(1, 0, 11, 10), shapely.box(40, 40, 45, 45)]  # one shifted 1 m, one false
    _write(tmp_path / "ref.gpkg", ref)
    _write(tmp_path / "pred.gpkg", pred)
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "pred.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg"), "--json"])
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    a, o = rep["area"], rep["objects"]
    assert a["completeness"] == pytest.approx(90 / 200)
    assert a["correctness"] == pytest.approx(90 / 125)
    assert a["quality"] == pytest.approx(90 / 235)
    assert o["matched"] == 1 and o["precision"] == 0.5 and o["recall"] == 0.5
    assert o["mean_iou"] == pytest.approx(90 / 110)
    assert o["hausdorff_mean"] == pytest.approx(1.0)
    assert rep["alignment"]["aligned_share"] == pytest.approx(1.0)

    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "pred.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg")])
    assert res.exit_code == 0, res.output
    assert "quality 0.383" in res.output and "precision 0.500" in res.output


def test_evaluate_reprojects_the_prediction(runner, tmp_path):
    from pyproj import Transformer

    from lidar2city.cli.main import cli

    ref = [shapely.box(0, 0, 20, 20)]
    _write(tmp_path / "ref.gpkg", ref)
    tr = Transformer.from_crs("EPSG:28992", "EPSG:32631", always_xy=True)
    world = shapely.transform(shapely.box(85000, 447000, 85020, 447020).segmentize(1.0),
                              lambda c: np.column_stack(tr.transform(c[:, 0], c[:, 1])))
    _write(tmp_path / "pred.gpkg", [world], crs="EPSG:32631", origin=(0.0, 0.0))
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "pred.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg"), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["area"]["quality"] > 0.999


def test_evaluate_protocol_leaves_out_cut_blocks(tmp_path):
    from lidar2city.tools.evaluate import evaluate_footprints

    ref = [shapely.box(10, 10, 20, 20), shapely.box(50, 10, 60, 20)]
    # a block reaching the data's edge at x = 100 (its reference is missing there) and a good one
    pred = [shapely.box(10, 10, 20, 20), shapely.box(50, 10, 100, 20), shapely.box(70, 70, 75, 75)]
    _write(tmp_path / "ref.gpkg", ref)
    _write(tmp_path / "pred.gpkg", pred)
    ext = (85000.0, 447000.0, 85100.0, 447100.0)
    rep = evaluate_footprints(tmp_path / "pred.gpkg", tmp_path / "ref.gpkg", extent=ext)
    p = rep["protocol"]
    assert p["pred_cut"] == 1 and p["ref_cut"] == 1
    # the false positive far from everything still counts
    assert rep["area"]["correctness"] == pytest.approx(100 / 125)
    rep = evaluate_footprints(tmp_path / "pred.gpkg", tmp_path / "ref.gpkg", extent=ext,
                              hull_margin=2.0)
    assert rep["area"]["quality"] == pytest.approx(1.0)


def test_evaluate_footprints_bad_input(runner, tmp_path):
    from lidar2city.cli.main import cli

    _write(tmp_path / "ref.gpkg", [shapely.box(0, 0, 10, 10)])
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "none.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg")])
    assert res.exit_code == 1
    assert res.output.startswith("Error:") and len(res.output.strip().splitlines()) == 1
    (tmp_path / "junk.gpkg").write_text("not a geopackage")
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "junk.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg")])
    assert res.exit_code == 1 and res.output.startswith("Error:")
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "ref.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg"), "--extent", "1,2,3"])
    assert res.exit_code == 2
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "ref.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg"), "--min-iou", "0"])
    assert res.exit_code == 1 and "min_iou" in res.output


def test_evaluate_footprints_that_do_not_overlap_the_reference(runner, tmp_path):
    """A prediction 5 km off its reference (another area, or a CRS mix-up without CRSs)
    scored quality 0.000 with exit 0, and 'overall accuracy 1.000' over the empty
    pixels: say they do not overlap instead."""
    from lidar2city.cli.main import cli

    _write(tmp_path / "ref.gpkg", [shapely.box(0, 0, 10, 10), shapely.box(20, 0, 30, 10)])
    _write(tmp_path / "pred.gpkg", [shapely.box(5000, 0, 5010, 10)])
    res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "pred.gpkg"),
                              "--reference", str(tmp_path / "ref.gpkg")])
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and "do not overlap" in lines[0]
