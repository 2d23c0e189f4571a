"""The block size of a run of given footprints: from the points a block reads."""

import numpy as np
import pytest

from lidar2city.io.las import TileInfo
from lidar2city.tools import blocks
from lidar2city.tools.blocks import Frame, footprint_block_size


def _tile(x0, y0, x1, y1, count):
    return TileInfo("t", np.array([x0, y0, 0.0]), np.array([x1, y1, 10.0]), count, None)


def _grid(x0, y0, x1, y1, step=20.0):
    """10 m x 10 m footprints every ``step`` metres over a box (local = world here)."""
    xs, ys = np.meshgrid(np.arange(x0, x1 - 10.0, step), np.arange(y0, y1 - 10.0, step))
    xs, ys = xs.ravel(), ys.ravel()
    return np.column_stack([xs, ys, xs + 10.0, ys + 10.0])


FRAME = Frame(np.zeros(3), None, 1.0, 1.0)


def test_a_sparse_area_keeps_the_largest_blocks():
    tile = _tile(0, 0, 1000, 1000, 1_000_000)  # 1 pt/m2
    assert footprint_block_size([tile], FRAME, _grid(0, 0, 1000, 1000), 51.0, 1000.0) == 1000.0


def test_a_dense_area_halves_the_blocks_until_they_fit_the_budget():
    tile = _tile(0, 0, 1000, 1000, 20_000_000)  # 20 pts/m2
    fps = _grid(0, 0, 1000, 1000)
    # blocks of 250 m read ~352 m x 352 m (2.5 M points), of 125 m ~227 m x 227 m (1.0 M)
    assert footprint_block_size([tile], FRAME, fps, 51.0, 1000.0) == 125.0
    assert footprint_block_size([tile], FRAME, fps, 51.0, 1000.0, budget=3_000_000) == 250.0
    # never below twice the margin a building reads around it, whatever the density
    assert footprint_block_size([tile], FRAME, fps, 51.0, 1000.0, budget=10) == 125.0
    assert footprint_block_size([tile], FRAME, fps, 20.0, 1000.0, budget=10) == 62.5


def test_only_the_boxes_blocks_read_count():
    # the same dense tile, its footprints in one 100 m corner: one 1 km block reads
    # ~200 m x 200 m of it (0.8 M points)
    tile = _tile(0, 0, 1000, 1000, 20_000_000)
    assert footprint_block_size([tile], FRAME, _grid(0, 0, 100, 100), 50.0, 1000.0) == 1000.0
    # points spread over several tiles are added up; tiles without points count nothing
    tiles = [_tile(0, 0, 500, 500, 5_000_000), _tile(500, 0, 1000, 500, 5_000_000),
             _tile(0, 500, 1000, 1000, 0)]
    # (blocks of 500 m read ~610 m x 550 m of the 20 pts/m2, 6.1 M points; of 250 m 2.2 M)
    assert footprint_block_size(tiles, FRAME, _grid(0, 0, 1000, 500), 50.0, 1000.0,
                                budget=3_000_000) == 250.0
    assert footprint_block_size(tiles[2:], FRAME, _grid(0, 0, 1000, 500), 50.0, 1000.0) == 1000.0


def test_the_default_block_size_gives_the_same_bytes(town_tiles_small, tmp_path, monkeypatch):
    from lidar2city.tools.reconstruct import plan_reconstruct, reconstruct

    paths, fp = town_tiles_small
    one = tmp_path / "one.city.json"
    reconstruct(paths, one, footprints=fp, lods=("1.2", "2.2"), block_size=1000.0)
    monkeypatch.setattr(blocks, "BLOCK_POINTS", 2_000)  # a few thousand points a block
    plan = plan_reconstruct(paths, tmp_path / "auto.city.json", footprints=fp, lods=("1.2", "2.2"))
    assert plan.options.block_size < 1000.0 and len(plan.specs) > 1
    auto = tmp_path / "auto.city.json"
    s = reconstruct(paths, auto, footprints=fp, lods=("1.2", "2.2"))
    assert s.blocks == len(plan.specs)
    assert auto.read_bytes() == one.read_bytes()


@pytest.fixture(scope="module")
def town_tiles_small(tmp_path_factory):
    """Two classified synthetic towns 300 m apart, a tile each, their footprints in one
    file (a raw block is classified on its own: its blocks keep the largest size)."""
    import shapely

    from lidar2city.io.las import write_points
    from lidar2city.io.vector import write_polygons
    from lidar2city.synthetic import make_town

    d = tmp_path_factory.mktemp("blocksize")
    towns = [make_town(size=(120.0, 90.0), density=6.0, seed=11, n_trees=5,
                       origin=(85_000.0 + dx, 447_000.0, 0.0)) for dx in (0.0, 300.0)]
    geoms, ids = [], []
    for k, town in enumerate(towns):
        write_points(d / f"town{k}.laz", town.cloud)
        geoms += [shapely.transform(g, lambda c, k=k: c + [300.0 * k, 0.0])
                  for g in town.footprints.geometries]
        ids += [f"{k}-{i}" for i in town.footprints.ids]
    write_polygons(d / "fp.gpkg", geoms, {"id": ids}, origin=towns[0].cloud.origin,
                   crs=towns[0].cloud.crs)
    return [d / "town0.laz", d / "town1.laz"], d / "fp.gpkg"
