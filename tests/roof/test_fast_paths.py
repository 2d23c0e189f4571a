"""The roof steps' fast paths give what the library calls they replace give."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.spatial import cKDTree

from lidar2city.roof.arrangement import (
    _close_points,
    _nearest,
    _point_cells,
    _spike_free,
    arrangement_cells,
)
from lidar2city.roof.refine import _remove_spikes
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


def _fit_plane_numpy(xyz):
    """fit_plane as it was, with np.linalg.solve."""
    m = xyz.mean(axis=0)
    d = xyz - m
    A = np.array([[d[:, 0] @ d[:, 0], d[:, 0] @ d[:, 1]], [d[:, 0] @ d[:, 1], d[:, 1] @ d[:, 1]]])
    rhs = np.array([d[:, 0] @ d[:, 2], d[:, 1] @ d[:, 2]])
    if A[0, 0] * A[1, 1] - A[0, 1] ** 2 <= 1e-12 * max(A[0, 0] * A[1, 1], 1e-300):
        return None
    a, b = np.linalg.solve(A, rhs)
    return np.array([a, b, m[2] - a * m[0] - b * m[1]])


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 80), spread=st.floats(0.01, 50.0),
       tilt=st.floats(-3.0, 3.0), skew=st.floats(-1.0, 1.0))
def test_fit_plane_same_doubles_as_linalg_solve(seed, n, spread, tilt, skew):
    from lidar2city.roof.facets import fit_plane

    rng = np.random.default_rng(seed)
    xyz = rng.normal(0.0, spread, (n, 3)) + 1000.0
    xyz[:, 1] += skew * xyz[:, 0]  # elongated, correlated point sets (either pivot row)
    xyz[:, 2] = tilt * xyz[:, 0] - 0.5 * xyz[:, 1] + rng.normal(0.0, 0.05, n)
    expected, got = _fit_plane_numpy(xyz), fit_plane(xyz)
    assert (expected is None) == (got is None)
    if got is not None:
        # the same doubles where LAPACK's dgesv runs its reference kernel; OpenBLAS picks
        # its kernel by CPU (DYNAMIC_ARCH), and on some the last bits differ
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * np.abs(xyz).max())


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 400), lines=st.integers(0, 6))
def test_point_cells_is_the_trees_query(seed, n, lines):
    """Points in the cells of a line arrangement (many on the lines and at their crossings,
    in several cells) take the cell an STRtree query gives first."""
    import shapely
    from shapely.geometry import box

    rng = np.random.default_rng(seed)
    foot = box(0, 0, 10, 6)
    segs = [np.array([[x, -1.0], [x, 7.0]]) for x in rng.integers(1, 10, lines)]
    segs += [np.array([[-1.0, -1.0], [11.0, 7.0]])] if lines % 2 else []
    cells = arrangement_cells(foot, segs)
    xy = rng.uniform(-1, 11, (n, 2))
    if n:  # points on the cells' vertices and edges, and on a lattice of the lines
        v = shapely.get_coordinates(np.asarray(cells, dtype=object))
        xy[: n // 3] = v[rng.integers(0, len(v), n // 3)]
        xy[n // 3: 2 * n // 3] = np.round(xy[n // 3: 2 * n // 3])
    ip, ic = shapely.STRtree(cells).query(shapely.points(xy), predicate="intersects")
    first = np.unique(ip, return_index=True)[1]
    got = _point_cells(cells, xy)
    np.testing.assert_array_equal(got[0], ip[first])
    np.testing.assert_array_equal(got[1], ic[first])


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), m=st.integers(0, 12), spikes=st.integers(0, 3))
def test_spike_free_is_remove_spikes(seed, m, spikes):

    rng = np.random.default_rng(seed)
    ring = list(np.round(rng.random((m, 2)) * 4, 1))
    for _ in range(spikes):  # A, X, A back and forth
        if len(ring) >= 2:
            i = int(rng.integers(1, len(ring)))
            ring[i:i] = [rng.random(2), ring[i - 1].copy()]
    ring = np.asarray(ring, dtype=float).reshape(-1, 2)
    want = np.asarray(_remove_spikes(list(ring)), dtype=float).reshape(-1, 2)
    np.testing.assert_array_equal(_spike_free(ring), want)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40), m=st.integers(1, 6),
       ties=st.booleans())
def test_column_medians_are_the_medians(seed, n, m, ties):
    from lidar2city._stats import median
    from lidar2city.roof.facets import _column_medians

    rng = np.random.default_rng(seed)
    d = rng.random((n, m))
    if ties:  # repeated values
        d = np.round(d * 3) / 3
    got = _column_medians(d)
    for c in range(m):
        assert got[c] == median(d[:, c].copy())


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 50), q=st.sampled_from([0.5, 0.9, 0.95]),
       rounded=st.booleans())
def test_quantile_side_agrees_with_numpy(seed, n, q, rounded):
    from lidar2city.roof.facets import quantile_side

    rng = np.random.default_rng(seed)
    a = rng.random(n) * 2
    if rounded:  # limits right on order statistics and ties
        a = np.round(a, 1)
    for limit in (0.5, 1.0, float(a[0]), float(np.quantile(a, q))):
        side = quantile_side(a.copy(), q, limit)
        if side is not None:
            assert side == bool(np.quantile(a, q) <= limit)
    # a limit far from the order statistics is decided without numpy
    assert quantile_side(a.copy(), q, 10.0) is True and quantile_side(a.copy(), q, -1.0) is False


def _roof_cloud(seed, n):
    """A gable, a lower flat annex, two level strips apart at one height and clutter."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [40.0, 30.0]
    x, y = xy[:, 0], xy[:, 1]
    z = np.where(y < 10, 10 + 0.5 * y, 20 - 0.5 * y)  # gable, ridge at y = 10
    z = np.where(y >= 20, 6.0, z)  # the annex
    z = np.where((x < 2) | (x > 38), 12.0, z)  # two rims at one height
    z = z + rng.normal(0, 0.03, n)
    clutter = rng.random(n) < 0.02
    z[clutter] += rng.random(clutter.sum()) * 2
    return np.column_stack([x, y, z])


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2500, 5000), tol=st.sampled_from([0.1, 0.2, 0.3]))
def test_screened_merge_is_the_fitted_merge(seed, n, tol):
    import lidar2city.roof.facets as facets

    xyz = _roof_cloud(seed, n)
    screened = facets.segment_planes(xyz, dist_tol=tol)
    old = facets._SCREEN_POINTS
    facets._SCREEN_POINTS = 10**12  # every union fitted
    try:
        fitted = facets.segment_planes(xyz, dist_tol=tol)
    finally:
        facets._SCREEN_POINTS = old
    np.testing.assert_array_equal(screened[0], fitted[0])
    np.testing.assert_array_equal(screened[1], fitted[1])


def _boundary_chains_numpy(grid):
    """boundary_chains' walk as it was, on numpy scalars (the same chains)."""
    from lidar2city.roof.topology import _boundary_graph

    graph = _boundary_graph(grid)
    if graph is None:
        return [], []
    u, v, pairs, deg, starts, nbr_edge, junction = graph
    W = grid.labels.shape[1] + 1
    used = np.zeros(len(u), dtype=bool)
    chains, chain_pairs = [], []

    def walk(node, edge):
        path = [node]
        while True:
            used[edge] = True
            nxt = v[edge] if u[edge] == node else u[edge]
            path.append(nxt)
            if junction[nxt]:
                return path
            cand = nbr_edge[starts[nxt]:starts[nxt] + 2]
            edge_next = cand[0] if cand[0] != edge else cand[1]
            if used[edge_next]:
                return path
            node, edge = nxt, edge_next

    for node in np.flatnonzero(junction & (deg > 0)):
        for k in range(starts[node], starts[node + 1]):
            if not used[nbr_edge[k]]:
                chains.append(np.array(walk(node, nbr_edge[k])))
                chain_pairs.append(tuple(pairs[nbr_edge[k]]))
    for e in np.flatnonzero(~used):
        if not used[e]:
            chains.append(np.array(walk(u[e], e)))
            chain_pairs.append(tuple(pairs[e]))
    out = []
    for path in chains:
        r, c = np.divmod(path, W)
        out.append(np.column_stack([grid.x0 + c * grid.cell, grid.y0 + r * grid.cell]))
    return out, [tuple(int(x) for x in p) for p in chain_pairs]


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), h=st.integers(1, 14), w=st.integers(1, 14),
       k=st.integers(1, 4))
def test_boundary_chains_walk_is_the_numpy_walk(seed, h, w, k):
    from lidar2city.roof.topology import LabelGrid, boundary_chains

    labels = np.random.default_rng(seed).integers(-1, k, (h, w))
    grid = LabelGrid(labels, 3.25, -7.5, 0.5)
    chains, pairs = boundary_chains(grid)
    ref_chains, ref_pairs = _boundary_chains_numpy(grid)
    assert pairs == ref_pairs
    assert len(chains) == len(ref_chains)
    for c, r in zip(chains, ref_chains, strict=True):
        np.testing.assert_array_equal(c, r)
