import numpy as np
import pytest
import shapely

from lidar2city.errors import FitError
from lidar2city.metrics.wireframe import roof_wireframe, wireframe_scores
from lidar2city.roof.arrangement import (
    _mixed_runs,
    arrangement_cells,
    chain_segments,
    collapse_short_edges,
    dissolve_cells,
    drop_collinear,
    extend_to_hits,
    restore_facets,
    snake_steps,
)
from lidar2city.roof.building import Lod22Config, reconstruct_lod22
from lidar2city.synthetic_roofs import roof_sample
from lidar2city.validate.solid import check_solid

SQ = shapely.box(0, 0, 10, 10)


def test_cells_tile_and_dangles_vanish():
    cells = arrangement_cells(SQ, [np.array([[-1, 5], [11, 5]]), np.array([[5, 5], [5, 8]])])
    assert len(cells) == 2  # the dangling piece cuts nothing
    assert sum(c.area for c in cells) == pytest.approx(100)


def test_extend_to_hits_closes_a_cell():
    short = [np.array([[2.0, 5.0], [8.0, 5.0]])]
    assert len(arrangement_cells(SQ, short)) == 1
    ext = extend_to_hits(short, SQ, max_ext=20)
    assert ext[0][0, 0] < 0 and ext[0][-1, 0] > 10
    assert len(arrangement_cells(SQ, ext)) == 2


def _first_hits_by_every_line(segments, footprint, max_ext, eps=1e-3):
    """extend_to_hits by brute force: each end's whole ray cut with every line by GEOS."""
    from shapely.geometry import LineString

    lines = [LineString(r.coords) for r in shapely.get_rings(footprint)]
    lines += [LineString(s) for s in segments if len(s) >= 2]
    out = [np.array(s, dtype=float) for s in segments]
    for k, s in enumerate(segments):
        if np.allclose(s[0], s[-1]):
            continue
        for i, j in ((0, 1), (-1, -2)):
            d = (s[i] - s[j]) / np.hypot(*(s[i] - s[j]))
            ray = LineString([s[i] + d * 1e-6, s[i] + d * max_ext])
            pts = [shapely.get_coordinates(ray.intersection(line)) for line in lines]
            pts = np.concatenate(pts) if pts else np.zeros((0, 2))
            if len(pts):
                out[k][i] = s[i] + d * (((pts - s[i]) @ d).min() + eps)
    return out


@pytest.mark.parametrize("max_ext", [75.0, 30.0])  # rays found in rounds; in one round
@pytest.mark.parametrize("seed", range(6))
def test_extend_to_hits_first_hit_as_by_every_line(seed, max_ext):
    # random chains in a 60 m block (most rays cross many lines; some meet none, some
    # run along a line): the first hit of each ray as when cut with every whole line
    rng = np.random.default_rng(seed)
    block = shapely.Polygon([(0, 0), (60, 0), (60, 25), (35, 25), (35, 40), (0, 40)])
    segs = []
    for _ in range(40):
        a = rng.uniform([0, 0], [60, 40])
        steps = rng.normal(0, 3, size=(rng.integers(1, 4), 2))
        if rng.random() < 0.3:
            steps[:, 1] = 0.0  # axis-parallel: rays along other chains and the outline
        segs.append(np.vstack([a, a + np.cumsum(steps, axis=0)]))
    segs.append(np.array([[10.0, 10.0], [20.0, 10.0]]))
    segs.append(np.array([[22.0, 10.0], [30.0, 10.0]]))  # on the line of the one before
    got = extend_to_hits(segs, block, max_ext=max_ext)
    want = _first_hits_by_every_line(segs, block, max_ext)
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_allclose(g, w, rtol=0, atol=1e-9)
    assert np.array_equal(got[-2][-1], [22.001, 10.0])  # stops at the next chain's end


def test_extend_to_hits_a_far_hit_near_the_start_does_not_hide_a_nearer_one():
    # the long diagonal piece's box meets the ray's first metres but crosses it at x = 18.5;
    # the short upright piece, away from them, crosses it first, at x = 16
    segs = [np.array([[5.0, 5.0], [12.0, 5.0]]), np.array([[13.5, 5.5], [23.5, 4.5]]),
            np.array([[16.0, 4.0], [16.0, 6.0]])]
    got = extend_to_hits(segs, shapely.box(0, 0, 40, 10), max_ext=40.0)
    np.testing.assert_allclose(got[0][-1], [16.001, 5.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[0][0], [-0.001, 5.0], rtol=0, atol=1e-12)


def test_dissolve_merges_labels_small_and_empty_cells():
    lines = [np.array([[-1, y], [11, y]]) for y in (3, 6)] + [np.array([[5, -1], [5, 11]])]
    cells = arrangement_cells(SQ, lines)
    assert len(cells) == 6
    labels = np.array([0 if c.centroid.y < 6 else 1 for c in cells])
    faces, lab = dissolve_cells(cells, labels)
    assert sorted(lab.tolist()) == [0, 1]
    # a straight boundary: the merged faces are rectangles (4 vertices each)
    assert all(len(f.exterior.coords) == 5 for f in faces)
    labels[0] = -1
    faces, lab = dissolve_cells(cells, labels)
    assert (lab >= 0).all() and sum(f.area for f in faces) == pytest.approx(100)


def test_drop_collinear_keeps_junctions():
    a = shapely.Polygon([(0, 0), (5, 0), (5, 5), (5, 10), (0, 10)])
    b = shapely.Polygon([(5, 0), (10, 0), (10, 5), (5, 5)])
    c = shapely.Polygon([(5, 5), (10, 5), (10, 10), (5, 10)])
    out = drop_collinear([a, b, c])
    # (5, 5) is straight in a but a corner of b and c: kept everywhere
    assert len(out[0].exterior.coords) == 6


def test_collapse_short_edges():
    a = shapely.Polygon([(0, 0), (5, 0), (5.2, 10), (0, 10)])
    b = shapely.Polygon([(5, 0), (10, 0), (10, 10), (5.2, 10)])
    c = shapely.Polygon([(0, 0), (5, 0), (4.9, 4.9), (5.1, 5.0), (5.2, 10), (0, 10)])
    d = shapely.Polygon([(5, 0), (10, 0), (10, 10), (5.2, 10), (5.1, 5.0), (4.9, 4.9)])
    fp = shapely.box(0, 0, 10, 10)
    out, kept = collapse_short_edges([a, b], fp, min_length=0.5)
    assert len(out) == 2  # the 0.2 m outline pieces are between footprint corners' neighbours
    out, kept = collapse_short_edges([c, d], fp, min_length=0.5)
    assert all(len(f.exterior.coords) == 6 for f in out)
    assert sum(f.area for f in out) == pytest.approx(100)


def _wall_then_valley(step=0.4):
    # planes z = 0.6 y + 5 (a main slope) and z = -0.7 x + 12 (a dormer's): they meet on
    # 0.7 x + 0.6 y = 7; the chain climbs a side wall at x = 5 up to that line, then follows it
    wall = np.column_stack([np.full(15, 5.0), np.arange(15) * step])
    xs = 5.0 - (np.arange(1, 9) * step)
    valley = np.column_stack([xs, (7 - 0.7 * xs) / 0.6])
    planes = np.array([[0.0, 0.6, 5.0], [-0.7, 0.0, 12.0]])
    return np.vstack([wall, valley]), planes


def test_mixed_chain_gives_a_wall_and_a_valley():
    chain, planes = _wall_then_valley()
    dz = chain @ (planes[0, :2] - planes[1, :2]) + planes[0, 2] - planes[1, 2]
    g = planes[0, :2] - planes[1, :2]
    dist = np.abs(dz) / np.hypot(*g)
    runs = _mixed_runs(chain, dz, dist, 0.3, 0.6, 0.8)
    assert [k for k, _ in runs] == ["step", "intersection"]
    assert np.allclose(runs[0][1][-1], runs[1][1][0])  # the pieces share their vertex
    segs, kinds = chain_segments([chain], [(0, 1)], planes, cell=0.4, direction=0.0, max_shift=5.0)
    assert kinds == ["step", "intersection"]
    assert np.allclose(segs[0][1:-1, 0], 5.0)  # the wall stays at x = 5 ...
    on_line = segs[1] @ g + planes[0, 2] - planes[1, 2]
    assert np.allclose(on_line, 0, atol=1e-9)  # ... and the valley is the exact line
    # a chain that is only a staircase along the line stays one intersection edge
    jag = chain[15:] + np.array([[0.1, 0.0], [-0.1, 0.0]] * 4)
    dzj = jag @ g + planes[0, 2] - planes[1, 2]
    assert _mixed_runs(jag, dzj, np.abs(dzj) / np.hypot(*g), 0.3, 0.6, 0.8) is None


def test_dormer_side_walls_kept_at_8_points():
    # the dormers' side walls survive the refinement as vertical steps (they used to be
    # pulled onto the valley line, leaving triangular dormers)
    s = roof_sample("dormer", density=8, seed=2)
    res = reconstruct_lod22(s.footprint, s.xyz, s.ground_z)
    sc = wireframe_scores(roof_wireframe(res.solids), s.wireframe, tolerance=0.5)
    assert sc["corners_matched"] >= 20, sc


@pytest.mark.parametrize("kind", ["gable", "hip", "L", "stepped"])
def test_exact_wireframes_on_clean_roofs(kind):
    s = roof_sample(kind, density=25, seed=0)
    res = reconstruct_lod22(s.footprint, s.xyz, s.ground_z)
    assert all(not check_solid(x) for x in res.solids)
    sc = wireframe_scores(roof_wireframe(res.solids), s.wireframe, tolerance=0.5)
    assert sc["corner_f1"] >= 0.9
    assert sc["edge_f1"] >= 0.85


def test_grid_topology_still_available():
    s = roof_sample("hip", density=8, seed=0)
    res = reconstruct_lod22(s.footprint, s.xyz, 0.0, config=Lod22Config(topology="grid"))
    assert all(not check_solid(x) for x in res.solids)


def test_deterministic():
    s = roof_sample("T", density=8, seed=2)
    a = reconstruct_lod22(s.footprint, s.xyz, 0.0).solids[0]
    b = reconstruct_lod22(s.footprint, s.xyz, 0.0).solids[0]
    assert np.array_equal(a.vertices, b.vertices)
    assert [list(map(list, x.rings)) for x in a.surfaces] == [list(map(list, x.rings)) for x in b.surfaces]


@pytest.mark.parametrize(("fp", "pts", "reason"), [
    (SQ, np.array([[5.0, 5.0, 8.0]]), "too few points"),
    (SQ, np.column_stack([np.linspace(0, 10, 50), np.linspace(0, 10, 50), np.full(50, 8.0)]), "one line"),
    (shapely.box(0, 0, 0.1, 0.1), np.array([[0.05, 0.05, 8], [0.02, 0.03, 8.1], [0.08, 0.01, 8.05]]),
     "smaller than one label cell"),
])
def test_bad_input_gives_a_reason(fp, pts, reason):
    with pytest.raises(FitError, match=reason):
        reconstruct_lod22(fp, pts, 0.0)


def test_bad_topology_option():
    from lidar2city.errors import ConfigError

    with pytest.raises(ConfigError, match="lod22.topology"):
        Lod22Config(topology="magic")


def _dissolve_by_passes(cells, labels, *, min_area=0.0, weights=None, min_width=0.0):
    """The reference: one merge per pass over every cell (components from scipy)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from lidar2city.roof.arrangement import _adjacency

    n = len(cells)
    labels = np.asarray(labels, dtype=np.int64).copy()
    area = shapely.area(np.asarray(cells, dtype=object))
    length = shapely.length(np.asarray(cells, dtype=object))
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=float)
    adj = _adjacency(cells)

    def components():
        same = np.array([e for e in adj if labels[e[0]] == labels[e[1]]], dtype=np.int64).reshape(-1, 2)
        g = coo_matrix((np.ones(len(same)), (same[:, 0], same[:, 1])), shape=(n, n))
        return connected_components(g, directed=False)[1]

    while True:
        comp = components()
        n_comp = comp.max() + 1
        c_area = np.bincount(comp, weights=area, minlength=n_comp)
        c_w = np.bincount(comp, weights=w, minlength=n_comp)
        c_lab = np.zeros(n_comp, dtype=np.int64)
        c_lab[comp] = labels
        inner = np.zeros(n_comp)
        for (i, j), L in adj.items():
            if comp[i] == comp[j]:
                inner[comp[i]] += 2 * L
        perim = np.bincount(comp, weights=length, minlength=n_comp) - inner
        bad = (c_area < min_area) | (c_w <= 0) | (c_lab < 0)
        if min_width > 0:
            bad |= 2 * c_area < min_width * perim
        merged = False
        for c in np.lexsort((np.arange(n_comp), c_lab >= 0, c_area)):
            if not bad[c]:
                continue
            shared = {}
            for (i, j), L in adj.items():
                for a, b in ((i, j), (j, i)):
                    if comp[a] == c and comp[b] != c:
                        shared[comp[b]] = shared.get(comp[b], 0.0) + L
            cand = [(L, -k) for k, L in shared.items() if c_lab[k] >= 0 or c_lab[c] < 0]
            if cand:
                labels[comp == c] = c_lab[-max(cand)[1]]
                merged = True
                break
        if not merged:
            return [shapely.union_all([cells[i] for i in np.flatnonzero(comp == c)])
                    for c in range(n_comp)], c_lab


def test_dissolve_matches_one_merge_per_pass():
    """The heap / union-find dissolve gives the faces of merging the smallest bad face
    one pass at a time, whatever the labels, weights and thresholds."""
    rng = np.random.default_rng(11)
    for k in range(80):
        # every other case on a half-metre grid: faces of equal area, so the tie rules count
        step = (lambda m: rng.integers(1, 3, m) * 0.5) if k % 2 else (lambda m: rng.uniform(0.2, 2.0, m))
        xs = np.cumsum(np.r_[0, step(int(rng.integers(2, 8)))])
        ys = np.cumsum(np.r_[0, step(int(rng.integers(2, 8)))])
        cells = [shapely.box(x0, y0, x1, y1) for x0, x1 in zip(xs, xs[1:]) for y0, y1 in zip(ys, ys[1:])]
        labels = rng.integers(-1, 3, len(cells))
        weights = np.where(rng.random(len(cells)) < 0.2, 0.0, rng.integers(1, 50, len(cells)))
        kw = dict(min_area=float(rng.uniform(0, 3)), weights=weights,
                  min_width=float(rng.choice([0.0, rng.uniform(0, 1.5)])))
        faces, face_labels = dissolve_cells(cells, labels, **kw)
        ref, ref_labels = _dissolve_by_passes(cells, labels, **kw)
        assert len(faces) == len(ref)
        for f, lab, g, ref_lab in zip(faces, face_labels, ref, ref_labels, strict=True):
            assert lab == ref_lab
            assert f.symmetric_difference(g).area < 1e-9


def _parapet_roof(neighbour=False, spacing=0.35, seed=0):
    """A 10 m x 10 m flat roof at 6 m with a 0.3 m rim at 7 m along its north edge (points
    labelled 0 on the roof, unlabelled on the rim); with ``neighbour``, a roof at 7 m
    continuing north of the outline (a taller neighbour reaching over it)."""
    rng = np.random.default_rng(seed)
    g = np.arange(spacing / 2, 10, spacing)
    x, y = (a.ravel() for a in np.meshgrid(g, np.arange(spacing / 2, 10.5, spacing)))
    z = np.where(y > 9.7, 7.0, 6.0) + rng.normal(0, 0.03, len(x))
    keep = y < (10.5 if neighbour else 10.0)
    xyz = np.column_stack([x, y, z])[keep]
    labels = np.where(xyz[:, 1] > 9.7, -1, 0)
    return xyz, labels, np.array([[0.0, 0.0, 6.0]])


def test_rim_strips_finds_a_parapet_not_a_neighbours_roof():
    from lidar2city.roof.arrangement import rim_strips

    xyz, labels, planes = _parapet_roof()
    rims = rim_strips(SQ, xyz, labels, planes, cell=0.35)
    assert len(rims) == 1
    z0, members, line, width, own = rims[0]
    assert z0 == pytest.approx(7.0, abs=0.05) and own == -1
    assert np.all(xyz[members, 1] > 9.7)
    assert np.allclose(line[:, 1], 10 - width) and 0.17 <= width <= 0.6
    # the same points continuing outside at the rim's height: a neighbour's roof, not a rim
    xyz, labels, planes = _parapet_roof(neighbour=True)
    labels[xyz[:, 1] > 10] = -1
    assert rim_strips(SQ, xyz, labels, planes, cell=0.35) == []
    # a roof rising to the edge is no rim: its top points are on its plane
    xyz, labels, _ = _parapet_roof()
    xyz[:, 2] = 6.0 + 0.5 * xyz[:, 1]
    assert rim_strips(SQ, xyz, np.zeros(len(xyz), dtype=int), np.array([[0.0, 0.5, 6.0]]), cell=0.35) == []


def test_parapet_rim_becomes_a_face():
    xyz, _, _ = _parapet_roof()
    res = reconstruct_lod22(SQ, xyz, 0.0)
    assert not check_solid(res.solids[0])
    tops = [np.asarray(s.rings[0]) for s in res.solids[0].surfaces if s.semantic == "RoofSurface"]
    z = [res.solids[0].vertices[r][:, 2].mean() for r in tops]
    assert min(z) == pytest.approx(6.0, abs=0.05) and max(z) == pytest.approx(7.0, abs=0.05)


def _rot(xy, deg):
    a = np.radians(deg)
    return np.asarray(xy, dtype=float) @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])


# the label grid's staircase (cell 0.5) of a 2.5 m wall at v = 2.25 along the building's
# u axis: the grid puts it at v = 2.0 on one half and 2.5 on the other, so its own line
# leans by ~13 deg, past the 10 deg angle snap
STAIR = [[0, 2.0], [0.5, 2.0], [1.0, 2.0], [1.0, 2.5], [1.5, 2.5], [2.0, 2.5], [2.5, 2.5]]
LEVELS = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, 6.0]])


@pytest.mark.parametrize("deg", [0.0, 20.0])
def test_step_snake_makes_a_short_wall_straight_on_the_axis(deg):
    chain = _rot(STAIR, deg)
    segs, kinds = chain_segments([chain], [(0, 1)], LEVELS, cell=0.5, direction=np.radians(deg),
                                 snap_angle=10.0, step_snake=True)
    assert kinds == ["step"]
    uv = _rot(segs[0], -deg)
    assert len(uv) == 2  # one straight piece
    assert abs(uv[1, 1] - uv[0, 1]) < 1e-6  # parallel to the building direction
    assert abs(uv[0, 1] - 2.25) <= 0.3  # on the wall, within about half a cell
    assert uv[:, 0].min() <= 0.0 and uv[:, 0].max() >= 2.5  # spans the chain


def test_step_snake_joins_chains_at_their_junction():
    # two walls meeting at a corner of the grid (an L between three levels): one graph
    a = np.array([[0, 2.0], [1.0, 2.0], [1.0, 2.5], [3.0, 2.5], [3.0, 2.0], [4.0, 2.0]])
    b = np.array([[4.0, 2.0], [4.0, 3.0], [4.5, 3.0], [4.5, 5.0], [4.0, 5.0], [4.0, 6.0]])
    out = snake_steps([a, b], [False, False], cell=0.5, direction=0.0)
    for poly, axis in zip(out, (1, 0), strict=True):
        assert poly is not None and len(poly) == 2
        assert abs(poly[1, axis] - poly[0, axis]) < 1e-6  # on the building axes


def test_step_snake_skips_a_solve_beyond_its_work_limit():
    out = snake_steps([np.array(STAIR, dtype=float)], [False], cell=0.5, direction=0.0, max_work=1.0)
    assert out == [None]  # the caller keeps its split-and-merge pieces


def test_step_snake_roofs_valid_and_deterministic():
    s = roof_sample("stepped", density=8, seed=1)
    cfg = Lod22Config(step_snake=True)
    a = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=cfg)
    b = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=cfg)
    assert all(not check_solid(x) for x in a.solids)
    assert np.array_equal(a.solids[0].vertices, b.solids[0].vertices)
    sc = wireframe_scores(roof_wireframe(a.solids), s.wireframe, tolerance=0.5)
    assert sc["corner_f1"] >= 0.9


def _lost_facet_roof(block=(4.0, 4.0, 6.5, 6.0), height=1.0, spacing=0.3, outside_z=None):
    """A flat 10 x 10 m roof at 5 m, points every ``spacing``, with a level block ``height``
    above it (facet 1) that the single face does not carry; ``outside_z``: points just
    outside the footprint (a neighbour's roof) at that height."""
    g = np.arange(-0.45, 10.46, spacing)
    xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    x0, y0, x1, y1 = block
    on = (xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)
    out = ~shapely.contains_xy(SQ, xy[:, 0], xy[:, 1])
    z = np.where(on, 5.0 + height, 5.0)
    if outside_z is not None:
        z = np.where(out & (np.abs(xy[:, 1] - (y0 + y1) / 2) < (y1 - y0) / 2), outside_z, z)
    labels = np.where(on, 1, 0)
    planes = np.array([[0.0, 0.0, 5.0], [0.0, 0.0, 5.0 + height]])
    return np.column_stack([xy, z]), labels, planes


def test_restore_facets_cuts_a_lost_block_back_in():
    xyz, labels, planes = _lost_facet_roof()
    faces, face_labels, n = restore_facets([SQ], [0], SQ, xyz, labels, planes, direction=0.0, spacing=0.3)
    assert n == 1 and sorted(face_labels.tolist()) == [0, 1]
    block = faces[int(np.flatnonzero(face_labels == 1)[0])]
    # the rectangle of the block's points (4.05-6.45 x 4.05-5.85) grown by half a spacing
    assert block.equals_exact(shapely.normalize(shapely.box(3.9, 3.9, 6.6, 6.0)), 1e-9)
    assert sum(f.area for f in faces) == pytest.approx(100)
    assert shapely.union_all(faces).area == pytest.approx(100)


@pytest.mark.parametrize("case", ["small", "on_the_face", "strip", "neighbour"])
def test_restore_facets_leaves_what_is_no_lost_facet(case):
    kw = {"small": {"block": (4.0, 4.0, 4.7, 4.7)},  # under 1 m2 of points
          "on_the_face": {"height": 0.2},  # within T_step of the face over it
          "strip": {"block": (-0.1, 3.0, 0.5, 8.0)},  # a 0.6 m strip along the outline
          "neighbour": {"block": (8.0, 4.0, 10.1, 6.0), "outside_z": 6.0}}[case]
    xyz, labels, planes = _lost_facet_roof(**kw)
    faces, face_labels, n = restore_facets([SQ], [0], SQ, xyz, labels, planes, direction=0.0, spacing=0.3)
    assert n == 0 and face_labels.tolist() == [0] and faces[0].equals(SQ)


def test_restored_block_makes_a_valid_better_roof():
    # a 1.5 x 1.5 m block on a roof whose label grid has 1 m cells: the partition's
    # smallest face (4 cells) drops it, the restoration cuts it back in (raised parts off:
    # they would cut the block in as a level rectangle without the restoration)
    xyz, _, _ = _lost_facet_roof(block=(4.0, 4.0, 5.5, 5.5))
    on = reconstruct_lod22(SQ, xyz, 0.0, config=Lod22Config(cell=1.0, raised_parts=False))
    off = reconstruct_lod22(SQ, xyz, 0.0, config=Lod22Config(cell=1.0, restore=False, raised_parts=False))
    assert not check_solid(on.solids[0]) and not check_solid(off.solids[0])
    assert (off.attributes["roof_planes"], on.attributes["roof_planes"]) == (1, 2)
    from lidar2city.lod.mesh import solid_triangles
    from lidar2city.metrics.model import point_mesh_distance, rmse

    inside = xyz[shapely.contains_xy(SQ, xyz[:, 0], xyz[:, 1])]
    e_on, e_off = (rmse(point_mesh_distance(inside, solid_triangles(r.solids))) for r in (on, off))
    assert e_on < 0.05 < e_off


def test_roof_lines_shared_by_the_partitions_with_and_without_rims():
    """The boundary lines computed once (:func:`roof_lines`) give each partition what it
    computes by itself, and the partition with rims does not add its rim lines to them."""
    from lidar2city.roof.arrangement import arrangement_partition, roof_lines

    xyz, labels, planes = _parapet_roof()
    # a second level on the south half, so there are inner boundary lines to share
    south = xyz[:, 1] < 5.0
    xyz[south, 2] += 1.5
    labels[south] = 1
    planes = np.vstack([planes, [[0.0, 0.0, 7.5]]])
    kw = dict(cell=0.35, direction=0.0, step_snake=True)
    lines = roof_lines(SQ, xyz, labels, planes, **kw)
    assert lines[1] and set(lines[1]) <= {"step", "intersection"}
    before = ([s.copy() for s in lines[0]], list(lines[1]))
    for rims in (True, False):
        own = arrangement_partition(SQ, xyz, labels, planes, rims=rims, **kw)
        shared = arrangement_partition(SQ, xyz, labels, planes, rims=rims, lines=lines, **kw)
        assert ("rim" in own[2]) == rims and own[2] == shared[2]
        np.testing.assert_array_equal(own[1], shared[1])
        np.testing.assert_array_equal(own[3], shared[3])
        assert [f.wkb for f in own[0]] == [f.wkb for f in shared[0]]
    assert lines[1] == before[1]
    assert all(np.array_equal(a, b) for a, b in zip(lines[0], before[0], strict=True))


def test_raised_parts_cut_a_chimney_in():
    """A 0.8 x 0.8 m chimney 1.5 m above a flat roof (too small for a facet): one level
    rectangle at its height around its points, grown by half a spacing."""
    from lidar2city.roof.arrangement import raised_parts

    xyz, _, _ = _lost_facet_roof(block=(4.0, 4.0, 4.8, 4.8), height=1.5)
    faces, labels, planes, n = raised_parts([SQ], [0], SQ, xyz, np.array([[0.0, 0.0, 5.0]]), direction=0.0,
                                            spacing=0.3)
    assert n == 1 and sorted(labels.tolist()) == [0, 1]
    np.testing.assert_allclose(planes[1], [0.0, 0.0, 6.5])
    chimney = faces[int(np.flatnonzero(labels == 1)[0])]
    # its points run 4.05-4.65 in x and y
    assert chimney.equals_exact(shapely.normalize(shapely.box(3.9, 3.9, 4.8, 4.8)), 1e-9)
    assert shapely.union_all(faces).area == pytest.approx(100) and sum(f.area for f in faces) == pytest.approx(100)


@pytest.mark.parametrize("case", ["low", "neighbour", "single", "strip"])
def test_raised_parts_leave_what_is_no_raised_part(case):
    from lidar2city.roof.arrangement import raised_parts

    kw = {"low": {"block": (4.0, 4.0, 4.8, 4.8), "height": 0.2},  # within T_step of the roof
          "neighbour": {"block": (9.0, 4.0, 10.1, 6.0), "outside_z": 6.5, "height": 1.5},  # goes on outside
          "single": {"block": (4.0, 4.0, 4.2, 4.2), "height": 1.5},  # one point: no cluster
          "strip": {"block": (2.0, 4.0, 8.0, 4.5), "height": 1.0}}[case]  # 6 x 0.5 m: a wall's top
    xyz, _, _ = _lost_facet_roof(**kw)
    faces, labels, planes, n = raised_parts([SQ], [0], SQ, xyz, np.array([[0.0, 0.0, 5.0]]), direction=0.0,
                                            spacing=0.3)
    assert n == 0 and labels.tolist() == [0] and faces[0].equals(SQ) and len(planes) == 1


def test_raised_parts_option_makes_a_valid_better_roof():
    from lidar2city.lod.mesh import solid_triangles
    from lidar2city.metrics.model import point_mesh_distance, rmse

    # a 0.6 x 0.6 m chimney (9 points, under 1 m2: no facet comes back for it)
    xyz, _, _ = _lost_facet_roof(block=(4.0, 4.0, 4.7, 4.7), height=1.5)
    on = reconstruct_lod22(SQ, xyz, 0.0, config=Lod22Config(cell=1.0, raised_parts=True))
    off = reconstruct_lod22(SQ, xyz, 0.0, config=Lod22Config(cell=1.0, raised_parts=False))
    assert not check_solid(on.solids[0]) and not check_solid(off.solids[0])
    assert (off.attributes["roof_planes"], on.attributes["roof_planes"]) == (1, 2)
    inside = xyz[shapely.contains_xy(SQ, xyz[:, 0], xyz[:, 1])]
    e_on, e_off = (rmse(point_mesh_distance(inside, solid_triangles(r.solids))) for r in (on, off))
    assert e_on < 0.05 < e_off
    # a plain roof has nothing to cut in: the same solid with the option
    xyz, _, _ = _lost_facet_roof(height=0.0)
    a = reconstruct_lod22(SQ, xyz, 0.0, config=Lod22Config(raised_parts=True))
    b = reconstruct_lod22(SQ, xyz, 0.0)
    assert np.array_equal(a.solids[0].vertices, b.solids[0].vertices)


def test_a_rim_facets_face_off_the_strip_is_no_rim():
    from shapely.geometry import box

    from lidar2city.roof.arrangement import _on_rims

    # faces: the rim strip (label 2), a small patch of the rim facet's label far from the
    # strip (label 2 too), a roof face (label 0)
    faces = [box(0, 9.7, 10, 10), box(4, 4, 4.5, 4.5), box(0, 0, 10, 9.7).difference(box(4, 4, 4.5, 4.5))]
    labels = np.array([2, 2, 0])
    strip = [box(x, 9.7, x + 1, 10) for x in range(10)]
    assert _on_rims(faces, labels, [2], strip).tolist() == [True, False, False]
    # without rim cells every face of a rim label counts (nothing to tell them apart)
    assert _on_rims(faces, labels, [2], []).tolist() == [True, True, False]


def test_straighten_outline_drops_jogs_below_tolerance_only():
    from lidar2city.roof.building import straighten_outline

    # a 10 x 6 m footprint with a 0.15 m jog in its long side and a 1 m deep notch
    poly = shapely.Polygon([(0, 0), (5, 0), (5, 0.15), (10, 0.15), (10, 6), (6, 6), (6, 5), (4, 5), (4, 6),
                            (0, 6)])
    out = straighten_outline(poly, 0.3)
    assert out.is_valid and len(out.interiors) == 0
    # the jog's two corners go, the notch's four stay
    assert len(out.exterior.coords) == len(poly.exterior.coords) - 2
    assert out.hausdorff_distance(poly) <= 0.3
    assert shapely.Point(4, 5).intersects(out.boundary) and shapely.Point(6, 5).intersects(out.boundary)
    # the jog's corners lie 0.075 m off the chord that replaces them: a smaller tolerance keeps them
    assert straighten_outline(poly, 0.05).equals(poly)


def test_straightened_outline_keeps_the_roof_valid_and_close():
    # the jogged footprint over a flat roof at 5 m: a valid solid, its points as close
    rng = np.random.default_rng(3)
    poly = shapely.Polygon([(0, 0), (5, 0), (5, 0.15), (10, 0.15), (10, 6), (0, 6)])
    xy = rng.uniform((0, 0), (10, 6), size=(1500, 2))
    xyz = np.column_stack([xy, 5.0 + rng.normal(0, 0.03, len(xy))])
    xyz = xyz[shapely.contains_xy(poly, xyz[:, 0], xyz[:, 1])]
    given = reconstruct_lod22(poly, xyz, 0.0, config=Lod22Config(outline_tolerance=0.0))
    straight = reconstruct_lod22(poly, xyz, 0.0, config=Lod22Config(outline_tolerance=1.0))
    assert not check_solid(straight.solids[0]) and not check_solid(given.solids[0])
    from lidar2city.metrics.wireframe import roof_cleanliness, roof_wireframe

    assert roof_cleanliness(roof_wireframe(straight.solids))[0] == 4 < roof_cleanliness(roof_wireframe(given.solids))[0]


@pytest.mark.parametrize("seed", range(5))
def test_near_chain_is_the_kd_tree_ball_query(seed):
    """The chain's neighbour points by brute force in its box are those of a k-d tree's
    ball query at every chain vertex, filtered to the two facets, in ascending order."""
    from scipy.spatial import cKDTree

    from lidar2city.roof.arrangement import _near_chain

    rng = np.random.default_rng(seed)
    xyz = np.column_stack([rng.uniform(0, 20, (3000, 2)), rng.uniform(0, 5, 3000)])
    xyz[:50, :2] = np.round(xyz[:50, :2] * 2) / 2  # points exactly on the grid the chain is on
    lab = rng.integers(-1, 4, 3000)
    chain = np.cumsum(rng.choice([-0.5, 0.0, 0.5], (int(rng.integers(1, 60)), 2)), axis=0) + 10.0
    tree = cKDTree(xyz[:, :2])
    for radius in (0.5, 1.0, 1.5, 3.0):
        ref = np.unique(np.concatenate(tree.query_ball_point(chain, radius)).astype(np.int64))
        ref = ref[(lab[ref] == 1) | (lab[ref] == 2)]
        for block in (1, 7, 256):
            got = _near_chain(xyz, lab, chain, 1, 2, radius, block=block)
            assert got.dtype == np.int64 and np.array_equal(got, ref)
    assert len(_near_chain(xyz, lab, np.zeros((0, 2)), 1, 2, 1.0)) == 0
