"""The primitives tool (one model per footprint), the primitives file reader, check images."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from test_fit_primitives import solid_problems  # noqa: E402  (same folder)

from lidar2city.datamodel import Footprints, PointCloud
from lidar2city.errors import FileFormatError, InputError
from lidar2city.fit.synthetic_primitives import synthetic_scene
from lidar2city.io.primitives import read_primitives
from lidar2city.tools.primitives import reconstruct_primitives, write_check_images


@pytest.fixture(scope="module")
def scene():
    return synthetic_scene(6, seed=21)


def test_reconstruct_every_building_with_attributes(scene):
    calls = []
    res = reconstruct_primitives(scene.cloud(), scene.footprint_set(), progress=calls.append)
    assert len(res) == 6 and calls == [1] * 6
    for r, truth in zip(res, scene.truth, strict=True):
        assert r.ok, r.reason
        assert r.attributes["primitive"] == truth.kind
        assert r.attributes["primitive_choice"] == "auto"
        assert solid_problems(r.solids["2.2"]) == []
        for k in ("primitive_x", "primitive_x_std", "primitive_height", "primitive_height_std",
                  "primitive_residual_rmse", "primitive_iterations"):
            assert k in r.attributes, k
        assert r.attributes["primitive_height"] == pytest.approx(truth.params["height"], abs=0.1)
    # the roof outline in the LiDAR refined most plans
    assert sum(r.attributes["primitive_n_outline"] > 0 for r in res) >= 4


def test_batch_survives_a_bad_footprint(scene):
    fps = scene.footprint_set()
    far = shapely.box(5000, 5000, 5010, 5010)
    bad = Footprints(fps.geometries[:2] + [far, None], fps.ids[:2] + ["far", "none"])
    res = reconstruct_primitives(scene.cloud(), bad)
    assert [r.ok for r in res] == [True, True, False, False]
    assert res[2].reason and res[3].reason


def test_world_coordinates_in_attributes(scene):
    origin = np.array([84000.0, 447000.0, 0.0])
    cloud = PointCloud(scene.points, origin=origin,
                       attributes={"classification": scene.classification})
    res = reconstruct_primitives(cloud, Footprints(scene.footprints[:1], scene.ids[:1]))
    assert res[0].attributes["primitive_x"] == pytest.approx(origin[0] + scene.truth[0].params["x"], abs=0.2)


def test_user_primitive_and_approximate_pose(scene):
    i = next(k for k, t in enumerate(scene.truth) if t.kind == "gable")
    fid = scene.ids[i]
    t = scene.truth[i].params
    one = Footprints([scene.footprints[i]], [fid])
    user = {fid: {"primitive": "gable", "azimuth": t["azimuth"] + 3.0, "height": t["height"] + 0.5}}
    r = reconstruct_primitives(scene.cloud(), one, user_primitives=user)[0]
    assert r.ok and r.attributes["primitive_choice"] == "user"
    assert r.attributes["primitive_roof_height"] == pytest.approx(t["roof_height"], abs=0.1)
    forced = reconstruct_primitives(scene.cloud(), one, user_primitives={fid: {"primitive": "box"}})
    assert forced[0].attributes["primitive"] == "box"
    with pytest.raises(InputError, match="pyramid"):
        reconstruct_primitives(scene.cloud(), scene.footprint_set(),
                               user_primitives={fid: {"primitive": "pyramid"}})


def test_datum_from_a_dtm(scene):
    from affine import Affine

    from lidar2city.io.raster import Raster

    dtm = Raster(np.full((200, 200), -3.0), Affine(1.0, 0, -20.0, 0, -1.0, 180.0))
    res = reconstruct_primitives(scene.cloud(), Footprints(scene.footprints[:2], scene.ids[:2]), dtm=dtm)
    assert all(r.ok for r in res)
    assert res[0].attributes["primitive_z"] == pytest.approx(-3.0)


def test_without_classification_uses_all_points(scene):
    cloud = PointCloud(scene.points)
    res = reconstruct_primitives(cloud, Footprints(scene.footprints[:3], scene.ids[:3]))
    assert all(r.ok for r in res)
    for r, t in zip(res, scene.truth[:3], strict=True):
        # datum from a low percentile of the surroundings: within a few noise sigmas
        assert r.attributes["primitive_z"] == pytest.approx(0.0, abs=0.15)
        assert r.attributes["primitive"] == t.kind


def test_check_images(scene, tmp_path):
    pytest.importorskip("matplotlib")
    res = reconstruct_primitives(scene.cloud(), Footprints(scene.footprints[:2], scene.ids[:2]))
    paths = write_check_images(tmp_path, scene.cloud(), res)
    assert len(paths) == 2
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_check_image_over_an_orthoimage(scene, tmp_path):
    pytest.importorskip("matplotlib")
    from affine import Affine

    from lidar2city.io.raster import Raster

    ortho = Raster(np.random.default_rng(0).integers(0, 255, (3, 120, 120)).astype(np.uint8),
                   Affine(0.5, 0, 0.0, 0, -0.5, 60.0))
    res = reconstruct_primitives(scene.cloud(), Footprints(scene.footprints[:1], scene.ids[:1]))
    paths = write_check_images(tmp_path, scene.cloud(), res, ortho=ortho)
    assert paths[0].stat().st_size > 1000


# ---------------------------------------------------------------------------
# primitives files


def test_read_primitives_csv_and_toml(tmp_path):
    csv = tmp_path / "p.csv"
    csv.write_text("id,primitive,azimuth,height,note\nA,gable,30,6.5,x\nB,box,,,\n", encoding="utf-8")
    got = read_primitives(csv)
    assert got == {"A": {"primitive": "gable", "azimuth": 30.0, "height": 6.5}, "B": {"primitive": "box"}}
    toml = tmp_path / "p.toml"
    toml.write_text('[[building]]\nid = "A"\nprimitive = "hip"\nhip_length = 3.0\n\n'
                    '[buildings.C]\nprimitive = "shed"\nroof_height = 1.5\n', encoding="utf-8")
    got = read_primitives(toml)
    assert got["A"] == {"primitive": "hip", "hip_length": 3.0}
    assert got["C"] == {"primitive": "shed", "roof_height": 1.5}


def test_read_primitives_gpkg_points(tmp_path):
    import pyogrio

    path = tmp_path / "p.gpkg"
    geoms = np.array([shapely.to_wkb(shapely.Point(10.0, 20.0))], dtype=object)
    pyogrio.raw.write(str(path), geoms, [np.array(["A"], dtype=object), np.array(["gable"], dtype=object),
                                         np.array([12.0])],
                      ["identificatie", "primitive", "length"], geometry_type="Point", crs="EPSG:28992",
                      driver="GPKG")
    got = read_primitives(path)
    assert got == {"A": {"primitive": "gable", "x": 10.0, "y": 20.0, "length": 12.0}}


@pytest.mark.parametrize("text,match", [
    ("id,primitive,height\nA,gable,high\n", "not a number"),
    ("id,height\nA,3\n", "primitive"),
    ("primitive\ngable\n", "id field"),
    ("id,primitive\nA,box\nA,gable\n", "twice"),
    ("id,primitive,width\nA,box,-2\n", "> 0"),
])
def test_read_primitives_errors(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(InputError, match=match):
        read_primitives(p)


def test_read_primitives_missing_file(tmp_path):
    with pytest.raises(FileFormatError):
        read_primitives(tmp_path / "none.csv")


# ---------------------------------------------------------------------------
# real data


@pytest.mark.slow
def test_delft_row_houses(data):
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints

    cloud = read_points([data / "delft" / "ahn3_cropped_1.laz"], crs="EPSG:7415")
    fps, _ = read_footprints(data / "delft" / "footprints_bgt.gpkg", origin=cloud.origin[:2],
                             xy_unit=cloud.xy_unit, target_crs=cloud.crs)
    sub = Footprints(fps.geometries[:20], fps.ids[:20])
    res = reconstruct_primitives(cloud, sub)
    assert all(r.ok for r in res), [(r.id, r.reason) for r in res if not r.ok]
    kinds = {r.attributes["primitive"] for r in res}
    assert kinds & {"gable", "prism_gable"}  # steep gable roofs are found
    for r in res:
        assert solid_problems(r.solids["2.2"]) == [], r.id
        assert r.attributes["primitive_residual_rmse"] < 1.0
