"""Surveys unlike Delft, run as a new user would (session 7's sweep).

Each test is a problem the sweep found: a tile or a footprint file of a kind
the shared data does not hold, made here in a few hundred points. A bad input
must give one ``Error:`` line and a non-zero exit; a good one a sensible model.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from shapely.geometry import box


def _error_line(res):
    """The single ``Error:`` line of a failed run (asserts there is nothing else)."""
    lines = [ln for ln in res.output.splitlines() if ln.strip() and not ln.startswith("WARNING")]
    assert res.exit_code not in (0, None), res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert len(lines) == 1 and lines[0].startswith("Error: "), res.output
    return lines[0]


ORIGIN = np.array([85000.0, 447000.0])


def _tile(path, xyz, cls, *, crs=28992):
    """A LAS/LAZ tile of world points ``xyz`` with classes ``cls``."""
    from pyproj import CRS

    from lidar2city.datamodel import PointCloud
    from lidar2city.io.las import write_points

    cloud = PointCloud.from_world(np.asarray(xyz, dtype=np.float64),
                                  crs=None if crs is None else CRS.from_epsg(crs),
                                  attributes={"classification": np.asarray(cls, dtype=np.uint8)})
    write_points(path, cloud)
    return path


def _footprints(path, polys, *, crs=28992):
    from pyproj import CRS

    from lidar2city.io.vector import write_polygons

    write_polygons(path, polys, {"id": [f"F{i}" for i in range(len(polys))]}, origin=ORIGIN,
                   crs=CRS.from_epsg(crs))
    return path


# --- a tile of one point ---------------------------------------------------------------------

@pytest.mark.parametrize("footprint", [box(5, 5, 15, 15), box(30, 30, 40, 40), None])
def test_one_point_tile_says_it_has_no_area(runner, tmp_path, footprint):
    """One point (or points on a line) has no area: say so, not that the footprints
    miss the tile (which sent the user checking CRSs) nor an empty success."""
    from lidar2city.cli.main import cli

    tile = _tile(tmp_path / "one.laz", [[*ORIGIN + 10.0, 8.0]], [6])
    args = ["reconstruct", str(tile), "-o", str(tmp_path / "out.city.json")]
    if footprint is not None:
        args += ["--footprints", str(_footprints(tmp_path / "f.gpkg", [footprint]))]
    line = _error_line(runner.invoke(cli, args))
    assert "1 point" in line and "no area" in line, line
    assert "footprints" not in line or "CRS" not in line
    assert not (tmp_path / "out.city.json").exists()


# --- a tile whose header bounds are wrong --------------------------------------------------

def _block_scene(n=4000, seed=1):
    """Flat ground 40 x 40 m with a 10 x 8 m building 6 m tall (classified), world points."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 40, (n, 2))
    inside = (xy[:, 0] > 10) & (xy[:, 0] < 20) & (xy[:, 1] > 10) & (xy[:, 1] < 18)
    z = np.where(inside, 6.0, 0.0) + rng.normal(0, 0.02, n)
    return np.column_stack([xy + ORIGIN, z]), np.where(inside, 6, 2), [box(10, 10, 20, 18)]


def _wrong_header(path, shift=5000.0):
    """Write the header's bounds ``shift`` units off its points (LAS 1.2 offsets 179-226)."""
    import struct

    import laspy

    with laspy.open(path) as f:
        mins, maxs = np.array(f.header.mins), np.array(f.header.maxs)
    with open(path, "r+b") as f:
        f.seek(179)
        f.write(struct.pack("<6d", maxs[0] + shift, mins[0] + shift, maxs[1] + shift,
                            mins[1] + shift, maxs[2], mins[2]))


@pytest.mark.parametrize("with_footprints", [True, False])
def test_wrong_header_bounds_are_named(runner, tmp_path, with_footprints):
    """The planner trusts the headers' bounds: a header off its points read as 'no
    footprint meets the extent (check both CRSs)' or 'no building found'. Say the
    header is wrong, naming the file."""
    from lidar2city.cli.main import cli

    xyz, cls, fps = _block_scene()
    tile = _tile(tmp_path / "t.las", xyz, cls)
    _wrong_header(tile)
    args = ["reconstruct", str(tile), "-o", str(tmp_path / "out.city.json")]
    if with_footprints:
        args += ["--footprints", str(_footprints(tmp_path / "f.gpkg", fps))]
    line = _error_line(runner.invoke(cli, args))
    assert "header" in line and "t.las" in line, line
    assert not (tmp_path / "out.city.json").exists()


def test_wrong_header_bounds_are_named_by_footprints_on_a_folder(runner, tmp_path):
    from lidar2city.cli.main import cli

    xyz, cls, _ = _block_scene()
    (tmp_path / "tiles").mkdir()
    _wrong_header(_tile(tmp_path / "tiles" / "t.las", xyz, cls))
    line = _error_line(runner.invoke(cli, ["footprints", str(tmp_path / "tiles"), "-o",
                                           str(tmp_path / "f.gpkg")]))
    assert "header" in line and "t.las" in line, line


# --- a tile in a geographic CRS ------------------------------------------------------------

def test_info_describes_a_geographic_tile(runner, tmp_path):
    """``info`` is what a user runs to learn what a file holds: on a tile in degrees
    (EPSG:4326) it failed like the commands that need metres. It now describes the
    file, bounds in degrees, and says why the other commands refuse it; those still
    give their one-line error, never metres taken for degrees."""
    import laspy
    from pyproj import CRS

    from lidar2city.cli.main import cli

    rng = np.random.default_rng(0)
    h = laspy.LasHeader(point_format=6, version="1.4")
    h.scales, h.offsets = [1e-7, 1e-7, 0.001], [4.0, 52.0, 0.0]
    h.add_crs(CRS.from_epsg(4326))
    las = laspy.LasData(h)
    las.x = 4.36 + rng.uniform(0, 0.001, 500)
    las.y = 52.01 + rng.uniform(0, 0.001, 500)
    las.z = rng.uniform(0, 10, 500)
    las.classification = np.full(500, 2, np.uint8)
    path = tmp_path / "geo.laz"
    las.write(path)
    res = runner.invoke(cli, ["info", str(path)])
    assert res.exit_code == 0, res.output
    assert "WGS 84" in res.output and "degree" in res.output
    assert "reproject the points" in res.output
    assert "4.36" in res.output and "52.01" in res.output
    res = runner.invoke(cli, ["info", str(path), "--json"])
    info = json.loads(res.output)
    assert info["xy_unit_m"] is None and info["density_pts_m2"] is None and info["points"] == 500
    line = _error_line(runner.invoke(cli, ["classify", str(path), "-o", str(tmp_path / "c.laz")]))
    assert "geographic" in line


# --- footprint files: formats, CRSs ---------------------------------------------------------

def test_footprint_table_without_geometry_says_so(runner, tmp_path):
    """A CSV of ids and coordinates (no geometry column) was 'holds no footprints',
    although it holds rows: say it has no geometry and what to give instead."""
    from lidar2city.cli.main import cli

    xyz, cls, _ = _block_scene()
    tile = _tile(tmp_path / "t.laz", xyz, cls)
    csv = tmp_path / "f.csv"
    csv.write_text("id,x,y\nA,85015,447014\n")
    line = _error_line(runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(csv),
                                           "-o", str(tmp_path / "out.city.json")]))
    assert "no geometry" in line and "WKT" in line, line


def test_footprints_in_wkt_csv_and_other_crs_give_the_same_models(runner, tmp_path):
    """A CSV with a WKT column (read by GDAL), and the same footprints in EPSG:3857,
    are reprojected onto the tile: the same model as from the GeoPackage."""
    from pyproj import Transformer

    from lidar2city.cli.main import cli

    xyz, cls, fps = _block_scene()
    tile = _tile(tmp_path / "t.laz", xyz, cls)
    csv = tmp_path / "f.csv"
    world = [(x + ORIGIN[0], y + ORIGIN[1]) for x, y in fps[0].exterior.coords]
    csv.write_text("id,wkt\nF0,\"POLYGON ((" + ", ".join(f"{x} {y}" for x, y in world)
                   + "))\"\n")
    tr = Transformer.from_crs(28992, 3857, always_xy=True)
    import shapely

    merc = shapely.transform(fps[0], lambda c: np.column_stack(
        tr.transform(c[:, 0] + ORIGIN[0], c[:, 1] + ORIGIN[1])) - ORIGIN)
    roofs = []
    for name, f in (("gpkg", _footprints(tmp_path / "f.gpkg", fps)), ("csv", csv),
                    ("3857", _footprints(tmp_path / "m.gpkg", [merc], crs=3857))):
        out = tmp_path / f"{name}.city.json"
        res = runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(f), "-o",
                                  str(out)])
        assert res.exit_code == 0, res.output
        b = json.loads(out.read_text())["CityObjects"]["F0"]["attributes"]
        roofs.append((b["roof_height"], b["ground_height"], b["point_count"]))
    assert roofs[0] == roofs[1] == roofs[2] and roofs[0][0] == pytest.approx(6.0, abs=0.05)


def test_footprints_without_crs_are_said_to_be_taken_in_the_tiles(runner, tmp_path, caplog):
    """Footprints without a CRS were silently taken to be in the tiles' CRS: right
    when they are, a puzzle when not; say so once."""
    import pyogrio.raw
    import shapely

    from lidar2city.cli.main import cli

    xyz, cls, fps = _block_scene()
    tile = _tile(tmp_path / "t.laz", xyz, cls)
    f = tmp_path / "f.gpkg"
    world = shapely.transform(fps[0], lambda c: c + ORIGIN)
    with pytest.warns(UserWarning, match="crs"):
        pyogrio.raw.write(str(f), shapely.to_wkb(np.array([world], dtype=object)),
                          [np.array(["F0"], dtype=object)], ["id"], geometry_type="Polygon")
    res = runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(f), "-o",
                              str(tmp_path / "o.city.json")])
    assert res.exit_code == 0, res.output
    assert "no CRS" in caplog.text and "Amersfoort" in caplog.text, caplog.text


# --- a tile with a few stray returns kilometres away ------------------------------------------

@pytest.mark.parametrize("command", ["classify", "ground"])
def test_stray_far_points_do_not_stop_classify_or_ground(runner, tmp_path, command, caplog):
    """Three returns 1000 km, 200 km and 30 km off the survey made the ground grid
    10^12 cells: 'grid too large; use a larger cell size', which no cell size
    fixes. They are left out as noise and the survey filtered as without them."""
    import laspy

    from lidar2city.cli.main import cli

    xyz, cls, _ = _block_scene()
    far = np.array([[1e6, 0, 5.0], [0, -2e5, 5.0], [3e4, 3e4, 5.0]]) + [*ORIGIN, 0]
    clean = _tile(tmp_path / "clean.laz", xyz, np.ones(len(xyz)))
    dirty = _tile(tmp_path / "dirty.laz", np.vstack([xyz, far]), np.ones(len(xyz) + 3))
    outs = []
    for t in (clean, dirty):
        out = tmp_path / f"{t.stem}_out.laz"
        dtm = ["--dtm", str(tmp_path / f"{t.stem}.tif")] if command == "ground" else []
        res = runner.invoke(cli, [command, str(t), "-o", str(out), *dtm])
        assert res.exit_code == 0, res.output
        outs.append(np.asarray(laspy.read(out).classification))
    assert np.array_equal(outs[0], outs[1][:-3])
    assert (outs[1][-3:] == (7 if command == "classify" else 1)).all()
    assert "3 point(s)" in caplog.text
    if command == "ground":  # the DTM covers the survey only
        from lidar2city.io.raster import read_raster

        a, b = read_raster(tmp_path / "clean.tif"), read_raster(tmp_path / "dirty.tif")
        assert a.array.shape == b.array.shape and a.transform == b.transform
        assert np.allclose(a.array, b.array, atol=1e-6, equal_nan=True)


def test_stray_far_points_do_not_plan_a_block_per_empty_square_km(runner, tmp_path):
    """Without footprints every cell of the tiles' header extent was a block: two stray
    returns 1000 km off made 10^6 blocks (a run that never ends). A tile whose header
    extent is almost empty is planned on the cells its points occupy."""
    from lidar2city.cli.main import cli
    from lidar2city.tools.reconstruct import plan_reconstruct

    xyz, cls, _ = _block_scene()
    far = np.array([[2e5, 0, 5.0], [0, -2e5, 5.0]]) + [*ORIGIN, 0]
    dirty = _tile(tmp_path / "dirty.laz", np.vstack([xyz, far]), np.r_[cls, 1, 1])
    out = tmp_path / "o.city.json"
    plan = plan_reconstruct([str(dirty)], out, crs="EPSG:28992")
    assert len(plan.specs) <= 3 * 9, len(plan.specs)
    res = runner.invoke(cli, ["reconstruct", str(dirty), "-o", str(out)])
    assert res.exit_code == 0, res.output
    objs = json.loads(out.read_text())["CityObjects"]
    assert [o["attributes"]["roof_height"] for o in objs.values()] == [pytest.approx(6.0, abs=0.1)]


def test_stray_far_points_do_not_stop_rasterize_nor_thin_info(runner, tmp_path, caplog):
    """rasterize asked for a 10^12-cell grid ('use a larger cell size'), and info gave a
    density of 0.00 pts/m2: both now work on the survey, the strays said."""
    from lidar2city.cli.main import cli
    from lidar2city.io.raster import read_raster

    xyz, cls, _ = _block_scene()
    far = np.array([[1e6, 0, 5.0], [0, -2e5, 5.0]]) + [*ORIGIN, 0]
    clean = _tile(tmp_path / "clean.laz", xyz, cls)
    dirty = _tile(tmp_path / "dirty.laz", np.vstack([xyz, far]), np.r_[cls, 1, 1])
    rasters, densities = [], []
    for t in (clean, dirty):
        out = tmp_path / f"{t.stem}.tif"
        res = runner.invoke(cli, ["rasterize", str(t), "-o", str(out)])
        assert res.exit_code == 0, res.output
        rasters.append(read_raster(out))
        res = runner.invoke(cli, ["info", str(t), "--json"])
        densities.append(json.loads(res.output)["density_pts_m2"])
    assert rasters[0].transform == rasters[1].transform
    assert np.allclose(rasters[0].array, rasters[1].array, equal_nan=True)
    assert "2 point(s)" in caplog.text
    assert densities[1] == pytest.approx(densities[0], rel=0.01) and densities[0] > 1


def test_tile_without_crs_and_footprints_in_degrees_asks_for_the_tiles_crs(runner, tmp_path):
    """A tile without a CRS takes its footprints' CRS: footprints in EPSG:4326 made the
    tile 'geographic' and the error said to reproject the points, which are in metres.
    Ask for the tiles' CRS instead (the footprints are then reprojected onto it)."""
    from pyproj import Transformer

    from lidar2city.cli.main import cli

    xyz, cls, fps = _block_scene()
    tile = _tile(tmp_path / "t.laz", xyz, cls, crs=None)
    tr = Transformer.from_crs(28992, 4326, always_xy=True)
    import shapely

    deg = shapely.transform(fps[0], lambda c: np.column_stack(
        tr.transform(c[:, 0] + ORIGIN[0], c[:, 1] + ORIGIN[1])))
    f = tmp_path / "f.gpkg"
    import pyogrio.raw

    pyogrio.raw.write(str(f), shapely.to_wkb(np.array([deg], dtype=object)),
                      [np.array(["F0"], dtype=object)], ["id"], geometry_type="Polygon",
                      crs="EPSG:4326")
    out = tmp_path / "o.city.json"
    line = _error_line(runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(f),
                                           "-o", str(out)]))
    assert "--crs" in line and "footprints" in line and "reproject the points" not in line, line
    res = runner.invoke(cli, ["reconstruct", str(tile), "--footprints", str(f), "-o", str(out),
                              "--crs", "EPSG:28992"])
    assert res.exit_code == 0, res.output
    b = json.loads(out.read_text())["CityObjects"]["F0"]["attributes"]
    assert b["roof_height"] == pytest.approx(6.0, abs=0.05)


def test_evaluate_footprints_against_a_reference_in_degrees(runner, tmp_path):
    """reconstruct reprojects footprints in EPSG:4326, evaluate footprints refused a
    reference in degrees; it now scores in the prediction's projected CRS, as with the
    same reference in metres."""
    import pyogrio.raw
    import shapely
    from pyproj import Transformer

    from lidar2city.cli.main import cli

    ref = [box(0, 0, 10, 10), box(20, 0, 30, 10)]
    pred = [box(1, 0, 11, 10), box(40, 40, 45, 45)]
    _footprints(tmp_path / "pred.gpkg", pred)
    _footprints(tmp_path / "ref.gpkg", ref)
    tr = Transformer.from_crs(28992, 4326, always_xy=True)
    deg = [shapely.transform(g, lambda c: np.column_stack(
        tr.transform(c[:, 0] + ORIGIN[0], c[:, 1] + ORIGIN[1]))) for g in ref]
    pyogrio.raw.write(str(tmp_path / "ref4326.gpkg"), shapely.to_wkb(np.array(deg, dtype=object)),
                      [np.array(["a", "b"], dtype=object)], ["id"], geometry_type="Polygon",
                      crs="EPSG:4326")
    reps = []
    for r in ("ref.gpkg", "ref4326.gpkg"):
        res = runner.invoke(cli, ["evaluate", "footprints", str(tmp_path / "pred.gpkg"),
                                  "--reference", str(tmp_path / r), "--json"])
        assert res.exit_code == 0, res.output
        reps.append(json.loads(res.output))
    # the round trip through degrees moves vertices by millimetres
    assert reps[1]["area"]["quality"] == pytest.approx(reps[0]["area"]["quality"], abs=1e-3)
    assert reps[1]["objects"]["matched"] == reps[0]["objects"]["matched"] == 1
