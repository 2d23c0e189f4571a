"""``lidar2city evaluate corners``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lidar2city.fit.primitives import GablePrimitive


def write_cityjson(path, solids: dict, *, scale=0.001, translate=(84000.0, 447000.0, 0.0)):
    """A minimal CityJSON 2.0 file with one Solid per building (integer vertices + transform)."""
    verts, objects = [], {}
    t = np.asarray(translate)
    for bid, solid in solids.items():
        off = len(verts)
        q = np.round((solid.vertices - t) / scale).astype(int)
        verts.extend(q.tolist())
        shells = [[[int(i) + off for i in ring] for ring in s.rings] for s in solid.surfaces]
        objects[bid] = {"type": "Building",
                        "geometry": [{"type": "Solid", "lod": "2.2", "boundaries": [shells]}]}
    doc = {"type": "CityJSON", "version": "2.0",
           "transform": {"scale": [scale] * 3, "translate": list(translate)},
           "CityObjects": objects, "vertices": verts}
    path.write_text(json.dumps(doc), encoding="utf-8")


def gable(dx=0.0, dz=0.0):
    return GablePrimitive({"x": 84010.0 + dx, "y": 447020.0, "z": 1.0 + dz, "azimuth": 20.0,
                           "length": 12.0, "width": 7.0, "height": 5.0, "roof_height": 3.0}).to_solid()


@pytest.fixture
def files(tmp_path):
    ref, pred = tmp_path / "ref.city.json", tmp_path / "pred.city.json"
    write_cityjson(ref, {"A": gable(), "B": gable(dx=30.0)})
    write_cityjson(pred, {"A": gable(dx=0.05, dz=-0.1), "B": gable(dx=30.0)})
    return pred, ref


def test_evaluate_corners_json(runner, files):
    from lidar2city.cli.main import cli

    pred, ref = files
    res = runner.invoke(cli, ["evaluate", "corners", str(pred), "--reference", str(ref), "--json"])
    assert res.exit_code == 0, res.output
    m = json.loads(res.output)
    assert m["n_reference"] == 20 and m["n_matched"] == 20
    assert m["completeness"] == 1.0 and m["correctness"] == 1.0
    assert m["mean_x"] == pytest.approx(0.025, abs=1e-6)
    assert m["rmse_z"] == pytest.approx(np.sqrt(0.5) * 0.1, abs=1e-6)


def test_evaluate_corners_text_and_obj_reference(runner, files, tmp_path):
    from lidar2city.cli.main import cli

    pred, _ = files
    obj = tmp_path / "ref.obj"
    lines = []
    n = 0
    for name, solid in (("A", gable()), ("B", gable(dx=30.0))):
        lines.append(f"o {name}")
        lines += [f"v {x:.3f} {y:.3f} {z:.3f}" for x, y, z in solid.vertices]
        for s in solid.surfaces:
            lines.append("f " + " ".join(str(n + int(i) + 1) for i in s.rings[0]))
        n += len(solid.vertices)
    obj.write_text("\n".join(lines) + "\n", encoding="utf-8")
    res = runner.invoke(cli, ["evaluate", "corners", str(pred), "-r", str(obj), "--per-building"])
    assert res.exit_code == 0, res.output
    assert "completeness  100.0 %" in res.output
    assert "A ~ A: 10/10" in res.output


def test_evaluate_corners_overlap_matching(runner, files, tmp_path):
    from lidar2city.cli.main import cli

    _, ref = files
    other = tmp_path / "other.city.json"
    write_cityjson(other, {"x1": gable(dx=30.0), "x2": gable()})
    res = runner.invoke(cli, ["evaluate", "corners", str(other), "-r", str(ref), "--json"])
    m = json.loads(res.output)
    assert m["buildings_paired"] == 2 and m["completeness"] == 1.0


@pytest.mark.parametrize("content,msg", [("{not json", "not JSON"), ('{"type": "Feature"}', "not a CityJSON")])
def test_evaluate_corners_bad_input_one_line_error(runner, files, tmp_path, content, msg):
    from lidar2city.cli.main import cli

    pred, _ = files
    bad = tmp_path / "bad.city.json"
    bad.write_text(content, encoding="utf-8")
    res = runner.invoke(cli, ["evaluate", "corners", str(pred), "-r", str(bad)])
    assert res.exit_code == 1
    assert res.output.strip().startswith("Error:") and msg in res.output
    assert len(res.output.strip().splitlines()) == 1


def test_evaluate_corners_missing_file(runner, files, tmp_path):
    from lidar2city.cli.main import cli

    pred, _ = files
    res = runner.invoke(cli, ["evaluate", "corners", str(pred), "-r", str(tmp_path / "none.city.json")])
    assert res.exit_code == 1 and "no such file" in res.output


def test_read_corners_of_the_3dbag_sample(data):
    from lidar2city.io.corners import read_corners

    corners = read_corners(data / "cityjson" / "multi_lod.city.json", lod="2.2")
    assert len(corners) == 10
    for c in corners.values():
        assert c.shape[1] == 3 and len(c) >= 8
        # RD New metres: the transform is applied
        assert 0 < c[:, 0].mean() < 300000 and 300000 < c[:, 1].mean() < 625000


def test_evaluate_corners_of_models_that_do_not_overlap(runner, tmp_path):
    """The same building ids in another area (or CRS: Delft in EPSG:7415 against the same
    buildings in EPSG:2263) printed 0 matched, 'mean X +nan' and exit 0: an error now."""
    from lidar2city.cli.main import cli

    ref, pred = tmp_path / "ref.city.json", tmp_path / "pred.city.json"
    write_cityjson(ref, {"A": gable(), "B": gable(dx=30.0)})
    write_cityjson(pred, {"A": gable(dx=5000.0), "B": gable(dx=5030.0)})
    res = runner.invoke(cli, ["evaluate", "corners", str(pred), "--reference", str(ref)])
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and "do not overlap" in lines[0]
