import tomllib

import numpy as np
import pytest
import shapely


def _write_scene(tmp_path):
    """A 60 x 60 2-m DSM with three flat-roofed buildings, its DTM and reference footprints."""
    from affine import Affine

    from lidar2city.crs import parse_crs
    from lidar2city.io.raster import Raster, write_raster
    from lidar2city.io.vector import write_polygons

    rng = np.random.default_rng(0)
    x0, y0, cell = 500000.0, 4200000.0, 2.0
    tr = Affine(cell, 0, x0, 0, -cell, y0)
    crs = parse_crs("EPSG:26918")
    dtm = 10.0 + np.zeros((60, 60))
    dsm = dtm + rng.normal(0, 0.1, dtm.shape)
    boxes = [(10, 22, 8, 20), (30, 44, 30, 50), (45, 55, 8, 24)]  # rows, cols in pixels
    refs = []
    for r0, r1, c0, c1 in boxes:
        dsm[r0:r1, c0:c1] += 7.0
        refs.append(shapely.box(c0 * cell, -r1 * cell, c1 * cell, -r0 * cell))
    write_raster(tmp_path / "dsm.tif", Raster(dsm, tr, crs))
    write_raster(tmp_path / "dtm.tif", Raster(dtm, tr, crs))
    write_polygons(tmp_path / "ref.gpkg", refs, {"id": np.arange(3)}, origin=(x0, y0), crs=crs)
    return tmp_path


def test_tune_writes_weights(runner, tmp_path):
    from lidar2city.cli.main import cli

    d = _write_scene(tmp_path)
    out = d / "w.toml"
    args = ["tune", "--dsm", str(d / "dsm.tif"), "--dtm", str(d / "dtm.tif"),
            "--reference", str(d / "ref.gpkg"), "-o", str(out), "--seed", "3",
            "--population", "4", "--generations", "1", "--figure", str(d / "ga.png")]
    res = runner.invoke(cli, args)
    assert res.exit_code == 0, res.output
    data = tomllib.loads(out.read_text())
    w = data["active_contour"]
    assert set(w) == {"alpha", "beta", "gamma", "mu", "epsilon", "anchor"}
    assert all(0.01 - 1e-9 <= v <= 10.0 + 1e-9 for v in w.values())  # the log scale: 10 ** [-2, 1]
    assert data["tune"]["cost"] <= data["tune"]["default_cost"]
    assert data["tune"]["cost"] < 0.02   # three clean boxes: almost every pixel right
    assert (d / "ga.png").stat().st_size > 1000
    # same seed, same weights
    out2 = d / "w2.toml"
    res = runner.invoke(cli, [str(out2) if a == str(out) else a for a in args])
    assert res.exit_code == 0, res.output
    assert tomllib.loads(out2.read_text())["active_contour"] == w
    assert data["tune"]["domain"] == "reference"
    # a complete reference can be scored on its whole bounding box
    out3 = d / "w3.toml"
    res = runner.invoke(cli, [str(out3) if a == str(out) else a for a in args] + ["--domain", "bbox"])
    assert res.exit_code == 0, res.output
    bbox = tomllib.loads(out3.read_text())["tune"]
    assert bbox["domain"] == "bbox" and bbox["cost"] < 0.02

    # the weights drive the outlines
    from lidar2city.tools.active_contour import footprints_active_contour

    info = footprints_active_contour(d / "dsm.tif", dtm=d / "dtm.tif", output=d / "fp.gpkg",
                                     weights=out)
    assert info["buildings"] == 3
    assert info["weights"] == pytest.approx(w)
    from lidar2city.io.vector import read_footprints

    fp, crs = read_footprints(d / "fp.gpkg", origin=(500000.0, 4200000.0))
    assert crs.to_epsg() == 26918
    truth = shapely.box(8 * 2.0, -22 * 2.0, 20 * 2.0, -10 * 2.0)  # first box, local metres
    best = max(g.intersection(truth).area / g.union(truth).area for g in fp.geometries)
    assert best > 0.8


@pytest.mark.parametrize("case", ["missing_reference", "bad_output", "grid_mismatch",
                                  "bad_population"])
def test_tune_bad_input_one_line_error(runner, tmp_path, case):
    from lidar2city.cli.main import cli

    d = _write_scene(tmp_path)
    args = ["tune", "--dsm", str(d / "dsm.tif"), "--dtm", str(d / "dtm.tif"),
            "--reference", str(d / "ref.gpkg"), "-o", str(d / "w.toml"),
            "--population", "4", "--generations", "0"]
    if case == "missing_reference":
        args[args.index("--reference") + 1] = str(d / "none.gpkg")
    elif case == "bad_output":
        args[args.index("-o") + 1] = str(d / "w.txt")
    elif case == "grid_mismatch":
        from affine import Affine

        from lidar2city.io.raster import Raster, write_raster

        write_raster(d / "small.tif", Raster(np.zeros((10, 10)), Affine(2, 0, 0, 0, -2, 0)))
        args[args.index("--dtm") + 1] = str(d / "small.tif")
    elif case == "bad_population":
        args[args.index("--population") + 1] = "2"
    res = runner.invoke(cli, args)
    assert res.exit_code != 0
    if case != "bad_population":  # click's own usage error otherwise
        assert res.output.strip().startswith("Error:"), res.output
        assert len(res.output.strip().splitlines()) == 1
    assert not (d / "w.toml").exists()


def test_tune_config_file_sets_snake_parameters(runner, tmp_path):
    from lidar2city.cli.main import cli

    d = _write_scene(tmp_path)
    (d / "run.toml").write_text("[active_contour]\nmax_iter = 'many'\n")
    args = ["tune", "--dsm", str(d / "dsm.tif"), "--dtm", str(d / "dtm.tif"),
            "--reference", str(d / "ref.gpkg"), "-o", str(d / "w.toml"), "--population", "4",
            "--generations", "0", "--config", str(d / "run.toml")]
    res = runner.invoke(cli, args)
    assert res.exit_code == 1 and "active_contour.max_iter" in res.output
    (d / "run.toml").write_text("[active_contour]\nmax_iter = 20\n")
    res = runner.invoke(cli, args)
    assert res.exit_code == 0, res.output
