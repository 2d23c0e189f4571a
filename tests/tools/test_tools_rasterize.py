"""``lidar2city rasterize``: synthetic clouds with exact answers, bad input, the Delft tile."""

from __future__ import annotations

import numpy as np
import pytest
from pyproj import CRS

from lidar2city.datamodel import ASPRS, PointCloud
from lidar2city.errors import EmptyInputError, InputError

RD = CRS.from_epsg(28992)


def _block(classified=True, rgb=True):
    """Ground at 1 m (class 2) on a 10 x 10 m square, a 4 x 4 m box 6 m above it (class 6)."""
    rng = np.random.default_rng(0)
    n = 20000
    xy = rng.uniform(0, 10, (n, 2)) + [100.0, 200.0]
    inbox = (np.abs(xy[:, 0] - 105) < 2) & (np.abs(xy[:, 1] - 205) < 2)
    z = np.where(inbox, 7.0, 1.0)
    cls = np.where(inbox, ASPRS.BUILDING, ASPRS.GROUND).astype(np.uint8)
    attrs = {"classification": cls if classified else np.ones(n, np.uint8),
             "intensity": np.where(inbox, 100, 50).astype(np.uint16)}
    if rgb:
        attrs.update(red=np.where(inbox, 60000, 1000).astype(np.uint16),
                     green=np.full(n, 2000, np.uint16), blue=np.full(n, 3000, np.uint16))
    # a noise point far above: never in the DSM
    xyz = np.column_stack([xy, z])
    xyz = np.vstack([xyz, [[101.3, 201.3, 80.0]]])
    attrs = {k: np.append(v, 7 if k == "classification" else v[0]) for k, v in attrs.items()}
    return PointCloud.from_world(xyz, crs=RD, attributes=attrs)


def test_products_exact():
    from lidar2city.tools.rasterize import rasterize_points

    c = _block()
    d = rasterize_points(c, product="dsm", cell=0.5)
    t = d["transform"]
    assert (t.a, t.e, t.c % 0.5, t.f % 0.5) == (0.5, -0.5, 0.0, 0.0)
    assert d["array"].shape == (20, 20)
    assert np.nanmax(d["array"]) == 7.0  # the noise point is left out
    col, row = ~t @ (105.0, 205.0)
    assert d["array"][int(row), int(col)] == 7.0 and d["array"][1, 1] == 1.0
    dtm = rasterize_points(c, product="dtm", cell=0.5)
    assert dtm["ground"] == "classified"
    assert np.allclose(dtm["array"], 1.0)
    nd = rasterize_points(c, product="ndsm", cell=0.5)["array"]
    assert nd[int(row), int(col)] == pytest.approx(6.0) and nd[1, 1] == pytest.approx(0.0)
    it = rasterize_points(c, product="intensity", cell=0.5)["array"]
    assert it[int(row), int(col)] == 100.0 and it[1, 1] == 50.0
    rgb = rasterize_points(c, product="rgb", cell=0.5)["array"]
    assert rgb.shape == (3, 20, 20) and rgb[0, int(row), int(col)] == 60000.0


def test_dtm_of_an_unclassified_cloud_uses_the_ground_filter():
    from lidar2city.tools.rasterize import rasterize_points

    c = _block(classified=False)
    dtm = rasterize_points(c, product="dtm", cell=1.0)
    assert dtm["ground"].startswith("filter")
    assert np.nanmedian(np.abs(dtm["array"] - 1.0)) < 0.05
    with pytest.raises(EmptyInputError, match="classified ground"):
        rasterize_points(c, product="dtm", cell=1.0, ground="classified")


def test_bad_input():
    from lidar2city.tools.rasterize import rasterize_points

    with pytest.raises(InputError, match="red/green/blue"):
        rasterize_points(_block(rgb=False), product="rgb")
    with pytest.raises(InputError, match="product"):
        rasterize_points(_block(), product="slope")
    with pytest.raises(InputError, match="cell"):
        rasterize_points(_block(), cell=-1)


def test_cli_rasterize(runner, tmp_path):
    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points
    from lidar2city.io.raster import read_raster

    c = _block()
    write_points(tmp_path / "a.laz", c.subset(c.xyz[:, 0] < 5))
    write_points(tmp_path / "b.laz", c.subset(c.xyz[:, 0] >= 5))
    out = tmp_path / "dsm.tif"
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "a.laz"), str(tmp_path / "b.laz"),
                              "-o", str(out), "--product", "ndsm"])
    assert res.exit_code == 0, res.output
    r = read_raster(out)
    assert r.crs.to_epsg() == 28992 and r.cell_size == 0.5 and np.nanmax(r.array) == pytest.approx(6.0)
    # an empty tile, and a DTM asked of a tile without ground classes: one line, no file
    write_points(tmp_path / "empty.laz", c.subset(np.zeros(len(c), bool)))
    for args in (["empty.laz"], ["a.laz", "--product", "dtm", "--ground", "classified"]):
        un = _block(classified=False)
        write_points(tmp_path / "un.laz", un)
        args = [str(tmp_path / a) if a.endswith(".laz") else a for a in args]
        if "classified" in args:
            args[0] = str(tmp_path / "un.laz")
        bad = tmp_path / "bad.tif"
        res = runner.invoke(cli, ["rasterize", *args, "-o", str(bad)])
        assert res.exit_code != 0
        assert "Traceback" not in res.output and len(res.output.strip().splitlines()) == 1
        assert not bad.exists()


def test_cli_rasterize_a_tile_without_crs(runner, tmp_path, caplog):
    """A tile without a CRS (AHN, a local survey): refused in one line naming both ways
    out; --no-crs writes the raster without one, with a warning; --crs sets it."""
    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points
    from lidar2city.io.raster import read_raster

    c = _block()
    write_points(tmp_path / "t.laz", PointCloud(c.xyz, origin=c.origin, crs=None,
                                                attributes=c.attributes))
    out = tmp_path / "dsm.tif"
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "t.laz"), "-o", str(out)])
    assert res.exit_code != 0 and not out.exists()
    line = res.output.strip()
    assert len(line.splitlines()) == 1 and "--crs" in line and "--no-crs" in line, res.output
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "t.laz"), "-o", str(out), "--no-crs"])
    assert res.exit_code == 0, res.output
    assert "no CRS" in caplog.text  # the warning
    r = read_raster(out)
    assert r.crs is None and np.nanmax(r.array) == pytest.approx(7.0)
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "t.laz"), "-o", str(out),
                              "--crs", "EPSG:28992"])
    assert res.exit_code == 0 and read_raster(out).crs.to_epsg() == 28992
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "t.laz"), "-o", str(out),
                              "--crs", "EPSG:28992", "--no-crs"])
    assert res.exit_code != 0 and "--no-crs" in res.output


def test_a_compound_crs_is_written_by_its_code(runner, tmp_path):
    """EPSG:7415 (RD New + NAP height) was written from its WKT, which GDAL stored as
    RD New + a vertical datum named 'Ibiza' with no EPSG code: a GIS read the heights
    on the wrong datum. A CRS with an EPSG code is written by its code."""
    import rasterio
    from pyproj import CRS as PCRS

    from lidar2city.cli.main import cli
    from lidar2city.io.las import write_points

    c = _block()
    write_points(tmp_path / "t.laz", PointCloud(c.xyz, origin=c.origin, crs=None,
                                                attributes=c.attributes))
    out = tmp_path / "dsm.tif"
    res = runner.invoke(cli, ["rasterize", str(tmp_path / "t.laz"), "-o", str(out),
                              "--crs", "EPSG:7415"])
    assert res.exit_code == 0, res.output
    with rasterio.open(out) as ds:
        assert ds.crs.to_epsg() == 7415
        crs = PCRS.from_wkt(ds.crs.to_wkt(version="WKT2_2019"))
    assert crs.sub_crs_list[1].datum.name == "Normaal Amsterdams Peil"


@pytest.mark.slow
def test_delft_dsm_equals_the_shared_one(data, tmp_path):
    from lidar2city.io.raster import read_raster
    from lidar2city.tools.rasterize import rasterize_files

    out = tmp_path / "dsm.tif"
    rasterize_files(data / "delft" / "ahn3_cropped_1.laz", out, product="dsm", cell=0.5,
                    crs="EPSG:28992")
    ours, shared = read_raster(out), read_raster(data / "delft" / "dsm_50cm.tif")
    assert ours.transform == shared.transform
    assert np.nanmax(np.abs(ours.array - shared.array)) < 1e-3
