"""``lidar2city footprints --dsm`` and ``lidar2city reconstruct --dsm``: synthetic rasters, errors, Alexandria."""

from __future__ import annotations

import json

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

CRS_UTM = CRS.from_epsg(26918)
T = Affine(1.0, 0.0, 500000.0, 0.0, -1.0, 4300000.0)


@pytest.fixture
def rasters(tmp_path):
    """A 1 m DSM/DTM pair: ground at 20 m, a 30 x 16 m box 9 m high, an L 6 m high."""
    from lidar2city.io.raster import Raster, write_raster

    h, w = 90, 110
    dsm = np.full((h, w), 20.0)
    dsm[10:26, 10:40] = 29.0
    dsm[40:80, 60:75] = 26.0
    dsm[65:80, 75:100] = 26.0
    dtm = np.full((h, w), 20.0)
    p_dsm, p_dtm = tmp_path / "dsm.tif", tmp_path / "dtm.tif"
    write_raster(p_dsm, Raster(dsm, T, CRS_UTM, np.isfinite(dsm)))
    write_raster(p_dtm, Raster(dtm, T, CRS_UTM, np.isfinite(dtm)))
    return p_dsm, p_dtm


def test_footprints_dsm(runner, rasters, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.raster import read_raster
    from lidar2city.io.vector import read_footprints

    p_dsm, p_dtm = rasters
    out, fig, dtm_out = tmp_path / "fp.gpkg", tmp_path / "fig.png", tmp_path / "dtm_out.tif"
    res = runner.invoke(cli, ["footprints", "--dsm", str(p_dsm), "--dtm", str(p_dtm), "-o", str(out),
                              "--figure", str(fig), "--dtm-out", str(dtm_out)])
    assert res.exit_code == 0, res.output
    assert "2 footprints (1 composite, 1 rectangle), 0 failed" in res.output
    fp, crs = read_footprints(out)
    assert crs.equals(CRS_UTM)
    assert sorted(fp.attributes["shape_type"]) == ["composite", "rectangle"]
    assert sorted(np.round(fp.attributes["height"], 2)) == [6.0, 9.0]
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert np.allclose(read_raster(dtm_out).array, 20.0)
    # the DTM built from the DSM, raw pixel outlines, and a config file
    (tmp_path / "run.toml").write_text("[dsm_roofs]\nmin_area = 500.0\n")
    res = runner.invoke(cli, ["footprints", "--dsm", str(p_dsm), "-o", str(out),
                              "--regularize", "none", "--config", str(tmp_path / "run.toml")])
    assert res.exit_code == 0, res.output
    assert "1 footprints (1 pixels)" in res.output  # the 480 m2 box is below min_area, the L is not
    assert "DTM built from the DSM" in res.output


@pytest.mark.parametrize("args, message", [
    (["-o", "x.gpkg"], "give point-cloud INPUTS or --dsm"),
    (["--dsm", "D", "--regularize", "snake", "-o", "x.gpkg"], "--regularize snake works on point clouds"),
    (["t.laz", "--dsm", "D", "-o", "x.gpkg"], "not both"),
    (["t.laz", "--dtm", "D", "-o", "x.gpkg"], "--dtm needs --dsm"),
    (["t.laz", "--figure", "f.png", "-o", "x.gpkg"], "--figure needs --dsm"),
    (["--dsm", "D", "--cell", "1", "-o", "x.gpkg"], "--cell applies to point clouds"),
])
def test_footprints_dsm_wrong_combinations(runner, tmp_path, args, message):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["footprints", *args])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.strip().splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("Error:") and message in lines[0], res.output


def test_dsm_choices_are_the_dsm_regularizers():
    from lidar2city.cli.footprints import DSM_REGULARIZER_NAMES
    from lidar2city.tools.dsm import REGULARIZERS

    # the polygon-fitting outlines, plus the active contours (their own tool)
    assert set(DSM_REGULARIZER_NAMES) == set(REGULARIZERS) | {"active-contour"}


def test_footprints_dsm_active_contour(runner, tmp_path, data):
    import pyogrio

    from lidar2city.cli.main import cli

    a = data / "alexandria"
    out = tmp_path / "ac.gpkg"
    res = runner.invoke(cli, ["footprints", "--dsm", str(a / "dsm_west.tif"), "--dtm",
                              str(a / "dtm_west.tif"), "--regularize", "active-contour", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert pyogrio.read_info(out)["features"] > 50
    res = runner.invoke(cli, ["footprints", "--dsm", str(a / "dsm_west.tif"), "--weights", "w.toml",
                              "-o", str(out)])
    assert res.exit_code == 1 and "--weights goes with" in res.output


def test_reconstruct_dsm(runner, rasters, tmp_path):
    import pyogrio
    import shapely

    from lidar2city.cli.main import cli
    from lidar2city.io.vector import write_polygons
    from lidar2city.tools.validate import validate_file

    p_dsm, p_dtm = rasters
    out = tmp_path / "o.city.json"
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(p_dsm), "--dtm", str(p_dtm), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "2 of 2 buildings reconstructed (LoD 1.2), 0 failed" in res.output
    doc = json.loads(out.read_text())
    assert doc["metadata"]["referenceSystem"].endswith("/26918")
    tops = []
    for obj in doc["CityObjects"].values():
        assert obj["type"] == "Building" and obj["geometry"][0]["lod"] == "1.2"
        a = obj["attributes"]
        assert a["ground_z"] == pytest.approx(20.0) and a["shape_type"] in ("rectangle", "composite")
        tops.append(round(a["roof_z"] - a["ground_z"], 2))
    assert sorted(tops) == [6.0, 9.0]
    rep = validate_file(out, schema=False)
    assert rep.objects and all(o.valid for o in rep.objects)
    # given footprints (another CRS: reprojected), OBJ and GPKG by extension
    fp = tmp_path / "given.gpkg"
    box = shapely.box(500010, 4299974, 500040, 4299990)
    write_polygons(fp, [box], {"id": ["A"]}, origin=(0, 0), crs=CRS_UTM)
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(p_dsm), "--dtm", str(p_dtm), "--footprints",
                              str(fp), "-o", str(tmp_path / "o.gpkg")])
    assert res.exit_code == 0, res.output
    assert "1 of 1 buildings" in res.output
    layers = [name for name, _ in pyogrio.list_layers(tmp_path / "o.gpkg")]
    assert layers[0] == "footprints" and len(layers) == 2, layers
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(p_dsm), "-o", str(tmp_path / "o.obj")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "o.obj").read_text().count("\nv ") >= 16


@pytest.mark.parametrize("args, message", [
    (["--dsm", "D", "--lod", "2.2", "-o", "x.city.json"], "LoD1.2 only"),
    (["--dsm", "D", "--crs", "EPSG:4326", "-o", "x.city.json"], "--crs does not apply"),
    (["-o", "x.city.json"], "give point-cloud INPUTS or --dsm"),
    (["t.laz", "--dsm", "D", "-o", "x.city.json"], "not both"),
    (["t.laz", "--ortho", "o.tif", "-o", "x.city.json"], "--ortho needs --dsm"),
])
def test_reconstruct_dsm_wrong_combinations(runner, args, message):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["reconstruct", *args])
    assert res.exit_code == 1
    lines = [ln for ln in res.output.strip().splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("Error:") and message in lines[0], res.output


@pytest.mark.slow
def test_dsm_commands_on_alexandria(runner, data, tmp_path):
    """Both commands on the shared Alexandria rasters (figures: benchmarks/bench_dsm_fit.py)."""
    from lidar2city.cli.main import cli
    from lidar2city.io.vector import read_footprints
    from lidar2city.tools.validate import validate_file

    a = data / "alexandria"
    out = tmp_path / "fp.gpkg"
    res = runner.invoke(cli, ["footprints", "--dsm", str(a / "dsm_west.tif"), "--dtm",
                              str(a / "dtm_west.tif"), "-o", str(out), "--figure",
                              str(tmp_path / "f.png")])
    assert res.exit_code == 0, res.output
    fp, crs = read_footprints(out)
    assert crs.to_epsg() == 26918 and len(fp) > 100
    assert set(fp.attributes["shape_type"]) <= {"rectangle", "right_trapezoid", "trapezoid",
                                                "composite", "polygon", ""}
    city = tmp_path / "a.city.json"
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(a / "dsm_west.tif"), "--dtm",
                              str(a / "dtm_west.tif"), "--footprints",
                              str(a / "footprints_west.gpkg"), "-o", str(city)])
    assert res.exit_code == 0, res.output
    assert "56 of 56 buildings reconstructed" in res.output
    rep = validate_file(city, schema_dir=data / "cityjson" / "schemas-2.0.2")
    assert rep.schema_errors == [] and len(rep.objects) == 56
    assert all(o.valid for o in rep.objects)


@pytest.mark.parametrize("case", ["no_crs", "all_nodata", "dtm_grid", "dtm_no_crs"])
@pytest.mark.parametrize("command", ["footprints", "tune"])
def test_bad_rasters_one_line_error(runner, rasters, tmp_path, case, command):
    from lidar2city.cli.main import cli
    from lidar2city.io.raster import Raster, read_raster, write_raster
    from lidar2city.io.vector import write_polygons

    p_dsm, p_dtm = rasters
    d = read_raster(p_dsm)
    bad = tmp_path / "bad.tif"
    if case in ("no_crs", "dtm_no_crs"):
        write_raster(bad, Raster(d.array, d.transform, None, d.mask))
    elif case == "all_nodata":
        write_raster(bad, Raster(np.full(d.shape, np.nan), d.transform, d.crs))
    else:
        write_raster(bad, Raster(d.array[1:, 1:], d.transform, d.crs))
    dsm, dtm = (p_dsm, bad) if case.startswith("dtm") else (bad, p_dtm)
    out = tmp_path / ("out.gpkg" if command == "footprints" else "w.toml")
    args = [command, "--dsm", str(dsm), "--dtm", str(dtm), "-o", str(out)]
    if command == "tune":
        import shapely

        ref = tmp_path / "ref.gpkg"
        write_polygons(ref, [shapely.box(500010, 4299974, 500040, 4299990)], {"id": ["a"]},
                       origin=(0.0, 0.0), crs=CRS_UTM)
        args += ["--reference", str(ref), "--population", "4", "--generations", "0"]
    res = runner.invoke(cli, args)
    assert res.exit_code != 0
    assert res.output.strip().startswith("Error:") and len(res.output.strip().splitlines()) == 1, \
        res.output
    assert not out.exists()


def test_reconstruct_dsm_with_footprints_of_another_area(runner, rasters, tmp_path):
    """Footprints of another area (Delft's on Alexandria's DSM) gave '0 of 78 buildings
    reconstructed, 78 failed: no valid DSM/DTM pixel inside the outline' and exit 0; the
    points path says none of them meets the extent, and so does the DSM path now. A
    footprint partly outside keeps its own reason."""
    import shapely

    from lidar2city.cli.main import cli
    from lidar2city.io.vector import write_polygons

    p_dsm, p_dtm = rasters
    far = tmp_path / "far.gpkg"
    write_polygons(far, [shapely.box(600010, 4299974, 600040, 4299990)], {"id": ["A"]},
                   origin=(0, 0), crs=CRS_UTM)
    out = tmp_path / "o.city.json"
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(p_dsm), "--dtm", str(p_dtm),
                              "--footprints", str(far), "-o", str(out)])
    assert res.exit_code == 1 and not out.exists(), res.output
    assert res.output.startswith("Error:") and "meets the DSM's extent" in res.output
    both = tmp_path / "both.gpkg"
    write_polygons(both, [shapely.box(500010, 4299974, 500040, 4299990),
                          shapely.box(600010, 4299974, 600040, 4299990)], {"id": ["A", "B"]},
                   origin=(0, 0), crs=CRS_UTM)
    res = runner.invoke(cli, ["reconstruct", "--dsm", str(p_dsm), "--dtm", str(p_dtm),
                              "--footprints", str(both), "-o", str(out)])
    assert res.exit_code == 0 and "1 of 2 buildings reconstructed" in res.output, res.output


def test_dsm_with_sentinel_values_under_another_nodata(runner, rasters, tmp_path, caplog):
    """A float DSM whose nodata is NaN but whose gaps hold -9999 (two tools' conventions
    mixed): the -9999 pixels were heights, and a building over them failed with
    `height -9999.28 m is not above the terrain` (Delft's DSM so rewritten: 8 of 132).
    Values below -2000 (lower than any land) are no data now, with a warning."""
    import logging

    import rasterio
    import shapely

    from lidar2city.cli.main import cli
    from lidar2city.io.vector import write_polygons

    p_dsm, p_dtm = rasters
    with rasterio.open(p_dsm) as src:
        a, profile = src.read(1), src.profile
    a[10:20, 10:40] = -9999.0  # most of the 9 m box
    a[0, 0] = np.nan
    profile.update(nodata=np.nan)
    bad = tmp_path / "mixed.tif"
    with rasterio.open(bad, "w", **profile) as dst:
        dst.write(a, 1)
    fp = tmp_path / "given.gpkg"
    write_polygons(fp, [shapely.box(500010, 4299974, 500040, 4299990)], {"id": ["A"]},
                   origin=(0, 0), crs=CRS_UTM)
    out = tmp_path / "o.city.json"
    with caplog.at_level(logging.WARNING):
        res = runner.invoke(cli, ["reconstruct", "--dsm", str(bad), "--dtm", str(p_dtm),
                                  "--footprints", str(fp), "-o", str(out)])
    assert res.exit_code == 0 and "1 of 1 buildings" in res.output, res.output
    assert "300 pixel(s) below -2000" in caplog.text, caplog.text
    a = next(iter(json.loads(out.read_text())["CityObjects"].values()))["attributes"]
    assert a["roof_z"] - a["ground_z"] == pytest.approx(9.0)


@pytest.mark.parametrize("pixel", [(1e-5, 1e-5), (7e-6, 4.5e-6)])
@pytest.mark.parametrize("command", ["footprints", "reconstruct"])
def test_dsm_in_degrees_says_reproject_the_raster(runner, rasters, tmp_path, pixel, command):
    """A DSM in EPSG:4326 was told to `reproject the points (e.g. PDAL ...)`, or, with
    pixels of unequal sides in degrees, that `pixels must be square`."""
    import rasterio

    from lidar2city.cli.main import cli

    p_dsm, _ = rasters
    with rasterio.open(p_dsm) as src:
        a, profile = src.read(1), src.profile
    profile.update(crs="EPSG:4326", transform=Affine(pixel[0], 0, 4.35, 0, -pixel[1], 52.01))
    geo = tmp_path / "geo.tif"
    with rasterio.open(geo, "w", **profile) as dst:
        dst.write(a, 1)
    res = runner.invoke(cli, [command, "--dsm", str(geo), "-o", str(tmp_path / "o.gpkg")])
    assert res.exit_code == 1, res.output
    line = res.output.strip()
    assert line.startswith("Error:") and "gdalwarp" in line and "\n" not in line, line
