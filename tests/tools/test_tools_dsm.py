"""DSM tools: footprints GPKG + figure, LoD1 prisms, given footprints, LAS gridding, real data."""

from __future__ import annotations

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS

from lidar2city.errors import InputError
from lidar2city.io.raster import Raster, read_raster, write_raster
from lidar2city.tools.dsm import (
    footprints_from_dsm,
    load_dsm_config,
    lod1_from_dsm,
    outlines_from_labels,
    rasters_from_las,
)

CRS_UTM = CRS.from_epsg(26918)
T = Affine(1.0, 0.0, 500000.0, 0.0, -1.0, 4300000.0)


@pytest.fixture
def scene(tmp_path):
    """A 1 m DSM: flat terrain at 20 m, a 30 x 16 m box 9 m high, an L 6 m high."""
    h, w = 90, 110
    dsm = np.full((h, w), 20.0)
    dsm[10:26, 10:40] = 29.0
    dsm[40:80, 60:75] = 26.0
    dsm[65:80, 75:100] = 26.0
    dsm[0:3, 0:3] = np.nan  # nodata corner
    dtm = np.full((h, w), 20.0)
    p_dsm, p_dtm = tmp_path / "dsm.tif", tmp_path / "dtm.tif"
    write_raster(p_dsm, Raster(dsm, T, CRS_UTM, np.isfinite(dsm)))
    write_raster(p_dtm, Raster(dtm, T, CRS_UTM, np.isfinite(dtm)))
    return p_dsm, p_dtm


def test_footprints_gpkg_and_figure(scene, tmp_path):
    import pyogrio
    import shapely

    p_dsm, p_dtm = scene
    out, fig, dtm_out = tmp_path / "fp.gpkg", tmp_path / "fig.png", tmp_path / "dtm_out.tif"
    calls = []
    # walls on pixel edges: none of the half-cell excess of a highest-point-per-cell DSM
    exact = load_dsm_config(None, **{"dsm_roofs.edge_inset": 0.0})
    s = footprints_from_dsm(p_dsm, output=out, figure=fig, dtm_out=dtm_out, config=exact,
                            progress=lambda i, n: calls.append((i, n)))
    assert s["buildings"] == 2 and s["failed"] == 0 and s["dtm"] == "built from the DSM"
    assert calls and calls[-1][0] == calls[-1][1]
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    t = read_raster(dtm_out)
    assert np.nanmax(np.abs(t.array - 20.0)) < 0.01 and np.isnan(t.array[0, 0])
    meta, _, wkb, fields = pyogrio.raw.read(str(out))
    assert CRS.from_user_input(meta["crs"]).equals(CRS_UTM)
    f = dict(zip(meta["fields"], fields, strict=True))
    geoms = shapely.from_wkb(wkb)
    order = np.argsort(f["area"])
    box = geoms[order[0]]
    assert f["shape_type"][order[0]] == "rectangle"
    assert box.area == pytest.approx(30 * 16, rel=0.03)
    assert box.bounds[0] == pytest.approx(500010.0, abs=0.5)
    assert box.bounds[3] == pytest.approx(4300000.0 - 10.0, abs=0.5)
    assert f["height"][order[0]] == pytest.approx(9.0, abs=0.01)
    assert f["shape_type"][order[1]] == "composite"
    assert f["n_vertices"][order[1]] == 6
    assert f["height"][order[1]] == pytest.approx(6.0, abs=0.01)
    # with the given DTM and the raw pixel outlines
    s2 = footprints_from_dsm(p_dsm, dtm=p_dtm, output=tmp_path / "raw.gpkg", regularize="none")
    assert s2["shape_types"] == {"pixels": 2}


def test_lod1_prisms_closed_and_oriented(scene):
    res = lod1_from_dsm(scene[0], dtm=scene[1])
    assert res["ok"] == 2 and res["crs"].equals(CRS_UTM)
    for b in res["buildings"]:
        solid = b.solids["1.2"]
        kinds = [s.semantic for s in solid.surfaces]
        assert kinds[:2] == ["GroundSurface", "RoofSurface"]
        assert kinds.count("WallSurface") == len(b.footprint.exterior.coords) - 1
        assert b.attributes["ground_z"] == pytest.approx(20.0)
        v = solid.vertices
        # signed volume from outward-oriented faces (fan triangulation)
        vol = 0.0
        for s in solid.surfaces:
            ring = v[s.rings[0]]
            for i in range(1, len(ring) - 1):
                vol += np.dot(ring[0], np.cross(ring[i], ring[i + 1])) / 6.0
        h = b.attributes["roof_z"] - b.attributes["ground_z"]
        assert vol == pytest.approx(b.footprint.area * h, rel=1e-4)  # vertices snapped to 1 mm


def test_prism_with_courtyard_volume():
    import shapely

    from lidar2city.lod.prism import prism_solid  # the one prism builder, used by lod1_from_dsm

    poly = shapely.Polygon([(0, 0), (10, 0), (10, 10), (0, 10)], [[(3, 3), (3, 6), (6, 6), (6, 3)]])
    s = prism_solid(poly, 1.0, 4.0)
    vol = 0.0
    for surf in s.surfaces:
        for ring_idx in surf.rings:
            ring = s.vertices[ring_idx]
            for i in range(1, len(ring) - 1):
                vol += np.dot(ring[0], np.cross(ring[i], ring[i + 1])) / 6.0
    assert vol == pytest.approx((100 - 9) * 3.0)
    assert sum(x.semantic == "WallSurface" for x in s.surfaces) == 8


def test_lod1_for_given_footprints(scene, tmp_path):
    import shapely

    from lidar2city.io.vector import write_polygons

    fp = tmp_path / "given.gpkg"
    geoms = [shapely.box(500010, 4299974, 500040, 4299990), None]
    write_polygons(fp, [geoms[0]], {"id": ["A"]}, origin=(0, 0), crs=CRS_UTM)
    res = lod1_from_dsm(scene[0], dtm=scene[1], footprints=fp)
    (b,) = res["buildings"]
    assert b.id == "A" and b.ok
    assert b.attributes["height"] == pytest.approx(9.0)


def test_bad_inputs(scene, tmp_path):
    p_dsm, _ = scene
    other = tmp_path / "other.tif"
    write_raster(other, Raster(np.zeros((5, 5)), T, CRS_UTM))
    with pytest.raises(InputError):
        footprints_from_dsm(p_dsm, dtm=other, output=tmp_path / "x.gpkg")
    with pytest.raises(InputError):
        footprints_from_dsm(p_dsm, output=tmp_path / "x.gpkg", regularize="magic")


@pytest.mark.slow
def test_autzen_rasters_from_las(data, tmp_path):
    """Gridded RGB points (feet CRS) give a metric-cell DSM and an orthoimage."""
    dsm_p, ortho_p = tmp_path / "dsm.tif", tmp_path / "ortho.tif"
    s = rasters_from_las(data / "misc" / "autzen_trim.laz", cell=1.0, dsm_out=dsm_p, ortho_out=ortho_p)
    d, o = read_raster(dsm_p), read_raster(ortho_p)
    assert d.crs is not None and d.xy_unit == pytest.approx(0.3048)
    assert d.cell_size == pytest.approx(1.0)
    assert o.array.shape == (3,) + d.shape
    # the trimmed tile covers part of its bounding box; inside it few cells are empty
    hull_cells = d.mask.sum()
    assert hull_cells > 0.5 * d.array.size
    assert s["points"] == 110000
    # the tile holds trees, lawns and a road but no house: the colour model must
    # keep the crowns out (without it, smooth crown tops may pass as roofs)
    # Known limit: with the default 10 m2 smallest roof (the annexes of Delft's row
    # houses) 26 smooth crown fragments of this 1 m tile pass the colour model; the
    # colour model itself is checked at the former 30 m2.
    big = load_dsm_config(None, **{"dsm_roofs.min_area": 30.0})
    with_rgb = footprints_from_dsm(dsm_p, ortho=ortho_p, output=tmp_path / "a.gpkg", config=big)
    assert with_rgb["buildings"] <= 1


@pytest.mark.parametrize("angle", [8.0, 17.0, 31.0])
def test_touching_regions_share_their_wall(angle):
    """Two row houses split at a step: with shared_margin no gap opens at their wall."""
    import shapely

    from lidar2city.fit.polygon import PolygonFitConfig

    def rot(v):
        a = np.deg2rad(angle)
        r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        return (v - [45.0, 35.0]) @ r.T + [45.0, 35.0]

    a = rot(np.array([[20, 20], [45, 20], [45, 46], [20, 46.0]]))  # pixel corners (x, y)
    b = rot(np.array([[45, 22], [70, 22], [70, 44], [45, 44.0]]))
    yy, xx = np.mgrid[0:70, 0:90] + 0.5
    lab = np.zeros((70, 90), np.int32)
    lab[shapely.contains_xy(shapely.Polygon(a), xx, yy)] = 1
    lab[shapely.contains_xy(shapely.Polygon(b), xx, yy)] = 2
    ndsm = np.where(lab > 0, 6.0, 0.0)
    to_m = np.array([0.5, -0.5])  # cell 0.5 m, y north
    truth = shapely.union_all([shapely.Polygon(a * to_m), shapely.Polygon(b * to_m)])
    wall = shapely.LineString(rot(np.array([[45, 22], [45, 44.0]])) * to_m).buffer(1.0)
    gaps = {}
    for margin in (0.0, 0.5):
        res = outlines_from_labels(lab, ndsm, cell=0.5,
                                   fit_config=PolygonFitConfig(shared_margin=margin,
                                                               outline_inset=0.0))
        assert [r.attributes["pixels"] for r in res] == [int((lab == 1).sum()),
                                                          int((lab == 2).sum())]
        u = shapely.union_all([r.footprint for r in res])
        gaps[margin] = truth.difference(u).intersection(wall).area
        # the overlap the margin leaves (a cell-wide strip along the wall, ~5 m2) is split
        # along the two outlines' common axis; a wedge stays where their axes differ
        assert res[0].footprint.intersection(res[1].footprint).area < 0.5
    assert gaps[0.5] < 0.05  # m2 along an 11 m wall
    assert gaps[0.5] < 0.3 * gaps[0.0]

@pytest.mark.slow
def test_alexandria_quality(data, tmp_path):
    """Restricted per-area quality and matching on the Alexandria west tile (see the benchmark)."""
    import pyogrio
    import shapely

    from lidar2city.metrics.footprints import area_metrics, match_objects

    a = data / "alexandria"
    out = tmp_path / "fp.gpkg"
    footprints_from_dsm(a / "dsm_west.tif", dtm=a / "dtm_west.tif", output=out)
    _, _, wkb, _ = pyogrio.raw.read(str(a / "footprints_west.gpkg"))
    ref = [max(shapely.get_parts(g), key=lambda p: p.area) for g in shapely.from_wkb(wkb)]
    _, _, w2, _ = pyogrio.raw.read(str(out))
    pred = [max(shapely.get_parts(g), key=lambda p: p.area) for g in shapely.from_wkb(w2)]
    hits = np.unique(shapely.STRtree(ref).query(pred, predicate="intersects")[0])
    sel = [pred[i] for i in hits]
    am = area_metrics(sel, ref)
    mo = match_objects(sel, ref)
    # measured (see benchmarks/bench_dsm_fit.py) minus a margin
    assert am["quality"] > QUALITY_MIN
    assert mo["recall"] > RECALL_MIN


# measured 0.552 and 0.732 (benchmarks/bench_dsm_fit.py, given DTM, issue 16's roof
# defaults; 0.564 / 0.750 before them, 0.564 / 0.696 before the saddle split and trimming);
# 0.526 / 0.714 with a shared-wall margin of one 2 m cell, which is why it rounds to none
# there
QUALITY_MIN = 0.53
RECALL_MIN = 0.70


def test_dsm_config_file_errors_are_one_line_errors(tmp_path):
    """load_dsm_config reads TOML through config.read_config: every file mistake is an error class."""
    from lidar2city.errors import ConfigError, FileFormatError
    from lidar2city.tools.dsm import load_dsm_config

    binary = tmp_path / "run.toml"
    binary.write_bytes(b"\xff\xfe\x00 not text")
    with pytest.raises(ConfigError):
        load_dsm_config(binary)
    with pytest.raises(FileFormatError):
        load_dsm_config(tmp_path / "missing.toml")
    good = tmp_path / "good.toml"
    good.write_text("[dsm_roofs]\nmin_area = 20.0\n[ground]\ncell = 1.0\n")
    cfg = load_dsm_config(good, **{"dsm_lod1.roof_stat": None})
    assert cfg["dsm_roofs"].min_area == 20.0
    with pytest.raises(ConfigError):
        load_dsm_config(None, **{"ground.cell": 2.0})


def test_a_feet_dsm_gives_the_metric_dsm_result(scene, tmp_path):
    """A DSM in a feet CRS (as `rasterize` writes for US tiles) holds heights in feet:
    the same scene in feet gives the same outlines, metric heights and areas, and
    prisms whose vertices are in feet, instead of 3.28 times taller buildings and
    thresholds (2.5 m minimum height) applied to feet."""
    import pyogrio

    ft = 0.3048
    crs_ft = CRS.from_epsg(2994)  # NAD83(HARN) / Oregon Lambert (ft)
    t_ft = Affine(1.0 / ft, 0.0, 2000000.0, 0.0, -1.0 / ft, 800000.0)
    paths = []
    for p in scene:
        r = read_raster(p)
        out = tmp_path / f"{p.stem}_ft.tif"
        write_raster(out, Raster(r.array / ft, t_ft, crs_ft, np.isfinite(r.array)))
        paths.append(out)
    metric = footprints_from_dsm(scene[0], dtm=scene[1], output=tmp_path / "m.gpkg")
    feet = footprints_from_dsm(paths[0], dtm=paths[1], output=tmp_path / "f.gpkg")
    assert feet["buildings"] == metric["buildings"] == 2
    fields = {}
    for name in ("m", "f"):
        meta, _, _, values = pyogrio.raw.read(tmp_path / f"{name}.gpkg")
        fields[name] = dict(zip(meta["fields"], values, strict=True))
    np.testing.assert_allclose(fields["f"]["height"], fields["m"]["height"], rtol=1e-6)
    np.testing.assert_allclose(fields["f"]["area"], fields["m"]["area"], rtol=1e-6)
    res_m, res_f = lod1_from_dsm(scene[0], dtm=scene[1]), lod1_from_dsm(paths[0], dtm=paths[1])
    assert res_f["z_unit"] == pytest.approx(ft)
    for bm, bf in zip(res_m["buildings"], res_f["buildings"], strict=True):
        assert bf.attributes["roof_z"] == pytest.approx(bm.attributes["roof_z"], rel=1e-6)
