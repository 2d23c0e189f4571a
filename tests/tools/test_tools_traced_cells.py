"""Traced blocks: only the cells the tiles' boxes meet, not every cell between tiles."""

import numpy as np

from lidar2city.io.las import TileInfo
from lidar2city.tools.blocks import Frame, traced_blocks


def _tile(name, x0, y0, x1, y1, count=10_000):
    return TileInfo(name, np.array([x0, y0, 0.0]), np.array([x1, y1, 10.0]), count, None)


def _frame():
    return Frame(np.zeros(3), None, 1.0, 1.0)


def test_two_areas_far_apart_give_the_cells_of_their_tiles_only():
    # two 500 m tiles 600 km apart in x and 400 km in y: 240,000 cells of 1 km between them
    a = _tile("a", 85_000, 447_000, 85_500, 447_500)
    b = _tile("b", 685_000, 847_000, 685_500, 847_500)
    specs = traced_blocks([a, b], _frame(), (85_000, 447_000, 685_500, 847_500), 1000.0, 150.0)
    assert [s.cell for s in specs] == [(85, 447), (685, 847)]
    assert [s.index for s in specs] == [0, 1]
    assert [t.path for t in specs[0].tiles] == ["a"] and [t.path for t in specs[1].tiles] == ["b"]


def test_contiguous_tiles_give_every_cell_of_their_extent_in_row_order():
    tiles = [_tile(f"t{i}{j}", 1000 * i, 1000 * j, 1000 * (i + 1) - 0.01, 1000 * (j + 1) - 0.01)
             for i in range(3) for j in range(2)]
    specs = traced_blocks(tiles, _frame(), (0, 0, 2999.99, 1999.99), 1000.0, 150.0)
    assert [s.cell for s in specs] == [(c, r) for r in range(2) for c in range(3)]
    # a tile without points adds no cell of its own
    empty = _tile("e", 5000, 0, 5999, 999, count=0)
    specs = traced_blocks(tiles + [empty], _frame(), (0, 0, 5999, 1999.99), 1000.0, 150.0)
    assert len(specs) == 6
