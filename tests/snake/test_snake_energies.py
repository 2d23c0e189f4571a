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
    short_edge_energy,
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


def _deviation_every_pair(p_u, p_v, raster, cell):
    """E_Dis sampled pair by pair (the formula without the per-axis lookup)."""
    dt, origin, scale = raster
    p0 = np.asarray(p_u, dtype=np.float64) * scale - origin
    p1 = np.asarray(p_v, dtype=np.float64) * scale - origin
    d = p1[None, :, :] - p0[:, None, :]
    length = np.hypot(d[..., 0], d[..., 1])
    n = max(int(np.ceil(float(length.max()))), 1) + 1
    t = np.linspace(0.0, 1.0, n)
    ix = np.clip(np.floor(p0[:, None, None, 0] + 0.5 + t * d[..., None, 0]).astype(np.intp), 0, dt.shape[0] - 1)
    iy = np.clip(np.floor(p0[:, None, None, 1] + 0.5 + t * d[..., None, 1]).astype(np.intp), 0, dt.shape[1] - 1)
    wts = np.full(n, 1.0 / (n - 1))
    wts[[0, -1]] *= 0.5
    return np.einsum("abn,n->ab", dt[ix, iy].astype(np.float64), wts) * length * (cell / scale) ** 2


@pytest.mark.parametrize("seed", range(4))
def test_deviation_lookup_matches_sampling_every_pair(seed):
    # free (window) and fixed (off-grid) vertices, candidates reaching past the raster
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 30, (6, 2))
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    r = distance_raster(seg, margin=1, subdivide=4)
    cands = candidate_positions(xy, 3, fixed=np.arange(6) == 2)
    for u, v in [(0, 1), (1, 2), (2, 3), (0, 5), (4, 4)]:
        got = deviation_energy(cands[u], cands[v], r, cell=0.5)
        np.testing.assert_allclose(got, _deviation_every_pair(cands[u], cands[v], r, 0.5), rtol=1e-12, atol=1e-12)


def test_deviation_long_edge_in_chunks_matches_sampling_every_pair():
    seg = np.array([[[0.0, 0.0], [400.0, 3.0]]])  # long: the candidates of u go in chunks
    r = distance_raster(seg, margin=4, subdivide=4)
    cands = candidate_positions(seg[0], 3)
    got = deviation_energy(cands[0], cands[1], r, cell=0.5)
    n = int(np.ceil(np.hypot(*(cands[1][:, None] - cands[0][None]).T).max() * r.scale)) + 1
    rows = 1_000_000 // (n * 49)  # the samples' memory budget
    assert rows < 49
    ref = np.concatenate([_deviation_every_pair(cands[0][i:i + rows], cands[1], r, 0.5) for i in range(0, 49, rows)])
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)


def test_edge_tables_batched_equal_edge_by_edge():
    xy = np.array([[0.0, 0.0], [10.0, 0.4], [10.0, 6.0], [0.2, 6.1]])
    seg = np.stack([xy, np.roll(xy, -1, axis=0)], axis=1)
    r = distance_raster(seg, margin=4)
    edges = np.array([(0, 1), (1, 2), (2, 3), (3, 0)])
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=np.array([1.0, 0.0, 2.0, 1.0]), c_dis=1.0, c_short=0.5, short_length=1.0)
    free = candidate_positions(xy, 2)  # equal candidate counts: all edges at once
    mixed = candidate_positions(xy, 2, fixed=[True, False, False, False])  # edge by edge
    for cands in (free, mixed):
        tables = edge_energy_tables(cands, edges, r, **kw)
        for k, (u, v) in enumerate(edges):
            ref = deviation_energy(cands[u], cands[v], r, cell=0.5)
            if kw["c_dir"][k]:
                ref = ref + kw["c_dir"][k] * direction_energy(cands[u], cands[v], cell=0.5, t_adjust=1.0)
            ref = ref + 0.5 * short_edge_energy(cands[u], cands[v], cell=0.5, short_length=1.0)
            np.testing.assert_array_equal(tables[k], ref)


def _random_graph(rng, n_vertices, n_edges, spread):
    xy = rng.uniform(0, spread, (n_vertices, 2))
    pairs = {tuple(sorted(p)) for p in rng.integers(0, n_vertices, (n_edges, 2)).tolist() if p[0] != p[1]}
    return xy, np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


@pytest.mark.parametrize("chunk", [None, 3000])
@pytest.mark.parametrize("seed", range(6))
def test_window_tables_are_bitwise_the_edge_by_edge_tables(seed, chunk, monkeypatch):
    """The shared-window path (tables over offset differences, edges sampled together,
    rows reordered after the BLAS sums, small chunks split by u's candidates) gives the
    very bytes of the edge-by-edge path."""
    import lidar2city.snake.energies as energies
    from lidar2city.snake.energies import _edge_tables_general, _window_layout

    if chunk:
        monkeypatch.setattr(energies, "_CHUNK", chunk)

    rng = np.random.default_rng(seed)
    xy, edges = _random_graph(rng, 9, 16, 25.0)
    xy[0] = xy[1] + [0.3, 0.2]  # a very short edge among the candidates
    edges = np.vstack([edges, [[0, 1]]])
    seg = np.stack([xy[edges[:, 0]], xy[edges[:, 1]]], axis=1)
    window = int(rng.integers(1, 4))
    cands = candidate_positions(xy, window)
    r = distance_raster(seg, margin=window + 2, subdivide=int(rng.choice([1, 2, 4])))
    c_dir = rng.choice([0.0, 1.0, 2.5], size=len(edges)) if seed % 2 else 1.0
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=c_dir, c_dis=float(rng.choice([0.5, 1.0])),
              c_short=float(rng.choice([0.0, 0.5])), short_length=1.0,
              step=float(rng.choice([1.0, 1.5, 2.0])))  # sparser samples too (the step snake's)
    assert _window_layout(cands, r) is not None
    got = edge_energy_tables(cands, edges, r, **kw)
    ref = _edge_tables_general(cands, edges, r, **kw)
    assert len(got) == len(ref)
    for a, b in zip(got, ref, strict=True):
        assert a.shape == b.shape and a.tobytes() == b.tobytes()


def test_window_tables_bitwise_on_a_large_raster_and_a_long_edge():
    # a raster above the sample budget stays int32; an edge long enough that its
    # candidates of u are sampled in chunks, as edge by edge
    from lidar2city.snake.energies import _SAMPLE_BUDGET, _edge_tables_general

    xy = np.array([[0.0, 0.0], [900.0, 4.0], [905.0, 300.0], [2.0, 301.0]])
    edges = np.array([(0, 1), (1, 2), (2, 3), (3, 0), (0, 2)])
    seg = np.stack([xy[edges[:, 0]], xy[edges[:, 1]]], axis=1)
    r = distance_raster(seg, margin=5, subdivide=2)
    assert r.dt.size > _SAMPLE_BUDGET
    cands = candidate_positions(xy, 3)
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=1.0, c_dis=1.0, c_short=0.25, short_length=1.0)
    for a, b in zip(edge_energy_tables(cands, edges, r, **kw), _edge_tables_general(cands, edges, r, **kw),
                    strict=True):
        assert a.tobytes() == b.tobytes()


def test_window_layout_needs_one_integer_window_everywhere():
    from lidar2city.snake.energies import _window_layout

    seg = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    r = distance_raster(seg, margin=4)
    xy = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert _window_layout(candidate_positions(xy, 2), r) is not None
    assert _window_layout(candidate_positions(xy, 2, fixed=[True, False]), r) is None
    odd = candidate_positions(xy, 1)
    assert _window_layout([odd[0], odd[1][::-1][:8]], r) is None  # not the same window


def test_sparser_deviation_samples_stay_close_and_exact_on_the_data():
    """Samples every 2 raster cells (the roof step snake's) instead of every cell: zero
    on the data still, and the integral within about a raster cell of distance x length
    of the dense one (the distance is 1-Lipschitz in raster cells)."""
    seg = np.array([[[0.0, 0.0], [12.0, 0.0]], [[12.0, 0.0], [12.0, 7.0]]])
    r = distance_raster(seg, margin=5)
    xy = np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 7.0]])
    edges = np.array([(0, 1), (1, 2)])
    cands = candidate_positions(xy, 2)
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=1.0, c_dis=1.0)
    dense = edge_energy_tables(cands, edges, r, **kw)
    sparse = edge_energy_tables(cands, edges, r, step=2.0, **kw)
    for a, b, (u, v) in zip(dense, sparse, edges, strict=True):
        assert a[0, 0] == 0.0 and b[0, 0] == 0.0  # the candidates on the data
        length = np.hypot(*(cands[v][None, :, :] - cands[u][:, None, :]).transpose(2, 0, 1)) * 0.5
        assert np.all(np.abs(a - b) <= length * 0.5 / r.scale + 1e-12)
        assert np.corrcoef(a.ravel(), b.ravel())[0, 1] > 0.99
    with pytest.raises(InputError):
        edge_energy_tables(cands, edges, r, step=0.0, **kw)


@pytest.mark.parametrize("seed", range(4))
def test_deviation_sums_do_not_depend_on_which_pairs_are_summed_together(seed):
    """The trapezoid sums of whole raster distances are exact integers rounded once:
    a pair's deviation is the same double whether computed among all of u's and v's
    candidates, among a few, or alone (not so with BLAS sums of weighted samples,
    whose rounding depends on a row's place in the matrix and on the CPU's kernels)."""
    rng = np.random.default_rng(seed)
    xy, edges = _random_graph(rng, 6, 10, 30.0)
    seg = np.stack([xy[edges[:, 0]], xy[edges[:, 1]]], axis=1)
    r = distance_raster(seg, margin=5)
    cands = candidate_positions(xy, 3)
    for u, v in edges:
        step = float(rng.choice([1.0, 2.0]))
        whole = deviation_energy(cands[u], cands[v], r, cell=0.5, step=step)
        # with the longest pair among them (it sets the number of samples)
        i, j = np.unravel_index(np.argmax(np.hypot(*(cands[v][None] - cands[u][:, None]).transpose(2, 0, 1))),
                                whole.shape)
        rows = np.append(rng.choice(len(cands[u]), 5, replace=False), i)
        part = deviation_energy(cands[u][rows], cands[v], r, cell=0.5, step=step)
        assert part.tobytes() == whole[rows].tobytes()
        k = int(rng.integers(len(cands[v])))
        pair = deviation_energy(cands[u][[i, i]], cands[v][[j, k]], r, cell=0.5, step=step)
        assert pair[0, 0] == whole[i, j] and pair[1, 1] == whole[i, k]


@pytest.mark.parametrize("seed", range(8))
def test_bounded_tables_are_exact_where_sampled_and_below_where_not(seed):
    """``bound=True``: the pairs paying the direction energy (weight > 0) keep only
    C_Dir E_Dir (+ C_Short E_Short), at most their true energy; every other entry is
    the very double of the whole table."""
    rng = np.random.default_rng(100 + seed)
    xy, edges = _random_graph(rng, 9, 16, 25.0)
    # edges near the axes too, whose pairs off the axis are bounded
    xy[1] = xy[0] + [rng.uniform(4, 12), rng.uniform(-0.6, 0.6)]
    xy[2] = xy[1] + [rng.uniform(-0.6, 0.6), rng.uniform(4, 12)]
    edges = np.unique(np.sort(np.vstack([edges, [[0, 1], [1, 2]]]), axis=1), axis=0)
    seg = np.stack([xy[edges[:, 0]], xy[edges[:, 1]]], axis=1)
    window = int(rng.integers(1, 4))
    cands = candidate_positions(xy, window)
    r = distance_raster(seg, margin=window + 2, subdivide=int(rng.choice([2, 4])))
    c_dir = rng.choice([0.0, 1.0, 2.5], size=len(edges)) if seed % 2 else 1.0
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=c_dir, c_dis=1.0, c_short=float(rng.choice([0.0, 0.5])),
              short_length=1.0, step=float(rng.choice([1.0, 2.0])))
    true = edge_energy_tables(cands, edges, r, **kw)
    tables, bounded = edge_energy_tables(cands, edges, r, bound=True, **kw)
    no_dev = edge_energy_tables(cands, edges, r, **{**kw, "c_dis": 0.0})
    weights = np.broadcast_to(np.asarray(c_dir, dtype=float), (len(edges),))
    n_bounded = 0
    for (u, v), w, t, b, m, z in zip(edges, weights, true, tables, bounded, no_dev, strict=True):
        assert m.shape == t.shape and b.shape == t.shape
        assert b[~m].tobytes() == t[~m].tobytes()
        assert np.all(b[m] <= t[m]) and b[m].tobytes() == z[m].tobytes()
        pays = (direction_energy(cands[u], cands[v], cell=0.5, t_adjust=1.0) > 0) & (w > 0)
        assert not np.any(m & ~pays)
        n_bounded += int(m.sum())
    assert n_bounded > 0


def test_bounded_tables_with_a_fixed_vertex_bound_nothing():
    xy = np.array([[0.0, 0.0], [10.0, 0.4], [10.2, 5.0]])
    edges = np.array([(0, 1), (1, 2)])
    seg = np.stack([xy[edges[:, 0]], xy[edges[:, 1]]], axis=1)
    r = distance_raster(seg, margin=4)
    cands = candidate_positions(xy, 2, fixed=[True, False, False])
    kw = dict(cell=0.5, t_adjust=1.0, c_dir=1.0, c_dis=1.0)
    tables, bounded = edge_energy_tables(cands, edges, r, bound=True, **kw)
    for t, b, m in zip(edge_energy_tables(cands, edges, r, **kw), tables, bounded, strict=True):
        assert not m.any() and t.tobytes() == b.tobytes()
