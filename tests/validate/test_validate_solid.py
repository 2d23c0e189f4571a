import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import MultiPoint, box

from lidar2city.datamodel import Solid, Surface
from lidar2city.lod.prism import clean_polygon, prism_solid
from lidar2city.validate import check_solid, parts_overlap, solid_error_codes


def cube():
    return prism_solid(box(0, 0, 1, 1), 0.0, 1.0)


def replace_surface(s, i, rings):
    surfaces = list(s.surfaces)
    surfaces[i] = Surface(rings, surfaces[i].semantic)
    return Solid(s.vertices, surfaces)


def test_cube_is_valid():
    assert check_solid(cube()) == []


def test_vertex_index_out_of_range_names_each_face():
    s = cube()
    n = len(s.vertices)
    bad = replace_surface(replace_surface(s, 2, [np.array([0, 1, n])]), 4, [np.array([-1, 0, 1])])
    issues = check_solid(bad)
    assert [(i.code, i.surface) for i in issues] == [(901, 2), (901, 4)]


def test_flipped_face_is_wrongly_oriented():
    s = cube()
    flipped = replace_surface(s, 3, [s.surfaces[3].rings[0][::-1]])
    assert solid_error_codes(flipped) == [307]


def test_all_faces_flipped_is_wrongly_oriented():
    s = cube()
    inv = Solid(s.vertices, [Surface([r[::-1] for r in f.rings], f.semantic) for f in s.surfaces])
    assert solid_error_codes(inv) == [307]


def test_removed_face_is_not_closed():
    s = cube()
    assert solid_error_codes(Solid(s.vertices, s.surfaces[:-1])) == [302]


def test_non_planar_face():
    s = cube()
    v = s.vertices.copy()
    v[s.surfaces[1].rings[0][0], 2] += 0.1  # lift one roof corner: roof and two walls bend
    codes = solid_error_codes(Solid(v, s.surfaces))
    assert codes == [203]
    # within the tolerance it passes
    v = s.vertices.copy()
    v[s.surfaces[1].rings[0][0], 2] += 0.004
    assert solid_error_codes(Solid(v, s.surfaces)) == []


def test_degenerate_faces():
    s = cube()
    r = s.surfaces[1].rings[0]
    assert solid_error_codes(replace_surface(s, 1, [np.r_[r, r[-1]]])) == [102]
    assert solid_error_codes(replace_surface(s, 1, [r[:2]])) == [101]
    bow = r[[0, 2, 1, 3]]  # bow tie ring
    assert 104 in solid_error_codes(replace_surface(s, 1, [bow]))


def test_inner_ring_checks():
    # roof with a hole outside its outer ring
    s = prism_solid(box(0, 0, 4, 4), 0.0, 2.0)
    v = np.vstack([s.vertices, [[10, 10, 2], [10, 11, 2], [11, 11, 2]]])
    n = len(s.vertices)
    roof = s.surfaces[1].rings[0]
    bad = replace_surface(Solid(v, s.surfaces), 1, [roof, np.array([n, n + 1, n + 2])])
    assert 206 in solid_error_codes(bad)


def test_non_manifold_edge():
    s = cube()
    extra = Surface([s.surfaces[2].rings[0][::-1]], "WallSurface")
    assert 303 in solid_error_codes(Solid(s.vertices, [*s.surfaces, extra, extra]))


def _triangulated(s):
    from lidar2city.lod.mesh import solid_mesh

    tris, face = solid_mesh(s)
    return Solid(s.vertices, [Surface([t], s.surfaces[f].semantic) for t, f in zip(tris, face, strict=True)])


def test_self_intersecting_shell():
    tri = _triangulated(cube())
    assert check_solid(tri) == []
    # push a roof corner through the floor: still closed, manifold and consistently
    # oriented, but roof triangles now cross floor triangles
    v = tri.vertices.copy()
    i = np.flatnonzero((v == [1, 1, 1]).all(axis=1))[0]
    v[i] = [0.5, 0.5, -1.0]
    assert solid_error_codes(Solid(v, tri.surfaces)) == [306]
    # two closed boxes in one shell
    a, b = prism_solid(box(0, 0, 2, 2), 0, 2), prism_solid(box(1, 1, 3, 3), 0, 2)
    joined = Solid(np.vstack([a.vertices, b.vertices]),
                   a.surfaces + [Surface([r + 8 for r in f.rings], f.semantic) for f in b.surfaces])
    assert 305 in solid_error_codes(joined)


@pytest.mark.parametrize("origin", [(0.0, 0.0, 0.0), (0.0, 1e6, 0.0), (1e7, 1e7, 0.0),
                                    (84880.0, -552520.0, 0.0), (-1e6, 3.3, 500.0)])
def test_checks_do_not_depend_on_where_the_solid_lies(origin):
    """A stray return moved reconstruct's local origin 1000 km off, and its crossing
    tolerance, scaled by the largest coordinate, grew to 1 mm: a roof crossing a wall by
    0.4 mm passed reconstruct's check and failed validate's (306), which works near the
    model. The same solid must get the same verdict wherever it is."""
    tri = _triangulated(cube())
    v = tri.vertices.copy()
    i = np.flatnonzero((v == [1, 1, 1]).all(axis=1))[0]
    v[i] = [0.5, 0.5, -4e-4]  # the roof corner 0.4 mm through the floor
    assert solid_error_codes(Solid(v + np.array(origin), tri.surfaces)) == [306]
    assert check_solid(Solid(tri.vertices + np.array(origin), tri.surfaces)) == []


def test_coplanar_overlapping_faces_are_found():
    from lidar2city.lod.mesh import triangulate_surfaces
    from lidar2city.validate.solid import _self_intersections

    v = np.array([[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1],
                  [1, 1, 1], [3, 1, 1], [3, 3, 1], [1, 3, 1],
                  [2, 0, 1.0], [4, 0, 1], [4, 2, 1]], dtype=float)
    overlapping = [[np.array([0, 1, 2, 3])], [np.array([4, 5, 6, 7])]]
    touching = [[np.array([0, 1, 2, 3])], [np.array([1, 9, 10, 2])]]
    for rings, expected in ((overlapping, [(0, 1)]), (touching, [])):
        mesh = triangulate_surfaces(v, rings)
        assert _self_intersections(v, rings, 0.001, mesh) == expected


def test_parts_overlap():
    a, b, c = (prism_solid(box(0, 0, 2, 2), 0, 3), prism_solid(box(2, 0, 4, 2), 0, 5),
               prism_solid(box(1, 1, 3, 3), 0, 4))
    assert parts_overlap([a, b]) == []
    assert parts_overlap([a, b, c]) == [(0, 2), (1, 2)]


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 100), st.floats(0, 100)), min_size=3, max_size=30),
       st.floats(-10, 10), st.floats(0.5, 50))
def test_prisms_of_random_polygons_are_valid(points, z0, h):
    poly = MultiPoint(points).convex_hull.buffer(-0.1).buffer(0.1)
    if poly.geom_type != "Polygon" or poly.area < 1:
        return
    # a non-convex footprint: carve a notch
    x0, y0, x1, y1 = poly.bounds
    notched = poly.difference(box((x0 + x1) / 2, y0 - 1, x1 + 1, (y0 + y1) / 2))
    for part in clean_polygon(notched, grid=0.001):
        if part.area < 0.01:
            continue
        s = prism_solid(part, z0, z0 + h, grid=0.001)
        assert check_solid(s) == [], part.wkt


@pytest.mark.parametrize("long_boxes", [False, True])
def test_candidate_pairs_are_every_pair_of_meeting_boxes_once(long_boxes):
    """The sweep and the R-tree (boxes overlapping along x by the hundred, as a hall's cap
    triangles) both give exactly the pairs of boxes meeting within tol, each once."""
    from lidar2city.validate.solid import _candidate_pairs

    rng = np.random.default_rng(3)
    n = 600
    lo = rng.uniform(0, 100, (n, 3)).round(1)
    size = rng.uniform(0, 3, (n, 3)).round(1)
    if long_boxes:  # spanning the whole x range: the sweep would meet every pair
        size[:, 0] = 100.0
    hi = lo + size
    tol = 0.1
    i, j = _candidate_pairs(lo, hi, tol)
    got = sorted(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist(), strict=True))
    meet = np.all((lo[:, None] <= hi[None] + tol) & (lo[None] <= hi[:, None] + tol), axis=2)
    want = [(a, b) for a, b in zip(*np.nonzero(np.triu(meet, 1)), strict=True)]
    assert got == [(int(a), int(b)) for a, b in want] and len(got) > 0


def _faces_checks_by_count(verts, rings_per_face, faces, planarity_tolerance):
    """The single-ring face checks as they were, one pass per vertex count (a reference)."""
    import shapely

    from lidar2city.lod.mesh import dot3, plane_bases
    from lidar2city.validate.solid import Issue

    issues = []
    by_len = {}
    for f in faces:
        by_len.setdefault(len(rings_per_face[f][0]), []).append(f)
    for k, group in sorted(by_len.items()):
        group = np.array(group)
        P = verts[np.stack([rings_per_face[f][0] for f in group])]
        bad = np.zeros(len(group), dtype=bool)
        if k > 3:
            c = P.mean(axis=1, keepdims=True)
            vt = np.linalg.svd(P - c, full_matrices=False)[2]
            dist = np.abs(dot3(P - c, vt[:, None, -1, :])).max(axis=1)
            for f in np.flatnonzero(dist > planarity_tolerance):
                issues.append(Issue(203, int(group[f]), f"vertex {dist[f]:.4f} m from the plane"))
                bad[f] = True
        Q = np.concatenate([P[:, 1:], P[:, :1]], axis=1)
        nw = np.stack([np.sum((P[..., 1] - Q[..., 1]) * (P[..., 2] + Q[..., 2]), axis=1),
                       np.sum((P[..., 2] - Q[..., 2]) * (P[..., 0] + Q[..., 0]), axis=1),
                       np.sum((P[..., 0] - Q[..., 0]) * (P[..., 1] + Q[..., 1]), axis=1)], axis=1)
        for f in np.flatnonzero(~bad & (np.sqrt(dot3(nw, nw)) < 1e-10)):
            issues.append(Issue(104, int(group[f]), "ring collapses to a line (zero area)"))
            bad[f] = True
        if k > 3 and (~bad).any():
            u, v = plane_bases(nw[~bad])
            P2 = np.stack([dot3(P[~bad], u[:, None, :]), dot3(P[~bad], v[:, None, :])], axis=-1)
            for f in np.flatnonzero(~bad)[~shapely.is_simple(shapely.linearrings(P2))]:
                issues.append(Issue(104, int(group[f]), "ring self-intersects"))
    return issues


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_one_pass_face_checks_give_the_per_count_issues(seed):
    """Faces of 3 to 9 vertices, some bent out of their plane by up to 5 cm, some folded
    onto a line, some with two vertices swapped (a bow tie): the one-pass checks (with
    their planarity shortcut) find the issues, in the order, of a pass per vertex count."""
    from lidar2city.validate.solid import _simple_faces_checks

    rng = np.random.default_rng(seed)
    verts, rings = [], []
    for _ in range(rng.integers(1, 25)):
        k = int(rng.integers(3, 10))
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        p = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(k)]) * rng.uniform(0.5, 20)
        kind = rng.integers(0, 4)
        if kind == 1:
            p[:, 2] += rng.uniform(-0.05, 0.05, k)   # bent: planar or not near the tolerance
        elif kind == 2:
            p[:, 1] = 0.0                            # folded onto a line
        elif kind == 3 and k > 3:
            p[[0, 2]] = p[[2, 0]]                    # a bow tie
        axis = rng.normal(size=(3, 3))
        rot = np.linalg.qr(axis)[0]
        p = p @ rot.T + rng.uniform(-100, 100, 3)
        rings.append([np.arange(len(verts) * 0 + sum(len(r[0]) for r in rings),
                                sum(len(r[0]) for r in rings) + k)])
        verts.append(p)
    verts = np.vstack(verts)
    faces = list(range(len(rings)))
    got = []
    _simple_faces_checks(verts, rings, faces, got, 0.01)
    assert [str(i) for i in got] == [str(i) for i in _faces_checks_by_count(verts, rings, faces, 0.01)]


@pytest.mark.parametrize("width", [0.05, 0.7, 3.0, 1000.0])
def test_strip_pairs_are_every_pair_of_meeting_boxes_once(width):
    """Strips of any width (boxes across many strips, ends on strip borders, equal lower
    corners, degenerate boxes) give exactly the pairs of boxes meeting within tol."""
    from lidar2city.validate.solid import _strip_pairs

    rng = np.random.default_rng(5)
    n = 400
    lo = rng.uniform(0, 20, (n, 3)).round(1)
    size = rng.uniform(0, 2, (n, 3)).round(1)
    size[::7, 0] = 20.0  # long along x
    size[::11] = 0.0  # points
    lo[::13] = lo[0]  # the same lower corner
    hi = lo + size
    tol = 0.1
    i, j = _strip_pairs(lo, hi, tol, width)
    got = sorted(zip(np.minimum(i, j).tolist(), np.maximum(i, j).tolist(), strict=True))
    meet = np.all((lo[:, None] <= hi[None] + tol) & (lo[None] <= hi[:, None] + tol), axis=2)
    want = [(int(a), int(b)) for a, b in zip(*np.nonzero(np.triu(meet, 1)), strict=True)]
    assert got == want and len(got) > 0


def test_a_solid_checked_again_gets_the_same_verdict_without_the_work(monkeypatch):
    """The verdict of a solid with the same vertices, rings and options as one checked a
    moment ago is that one's; another vertex, ring or option is checked anew."""
    from lidar2city.validate import solid as validate

    s = prism_solid(box(0, 0, 4, 3), 0.0, 2.0)
    calls = []
    real = validate._check_solid

    def counted(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(validate, "_check_solid", counted)
    validate._CHECKED.clear()
    assert check_solid(s) == [] and len(calls) == 1
    assert check_solid(Solid(s.vertices.copy(), list(s.surfaces))) == [] and len(calls) == 1
    bent = s.vertices.copy()
    bent[0, 2] += 0.5  # a floor corner lifted: faces no longer planar
    got = check_solid(Solid(bent, s.surfaces))
    assert got and got == check_solid(Solid(bent.copy(), s.surfaces)) and len(calls) == 2
    assert check_solid(Solid(bent, s.surfaces), planarity_tolerance=1.0) != got
    assert len(calls) == 3
    flipped = [Surface([f.rings[0][::-1].copy()], f.semantic) if i == 0 else f
               for i, f in enumerate(s.surfaces)]
    assert check_solid(Solid(s.vertices, flipped)) and len(calls) == 4
