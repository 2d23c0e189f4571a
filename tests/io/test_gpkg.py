"""The sqlite3 GeoPackage reader gives what GDAL gives, or steps aside (None)."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest
import shapely

from lidar2city.io.gpkg import gpkg_crs, read_gpkg_raw
from lidar2city.io.vector import read_footprints, write_polygons

pyogrio_raw = pytest.importorskip("pyogrio.raw")


def _same_as_gdal(path, **kw):
    ogr_kw = dict(kw)
    if "fids" in ogr_kw:
        ogr_kw["fids"] = np.asarray(ogr_kw["fids"], dtype=np.int64)
    a = pyogrio_raw.read(str(path), return_fids=True, force_2d=True, **ogr_kw)
    b = read_gpkg_raw(path, **kw)
    assert b is not None
    assert a[0]["crs"] == b[0]["crs"]
    assert list(a[0]["fields"]) == list(b[0]["fields"])
    assert a[1].dtype == b[1].dtype and np.array_equal(a[1], b[1])
    ga = shapely.from_wkb(a[2])
    gb = shapely.force_2d(shapely.from_wkb(b[2]))
    assert list(shapely.to_wkb(ga)) == list(shapely.to_wkb(gb))
    for x, y in zip(a[3], b[3], strict=True):
        assert x.dtype == y.dtype
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
        assert [type(v) for v in x] == [type(v) for v in y]
    return b


@pytest.mark.parametrize(("kw", "count"), [({}, 132), ({"fids": [5, 3, 100]}, 3),
                                           ({"skip_features": 10, "max_features": 20}, 20),
                                           ({"skip_features": 130, "max_features": 50}, 2)])
def test_delft_footprints_as_gdal_reads_them(data, kw, count):
    b = _same_as_gdal(data / "delft" / "footprints_bgt.gpkg", **kw)
    assert len(b[1]) == count


def test_null_reals_are_nan_as_in_gdal(data):
    b = _same_as_gdal(data / "alexandria" / "footprints_west.gpkg")
    assert np.isnan(b[3][0]).sum() == 2


def test_several_layers_or_unknown_layer_step_aside(data):
    assert read_gpkg_raw(data / "delft" / "bgt_terrain.gpkg") is None
    assert read_gpkg_raw(data / "delft" / "footprints_bgt.gpkg", layer="nope") is None
    assert read_gpkg_raw(data / "delft" / "footprints_bgt.gpkg", fids=[1, 99999]) is None


def test_unmapped_types_step_aside_and_read_footprints_still_reads(tmp_path):
    from pyproj import CRS

    path = tmp_path / "fp.gpkg"
    sq = shapely.box(0, 0, 10, 8)
    write_polygons(path, [sq, shapely.box(20, 0, 30, 5)], {"id": ["a", "b"]}, origin=(100.0, 200.0),
                   crs=CRS.from_epsg(28992))
    assert read_gpkg_raw(path) is not None
    fps, crs = read_footprints(path)
    assert fps.ids == ["a", "b"] and crs.to_epsg() == 28992
    assert shapely.equals(fps.geometries[0], shapely.box(100, 200, 110, 208))
    with sqlite3.connect(path) as con:  # a DATE column: GDAL's mapping is GDAL's business
        table = con.execute("SELECT table_name FROM gpkg_contents").fetchone()[0]
        con.execute(f'ALTER TABLE "{table}" ADD COLUMN "built" DATE')
    con.close()
    assert read_gpkg_raw(path) is None
    fps2, _ = read_footprints(path)  # read through GDAL instead
    assert fps2.ids == ["a", "b"]
    assert shapely.equals(fps2.geometries[1], fps.geometries[1])


def test_not_a_geopackage_steps_aside(tmp_path):
    bad = tmp_path / "x.gpkg"
    bad.write_bytes(b"not sqlite")
    assert read_gpkg_raw(bad) is None
    assert read_gpkg_raw(tmp_path / "x.geojson") is None


@pytest.mark.parametrize("suffix", [".gpkg", ".geojson"])
def test_missing_footprint_ids_take_the_feature_id(tmp_path, suffix, caplog):
    """Null or blank ids became the CityObject ids 'None', 'None-2' and '' (and an
    integer column with nulls, read as floats, gave '12.0'); a footprint without an id
    is named by its feature id, as in a layer without an id column, with a warning."""
    import pyogrio.raw

    path = tmp_path / f"f{suffix}"
    g = [shapely.box(i * 10.0, 0.0, i * 10.0 + 5.0, 5.0) for i in range(4)]
    ids = np.array([12.0, np.nan, 14.0, np.nan]) if suffix == ".geojson" else \
        np.array(["a", None, " ", None], dtype=object)
    pyogrio.raw.write(str(path), shapely.to_wkb(np.array(g)), [ids], ["id"],
                      crs="EPSG:28992", geometry_type="Polygon")
    fps, _ = read_footprints(path)
    # GeoPackage feature ids start at 1, GeoJSON's at 0
    want = ["12", "1", "14", "3"] if suffix == ".geojson" else ["a", "2", "3", "4"]
    assert fps.ids == want
    assert "have no 'id'" in caplog.text


def _gdal_crs(path, layer=None):
    import pyogrio

    return pyogrio.read_info(str(path), layer=layer)["crs"]


@pytest.mark.parametrize("name", ["delft/footprints_bgt.gpkg", "alexandria/footprints_west.gpkg"])
def test_plain_crs_as_gdal_reads_it(data, name):
    path = data / name
    assert gpkg_crs(path) == _gdal_crs(path)
    table = pyogrio_raw.read(str(path), max_features=1)[0]  # (the layer GDAL reads first)
    layer = __import__("pyogrio").list_layers(str(path))[0][0]
    assert table["crs"] == gpkg_crs(path, layer=layer)
    assert gpkg_crs(path, layer="nope") is None


def test_crs_steps_aside_for_several_layers_or_another_authority(data, tmp_path):
    from pyproj import CRS

    assert gpkg_crs(data / "delft" / "bgt_terrain.gpkg") is None  # several layers
    assert gpkg_crs(tmp_path / "x.geojson") is None
    bad = tmp_path / "x.gpkg"
    bad.write_bytes(b"not sqlite")
    assert gpkg_crs(bad) is None
    path = tmp_path / "fp.gpkg"
    write_polygons(path, [shapely.box(0, 0, 10, 8)], {"id": ["a"]}, origin=(100.0, 200.0),
                   crs=CRS.from_epsg(28992))
    assert gpkg_crs(path) == "EPSG:28992" == _gdal_crs(path)
    with sqlite3.connect(path) as con:  # an SRS of another organisation: GDAL's business
        con.execute("UPDATE gpkg_spatial_ref_sys SET organization = 'ACME' "
                    "WHERE organization_coordsys_id = 28992")
    con.close()
    assert gpkg_crs(path) is None


def test_vector_crs_of_a_plain_geopackage_without_gdal(data, tmp_path):
    """A run with a plain GeoPackage's footprints never loads GDAL (pyogrio): its CRS
    and its features are read with sqlite3, the same CRS as GDAL's."""
    import subprocess
    import sys

    from pyproj import CRS

    from lidar2city.io.vector import vector_crs

    path = data / "delft" / "footprints_bgt.gpkg"
    assert vector_crs(path) == CRS.from_user_input(_gdal_crs(path))
    code = ("import sys; from lidar2city.io.vector import vector_crs, read_footprints; "
            f"c = vector_crs({str(path)!r}); f, _ = read_footprints({str(path)!r}); "
            "print(c.to_epsg(), len(f), 'pyogrio' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["28992", "132", "False"]
    # geographic: GDAL is asked (its bounds tell degrees from projected coordinates)
    geo = tmp_path / "geo.gpkg"
    write_polygons(geo, [shapely.box(4.0, 52.0, 4.001, 52.001)], {"id": ["a"]},
                   origin=(0.0, 0.0), crs=CRS.from_epsg(4326))
    assert gpkg_crs(geo) == "EPSG:4326"
    assert vector_crs(geo) == CRS.from_user_input(_gdal_crs(geo))
