"""The roof steps' fast paths give what the library calls they replace give."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial import cKDTree

from lidar2city.roof.arrangement import _close_points, _nearest
from lidar2city.roof.topology import _cross_dilation

coord = st.floats(-1e4, 1e4, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(p=st.tuples(coord, coord), d=st.tuples(st.floats(-1e-3, 1e-3), st.floats(-1e-7, 1e-7)))
def test_close_points_is_allclose(p, d):
    a = np.array(p)
    for b in (a + np.array(d), a.copy(), a + 1.0):
        assert _close_points(a, b) == np.allclose(a, b)
    for special in (np.inf, -np.inf, np.nan):
        b = a.copy()
        b[1] = special
        assert _close_points(a, b) == np.allclose(a, b)
        assert _close_points(b, b) == np.allclose(b, b)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 300), q=st.integers(1, 60),
       grid=st.booleans())
def test_nearest_is_the_trees(seed, n, q, grid):
    rng = np.random.default_rng(seed)
    pts, qs = rng.random((n, 2)) * 20, rng.random((q, 2)) * 20
    if grid:  # millimetre coordinates on a coarse lattice: many equal distances
        pts, qs = np.round(pts) / 2, np.round(qs) / 2
    np.testing.assert_array_equal(_nearest(pts, qs, cKDTree), cKDTree(pts).query(qs)[1])


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), h=st.integers(1, 9), w=st.integers(1, 9))
def test_cross_dilation_is_binary_dilation(seed, h, w):
    m = np.random.default_rng(seed).random((h, w)) < 0.3
    np.testing.assert_array_equal(_cross_dilation(m), ndimage.binary_dilation(m))
