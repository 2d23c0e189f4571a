"""Direction / deviation energies of the building snake (eqs. 4–6)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import InputError
from lidar2city.snake.energies import (
    candidate_positions,
    deviation_energy,
    direction_energy,
    distance_raster,
    edge_energy_tables,
    window_offsets,
)


def test_window_offsets_centre_first_and_complete():
    off = window_offsets(2)
    assert off.shape == (25, 2)
    assert off[0].tolist() == [0, 0]
    assert len({tuple(o) for o in off.tolist()}) == 25
    assert np.abs(off).max() == 2
    with pytest.raises(InputError, match="window"):
        window_offsets(-1)


def test_candidates_snap_free_and_keep_fixed():
    g = np.array([[1.2, 3.7], [5.25, 6.5]])
    c = candidate_positions(g, 1, fixed=[False, True])
    assert c[0].shape == (9, 2) and c[0][0].tolist() == [1.0, 4.0]
    assert c[1].shape == (1, 2) and c[1][0].tolist() == [5.25, 6.5]


def test_direction_energy_classes():
    cell, T = 0.5, 1.0
    p = np.array([[0.0, 0.0]])
    q = np.array([
        [20.0, 0.0],  # horizontal: aligned
        [0.0, 7.0],  # vertical: aligned
        [20.0, 1.0],  # 0.5 m off over 10 m: adjustable, pays its length
        [20.0, 2.0],  # 1.0 m off: still adjustable (<= T)
        [20.0, 3.0],  # 1.5 m off on both extents > T: oblique, free
        [10.0, 10.0],  # 45 degrees: oblique, free
    ])
    e = direction_energy(p, q, cell=cell, t_adjust=T)[0]
    assert e[0] == 0 and e[1] == 0 and e[4] == 0 and e[5] == 0
    assert e[2] == pytest.approx(np.hypot(10.0, 0.5))
    assert e[3] == pytest.approx(np.hypot(10.0, 1.0))


def test_deviation_energy_is_zero_on_the_data_and_grows_with_offset():
    seg = np.array([[[0.0, 0.0], [40.0, 0.0]]])  # a 20 m wall (cell 0.5) on y = 0
    r = distance_raster(seg, margin=4, subdivide=4)
    p = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])
    q = np.array([[40.0, 0.0], [40.0, 1.0], [40.0, 2.0]])
    e = deviation_energy(p, q, r, cell=0.5)
    assert e[0, 0] == pytest.approx(0.0)
    # Parallel shift by 0.5 m and 1.0 m: integral of distance = 20 m * offset.
    assert e[1, 1] == pytest.approx(20 * 0.5, rel=0.02)
    assert e[2, 2] == pytest.approx(20 * 1.0, rel=0.02)
    # A tilted candidate (0 -> 0.5 m): about half the parallel shift.
    assert e[0, 1] == pytest.approx(20 * 0.25, rel=0.1)
    assert np.all(e >= 0)


def test_chessboard_distance_transform():
    seg = np.array([[[0.0, 0.0], [0.0, 0.0001]]])
    r = distance_raster(seg, margin=3, subdivide=1)
    i0, j0 = -r.origin
    assert r.dt[i0, j0] == 0
    assert r.dt[i0 + 2, j0 + 2] == 2  # chessboard, not Euclidean
    assert r.dt[i0 + 3, j0 + 1] == 3


def test_edge_tables_shapes_and_weights():
    seg = np.array([[[0.0, 0.0], [10.0, 0.4]], [[10.0, 0.4], [10.0, 6.0]]])
    r = distance_raster(seg, margin=4)
    cands = candidate_positions(np.array([[0, 0], [10, 0.4], [10, 6]]), 1)
    edges = [(0, 1), (1, 2)]
    t_dis = edge_energy_tables(cands, edges, r, cell=0.5, t_adjust=1.0, c_dir=0.0, c_dis=1.0)
    t_both = edge_energy_tables(cands, edges, r, cell=0.5, t_adjust=1.0, c_dir=2.0, c_dis=1.0)
    assert [t.shape for t in t_both] == [(9, 9), (9, 9)]
    diff = t_both[0] - t_dis[0]
    dirs = direction_energy(cands[0], cands[1], cell=0.5, t_adjust=1.0)
    np.testing.assert_allclose(diff, 2.0 * dirs)
    # The horizontal candidate edge has no direction penalty.
    assert dirs[0, 0] == 0.0
