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


def _part_floor_plain(poly, xyz, labels, planes, ground_z, *, min_height, spacing,
                      flat_slope=3.0, share=1 / 3, building_points=None):
    """part_floor as it was: every plane's points in a tree, its lowest height measured."""
    corners = np.asarray(poly.exterior.coords)[:, :2]
    lows, held, flat_lows, flat_held = [], 0, [], 0
    for k, (a, b, c) in enumerate(np.asarray(planes)):
        flat = np.degrees(np.arctan(np.hypot(a, b))) < flat_slope
        own = xyz[labels == k]
        if not len(own):
            continue
        near = cKDTree(own[:, :2]).query(corners, distance_upper_bound=2 * spacing)[0] < np.inf
        low = float(np.min(np.vstack([own[:, :2], corners[near]]) @ (a, b) + c))
        if low >= ground_z + min_height:
            continue
        if flat:
            flat_lows.append(low)
            flat_held += len(own)
        else:
            lows.append(low)
            held += len(own)
    if lows and held >= share * len(xyz):
        return min(ground_z, min(lows) - 2 * min_height)
    total = len(xyz) if building_points is None else max(int(building_points), len(xyz))
    if flat_lows and held + flat_held >= share * total:
        return min(ground_z, min(lows + flat_lows) - 2 * min_height)
    return ground_z


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 80), k=st.integers(0, 6),
       ground=st.floats(-2.0, 12.0))
def test_part_floor_passes_planes_only_when_the_plain_loop_would(seed, n, k, ground):
    # planes whose lowest height over their points and every corner stays above the floor's
    # reach are passed without a tree: the floor is the one the plain loop finds
    from shapely.geometry import box

    from lidar2city.roof.building import part_floor

    rng = np.random.default_rng(seed)
    poly = box(0, 0, 10, 8)
    xyz = np.column_stack([rng.uniform(-0.5, 10.5, n), rng.uniform(-0.5, 8.5, n),
                           rng.uniform(0, 10, n)])
    labels = rng.integers(-1, k + 1, n)
    planes = np.column_stack([rng.normal(0, 0.5, k) * (rng.random(k) < 0.7),
                              rng.normal(0, 0.5, k) * (rng.random(k) < 0.7),
                              rng.uniform(-2, 12, k)])
    kw = dict(min_height=0.5, spacing=float(rng.uniform(0.3, 2.0)),
              building_points=int(rng.integers(0, 2 * n + 1)))
    assert part_floor(poly, xyz, labels, planes, ground, **kw) == \
        _part_floor_plain(poly, xyz, labels, planes, ground, **kw)
def _random_cells(seed, n_lines):
    import shapely

    rng = np.random.default_rng(seed)
    fp = shapely.Polygon([(0, 0), (10, 0), (10, 6), (6, 6), (6, 10), (0, 10)],
                         [[(2, 2), (3, 2), (3, 3), (2, 3)]])
    lines = [rng.random((2, 2)) * 14 - 2 for _ in range(n_lines)]
    if n_lines:  # lines through the same points: collinear overlaps and concurrent crossings
        lines.append(np.array([lines[0][0], lines[0][0] + 0.5 * (lines[0][1] - lines[0][0])]))
    return arrangement_cells(fp, lines)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lines=st.integers(0, 8))
def test_shared_lengths_are_the_overlays(seed, n_lines):
    import shapely

    from lidar2city.roof.arrangement import _shared_lengths

    cells = np.asarray(_random_cells(seed, n_lines), dtype=object)
    a, b = np.triu_indices(len(cells), 1)
    want = shapely.length(shapely.intersection(shapely.boundary(cells[a]), shapely.boundary(cells[b])))
    np.testing.assert_allclose(_shared_lengths(list(cells), a, b), want, rtol=1e-12, atol=1e-12)


def _drop_collinear_by_ring(faces, tol=1e-6):
    """drop_collinear's turning test as it was, ring by ring (without the merge of close
    vertices, which the cases below do not need)."""
    import shapely

    from lidar2city.roof.solid import _ring_keys

    rings = [[np.asarray(r.coords)[:-1] for r in shapely.get_rings(f)] for f in faces]
    turning = set()
    for rs in rings:
        for r in rs:
            prev, nxt = np.roll(r, 1, axis=0), np.roll(r, -1, axis=0)
            u, v = r - prev, nxt - r
            dev = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]) / np.maximum(
                np.hypot(*(nxt - prev).T), 1e-12)
            turning.update(_ring_keys(r[(dev > tol) | (np.einsum("ij,ij->i", u, v) < 0)]))
    out = []
    for f, rs in zip(faces, rings, strict=True):
        kept = [r[[k in turning for k in _ring_keys(r)]] for r in rs]
        out.append(f if len(kept[0]) < 3 else
                   shapely.Polygon(kept[0], [h for h in kept[1:] if len(h) >= 3]))
    return out


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lines=st.integers(0, 8))
def test_drop_collinear_is_ring_by_ring(seed, n_lines):
    import shapely

    from lidar2city.roof.arrangement import dissolve_cells, drop_collinear

    cells = _random_cells(seed, n_lines)
    # faces with straight vertices: cells of one label dissolved without the collinear drop
    labels = np.random.default_rng(seed).integers(0, 2, len(cells))
    faces, _ = dissolve_cells(cells, labels)
    faces = list(shapely.segmentize(np.asarray(faces, dtype=object), 1.5))
    want = _drop_collinear_by_ring(faces)
    if not all(f.is_valid and f.area > 0 for f in want):
        want = faces
    got = drop_collinear(faces)
    assert [g.wkb for g in got] == [w.wkb for w in want]


def test_as_rebuilt_keeps_clean_faces():
    import shapely

    from lidar2city.roof.arrangement import _as_rebuilt

    clean = shapely.Polygon([(0, 0), (4, 0), (4, 4), (0, 4)], [[(1, 1), (2, 1), (2, 2), (1, 2)]])
    repeat = shapely.Polygon([(0, 0), (4, 0), (4, 0), (4, 4), (0, 4)])
    spike = shapely.Polygon([(0, 0), (4, 0), (4, 4), (5, 5), (4, 4), (0, 4)])
    hole_repeat = shapely.Polygon([(0, 0), (4, 0), (4, 4), (0, 4)],
                                  [[(1, 1), (2, 1), (2, 1), (2, 2), (1, 2)]])
    faces = [clean, repeat, spike, hole_repeat, clean]
    rings = [[np.asarray(r.coords)[:-1] for r in shapely.get_rings(f)] for f in faces]
    got = _as_rebuilt(faces, rings, lambda fi, mp: ("rebuilt", fi))
    assert got == [clean, ("rebuilt", 1), ("rebuilt", 2), ("rebuilt", 3), clean]
    assert got[0] is clean


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lines=st.integers(0, 6), lift=st.floats(0.0, 3.0))
def test_held_faces_are_supported(seed, n_lines, lift):
    from lidar2city.roof.building import _fixed_face, _held_faces

    rng = np.random.default_rng(seed)
    faces = _random_cells(seed, n_lines)
    planes = [np.array([a, b, c]) for a, b, c in rng.normal(0.0, 0.5, (len(faces), 3))]
    labels = np.arange(len(faces))
    xyz = np.column_stack([rng.random((400, 2)) * 10, rng.normal(0.0, 1.0, 400) + lift])
    x = xyz[:, 0]
    by_x = np.argsort(x, kind="stable")
    sorted_x = (by_x, x[by_x])
    zmin = float(xyz[:, 2].min())
    held = _held_faces(faces, labels, planes, xyz, sorted_x, zmin, spacing=0.5, t_step=0.3)
    want = [_fixed_face(f, planes[k], xyz, sorted_x, zmin, spacing=0.5, t_step=0.3) is None
            for k, f in enumerate(faces)]
    assert not (held & ~np.asarray(want, dtype=bool)).any()  # held: supported


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_lines=st.integers(0, 6))
def test_repeat_vertices_is_ring_by_ring(seed, n_lines):
    import shapely

    from lidar2city.roof.building import _repeat_vertices, _repeats_a_vertex

    faces = _random_cells(seed, n_lines)
    # a shell through one vertex twice (a hole pinched into it) and a hole that does
    pinch = shapely.Polygon([(0, 0), (4, 0), (4, 4), (2, 4), (2.5, 2), (1.5, 2), (2, 4), (0, 4)])
    holed = shapely.Polygon([(0, 0), (4, 0), (4, 4), (0, 4)],
                            [[(1, 1), (2, 1), (2, 2), (1.5, 1.00001), (1, 2)]])
    arr = np.asarray([*faces, pinch, shapely.Polygon(), holed,
                      shapely.MultiPolygon([shapely.box(0, 0, 1, 1)])], dtype=object)
    which = (shapely.get_type_id(arr) == 3) & ~shapely.is_empty(arr)
    want = [bool(w) and any(_repeats_a_vertex(r) for r in shapely.get_rings(f))
            for f, w in zip(arr, which, strict=True)]
    assert _repeat_vertices(arr, which).tolist() == want
    assert want[len(faces)] and not want[len(faces) + 1]
