"""reconstruct gives the same buildings (the same bytes) whatever the tiling of the input."""

import numpy as np
import pytest

from lidar2city.datamodel import ASPRS
from lidar2city.io.las import TileReader, read_las, scan_tiles, write_points
from lidar2city.io.vector import write_polygons
from lidar2city.synthetic import make_town
from lidar2city.tools.reconstruct import reconstruct


def _split(cloud, cuts_x, cuts_y, folder, prefix):
    """Write ``cloud`` as tiles cut at the world coordinates ``cuts_x`` / ``cuts_y``."""
    world = cloud.to_world(cloud.xyz)
    cx = np.searchsorted(np.asarray(cuts_x, float), world[:, 0], side="right")
    cy = np.searchsorted(np.asarray(cuts_y, float), world[:, 1], side="right")
    paths = []
    for i in range(len(cuts_x) + 1):
        for j in range(len(cuts_y) + 1):
            m = (cx == i) & (cy == j)
            if m.any():
                p = folder / f"{prefix}_{i}_{j}.laz"
                write_points(p, cloud.subset(m))
                paths.append(p)
    return paths


@pytest.fixture(scope="module")
def town_tiles(tmp_path_factory, raw_town):
    d = tmp_path_factory.mktemp("tiles")
    town, raw = raw_town(d, size=(120.0, 90.0), density=6.0, seed=11)
    o = raw.origin
    four = _split(raw, [o[0] + 55.0], [o[1] + 47.0], d, "four")
    strips = _split(raw, [o[0] + 33.0, o[0] + 81.0], [], d, "strip")
    empty = d / "empty.laz"  # an empty tile (header bounds at 0, 0) changes nothing
    write_points(empty, raw.subset(np.zeros(len(raw), bool)))
    return town, d, {"whole": [d / "whole.laz"], "four": four[::-1] + [empty],
                     "strips": [strips[1], strips[2], strips[0]]}


def test_tile_reader_box_is_the_same_whatever_the_tiling(town_tiles):
    _, d, sets = town_tiles
    boxes = []
    for paths in sets.values():
        reader = TileReader(scan_tiles(paths, allow_empty=True), cache=2)
        o = reader.origin
        c = reader.box(o[0] + 20.0, o[1] + 10.0, o[0] + 100.0, o[1] + 60.0)
        boxes.append(c)
        # the LRU cache holds at most two decoded tiles
        assert len(reader._tiles) <= 2
    for c in boxes[1:]:
        assert np.array_equal(c.xyz, boxes[0].xyz) and np.array_equal(c.origin, boxes[0].origin)
        assert np.array_equal(c.attributes["classification"], boxes[0].attributes["classification"])
    whole = read_las(d / "whole.laz").point_cloud()
    assert len(boxes[0]) < len(whole)


def test_scan_tiles_reads_headers_and_checks_crs(town_tiles, tmp_path):
    from lidar2city.errors import CRSError, FileFormatError

    _, d, sets = town_tiles
    tiles = scan_tiles(sets["four"])
    assert sum(t.count for t in tiles) == read_las(d / "whole.laz").data.header.point_count
    # one CRS object for all the tiles (a country's tile index holds thousands)
    assert tiles[0].crs is not None and all(t.crs is tiles[0].crs for t in tiles)
    assert TileReader(tiles).world_bounds()[0] > 0  # the empty tile's zeros are left out
    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"not a las file")
    with pytest.raises(FileFormatError, match="bad.laz"):
        scan_tiles([bad])
    other = read_las(sets["four"][0]).point_cloud()
    write_points(tmp_path / "other.laz", other.__class__(other.xyz, other.origin, None,
                                                         other.xy_unit, other.z_unit,
                                                         other.attributes))
    with pytest.raises(CRSError, match="different CRSs"):
        scan_tiles([sets["four"][1], tmp_path / "other.laz"])


@pytest.mark.parametrize("with_footprints", [True, False])
def test_reconstruct_is_the_same_whatever_the_tiling(town_tiles, tmp_path, with_footprints):
    town, d, sets = town_tiles
    outs = {}
    for name, paths in sets.items():
        out = tmp_path / f"{name}.city.json"
        s = reconstruct(paths, out, footprints=d / "fp.gpkg" if with_footprints else None,
                        lods=("1.2", "2.2"), block_size=50.0)
        assert s.failed == 0 and s.invalid == 0
        if with_footprints:
            assert s.total == len(town.buildings)
        outs[name] = out.read_bytes()
    assert outs["four"] == outs["whole"] and outs["strips"] == outs["whole"]


def test_block_size_must_be_positive(town_tiles, tmp_path):
    from lidar2city.errors import InputError

    _, d, sets = town_tiles
    with pytest.raises(InputError, match="block_size"):
        reconstruct(sets["whole"], tmp_path / "x.city.json", footprints=d / "fp.gpkg", block_size=0)


@pytest.mark.slow
def test_delft_is_the_same_whatever_the_tiling(data, tmp_path):
    """The AHN3 tile cut in 2 x 2 and in 3 strips, given in shuffled order, LoD1.2 + LoD2.2."""
    tile = read_las(data / "delft" / "ahn3_cropped_1.laz", crs="EPSG:28992")
    cloud = tile.point_cloud()
    o = cloud.origin
    four = _split(cloud, [o[0] + 92.0], [o[1] + 88.0], tmp_path, "four")
    strips = _split(cloud, [o[0] + 62.0, o[0] + 132.0], [], tmp_path, "strip")
    fp = data / "delft" / "footprints_bgt.gpkg"
    outs = []
    for paths in ([data / "delft" / "ahn3_cropped_1.laz"], four[::-1], strips[1:] + strips[:1]):
        out = tmp_path / f"m{len(outs)}.city.json"
        s = reconstruct(paths, out, footprints=fp, crs="EPSG:28992", lods=("1.2", "2.2"),
                        block_size=100.0)
        assert s.done == s.total == 132 and s.invalid == 0
        outs.append(out.read_bytes())
    assert outs[1] == outs[0] and outs[2] == outs[0]


def test_classified_input_is_never_reclassified_block_by_block(tmp_path, monkeypatch):
    """A classified input keeps its classes in every block, even a block without
    building points (it is not ground-filtered and classified on its own)."""
    import shapely

    import lidar2city.tools.classify as tc
    from lidar2city.io.cityjson import read_cityjson

    def no_classification(*a, **k):
        raise AssertionError("a block of a classified input was classified again")

    monkeypatch.setattr(tc, "classify_cloud", no_classification)
    town = make_town(size=(160.0, 60.0), density=4.0, seed=3)
    # a field east of the town (ground only) and a footprint over it, more than the
    # 50 m margin away from any building point: its block holds no building point
    c = town.cloud
    gx, gy = np.meshgrid(np.arange(200.0, 300.0, 0.5), np.arange(0.0, 60.0, 0.5))
    field = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    attrs = {k: np.concatenate([v, np.full(len(field), ASPRS.GROUND if k == "classification" else 1,
                                           dtype=v.dtype)]) for k, v in c.attributes.items()}
    cloud = c.__class__(np.concatenate([c.xyz, field]), c.origin, c.crs, c.xy_unit, c.z_unit, attrs)
    write_points(tmp_path / "c.laz", cloud)
    lone = shapely.box(250.0, 20.0, 258.0, 28.0)
    assert not any(g.intersects(lone.buffer(5.0)) for g in town.footprints.geometries)
    write_polygons(tmp_path / "fp.gpkg", [*town.footprints.geometries, lone],
                   {"id": [*town.footprints.ids, "lone"]}, origin=town.cloud.origin,
                   crs=town.cloud.crs)
    s = reconstruct([tmp_path / "c.laz"], tmp_path / "m.city.json", footprints=tmp_path / "fp.gpkg",
                    block_size=50.0)
    assert s.total == len(town.buildings) + 1 and s.failed == 1
    assert next(iter(s.reasons)) == "no building point in the block around the footprint"
    assert len(read_cityjson(tmp_path / "m.city.json").objects) == len(town.buildings) + 1
