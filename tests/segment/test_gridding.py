"""Aligned grids and per-cell statistics (lidar2city.segment.gridding)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lidar2city.errors import EmptyInputError, InputError
from lidar2city.segment.gridding import aligned_grid, cell_index, cell_max, cell_mean, fill_nearest


def test_aligned_grid_edges_are_multiples():
    g = aligned_grid((10.2, 3.9, 11.0, 5.0), cell=0.5)
    assert (g.x0, g.y_top, g.shape) == (10.0, 5.5, (4, 3))


@given(st.floats(-1e5, 1e5), st.floats(-1e5, 1e5), st.floats(0, 300), st.floats(0, 300),
       st.sampled_from([0.25, 0.5, 1.0, 2.0]))
def test_aligned_grid_covers_and_aligns(x, y, dx, dy, cell):
    g = aligned_grid((x, y, x + dx, y + dy), cell=cell)
    assert g.x0 / cell == pytest.approx(round(g.x0 / cell))
    assert g.y_top / cell == pytest.approx(round(g.y_top / cell))
    flat = cell_index(np.array([[x, y], [x + dx, y + dy]]), g)
    assert (flat >= 0).all()


def test_cell_max_and_mean():
    g = aligned_grid((0, 0.1, 1.9, 0.9), cell=1.0)  # 1 x 2 cells
    xy = np.array([[0.2, 0.5], [0.8, 0.5], [1.5, 0.5], [5.0, 5.0]])
    flat = cell_index(xy, g)
    assert flat.tolist() == [0, 0, 1, -1]
    assert cell_max([1.0, 3.0, 2.0, 99.0], flat, g.shape).tolist() == [[3.0, 2.0]]
    assert cell_mean([1.0, 3.0, 2.0, 99.0], flat, g.shape).tolist() == [[2.0, 2.0]]
    rgb = cell_mean(np.array([[0, 10, 20], [2, 10, 20], [5, 5, 5], [9, 9, 9]]), flat, g.shape)
    assert rgb.shape == (3, 1, 2) and rgb[:, 0, 0].tolist() == [1.0, 10.0, 20.0]


def test_fill_nearest():
    g = np.array([[1.0, np.nan, np.nan, np.nan, 5.0]])
    assert fill_nearest(g).tolist() == [[1.0, 1.0, 1.0, 5.0, 5.0]] or \
        fill_nearest(g)[0, [0, 1, 3, 4]].tolist() == [1.0, 1.0, 5.0, 5.0]
    part = fill_nearest(g, max_distance=1)
    assert np.isnan(part[0, 2]) and part[0, 1] == 1.0 and part[0, 3] == 5.0
    with pytest.raises(EmptyInputError):
        fill_nearest(np.full((2, 2), np.nan))
    with pytest.raises(InputError):
        aligned_grid((0, 0, 1, 1), cell=0)
