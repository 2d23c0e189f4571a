from collections import Counter

import numpy as np
import pytest
from shapely.geometry import Polygon, box

from lidar2city.errors import FitError
from lidar2city.roof.solid import partition_solid


def shell_errors(solid):
    """Every directed edge used once and its reverse once; positive volume."""
    edges = Counter()
    vol = 0.0
    V = solid.vertices
    for s in solid.surfaces:
        for ring in s.rings:
            r = list(ring)
            assert len(set(r)) == len(r)
            edges.update(zip(r, r[1:] + r[:1], strict=True))
            P = V[r]
            for k in range(1, len(P) - 1):
                vol += np.dot(P[0], np.cross(P[k], P[k + 1])) / 6
    bad = [e for e, n in edges.items() if n != 1 or edges.get((e[1], e[0]), 0) != 1]
    return bad, vol


def test_box_and_step():
    faces = [box(0, 0, 5, 4), box(5, 0, 10, 4)]
    planes = np.array([[0, 0, 3.0], [0, 0, 6.0]])
    s = partition_solid(faces, planes, 0.0)
    bad, vol = shell_errors(s)
    assert not bad
    assert vol == pytest.approx(5 * 4 * 3 + 5 * 4 * 6)
    kinds = Counter(x.semantic for x in s.surfaces)
    assert kinds["RoofSurface"] == 2 and kinds["GroundSurface"] == 1
    # 4 + 4 outer walls (the step wall is one more)
    assert kinds["WallSurface"] == 7


def test_gable_has_no_wall_on_the_ridge():
    faces = [box(0, 0, 10, 3), box(0, 3, 10, 6)]
    planes = np.array([[0, 1.0, 3.0], [0, -1.0, 9.0]])  # both 6 m at y = 3
    s = partition_solid(faces, planes, 0.0)
    bad, vol = shell_errors(s)
    assert not bad
    assert vol == pytest.approx(10 * 6 * 3 + 10 * 6 * 3 / 2)
    # no wall on the ridge: the 4 outer walls, the gable ends in one piece per roof face
    assert Counter(x.semantic for x in s.surfaces)["WallSurface"] == 6
    ridge_wall = [x for x in s.surfaces if x.semantic == "WallSurface"
                  and np.allclose(s.vertices[x.rings[0], 1], 3.0)]
    assert not ridge_wall


def test_crossing_planes_split_the_wall():
    faces = [box(0, 0, 10, 4), box(0, 4, 10, 8)]
    planes = np.array([[0.2, 0, 3.0], [-0.2, 0, 5.0]])  # cross at x = 5
    s = partition_solid(faces, planes, 0.0)
    bad, vol = shell_errors(s)
    assert not bad and vol > 0


def test_courtyard_and_below_floor():
    ring = Polygon(box(0, 0, 20, 20).exterior.coords, [box(8, 8, 12, 12).exterior.coords])
    s = partition_solid([ring], np.array([[0, 0, 5.0]]), 1.0)
    bad, vol = shell_errors(s)
    assert not bad and vol == pytest.approx((400 - 16) * 4)
    with pytest.raises(FitError, match="below the floor"):
        partition_solid([box(0, 0, 5, 5)], np.array([[1.0, 0, -2.0]]), 0.0)


def _cut_saddle(faces, planes):
    """The one saddle at (5, 5) found, cut out, and the cut partition's solid checked valid."""
    from lidar2city.roof.building import _nonmanifold_points
    from lidar2city.roof.solid import split_saddles
    from lidar2city.validate.solid import check_solid

    bad = _nonmanifold_points(partition_solid(faces, planes, 0.0))
    assert len(bad) and np.allclose(bad, [[5, 5]])
    cut = split_saddles(faces, bad)
    s = partition_solid(cut, planes, 0.0)
    assert not len(_nonmanifold_points(s)) and not shell_errors(s)[0] and not check_solid(s)
    return cut, s


def test_saddle_vertex_is_cut_out():
    # four roof parts meeting at one vertex, high and low alternating around it (the
    # ISPRS CSite4 station roof has dozens): four walls share one vertical edge
    faces = [box(0, 0, 5, 5), box(5, 0, 10, 5), box(5, 5, 10, 10), box(0, 5, 5, 10)]
    planes = np.array([[0, 0, 6.0], [0, 0, 3.0], [0, 0, 6.0], [0, 0, 4.0]])
    cut, s = _cut_saddle(faces, planes)
    # the largest (first of equals) took the patch; nothing moved farther than 5 cm
    assert cut[0].area > 25
    assert sum(f.area for f in cut) == pytest.approx(100)
    assert all(f.symmetric_difference(g).area < 0.01 for f, g in zip(cut, faces, strict=True))
    assert shell_errors(s)[1] == pytest.approx(25 * (6 + 3 + 6 + 4), abs=0.02)


def test_saddle_on_the_outline_is_notched():
    # two parts touching only at one vertex, the outside on one side and a courtyard on the
    # other, joined around the courtyard by two strips
    faces = [box(0, 0, 5, 5), box(5, 5, 10, 10), box(-3, 0, 0, 13), box(0, 10, 10, 13)]
    planes = np.array([[0, 0, 6.0], [0, 0, 4.0], [0, 0, 5.0], [0, 0, 5.0]])
    cut, _ = _cut_saddle(faces, planes)
    assert cut[0].area + cut[1].area == pytest.approx(50 - 0.05**2, abs=1e-6)
    assert cut[0].distance(cut[1]) > 0.05
    assert cut[2].equals(faces[2]) and cut[3].equals(faces[3])


def test_manifold_solid_keeps_planes_when_relabelling_gives_up():
    from lidar2city.roof.building import _manifold_solid
    from lidar2city.validate.solid import check_solid

    faces = [box(0, 0, 5, 5), box(5, 0, 10, 5), box(5, 5, 10, 10), box(0, 5, 5, 10)]
    planes = np.array([[0, 0, 6.0], [0, 0, 3.0], [0, 0, 6.0], [0, 0, 4.0]])
    s, relabelled = _manifold_solid(faces, np.arange(4), planes, 0.0, 0.1, max_rounds=0)
    assert relabelled == 0 and not check_solid(s)
    roofs = sorted({round(float(z), 3) for z in s.vertices[:, 2]} - {0.0})
    assert roofs == [3.0, 4.0, 6.0]


def test_level_sets_are_the_group_means_of_each_vertex():
    """All vertices' height levels at once equal sorting, splitting and averaging each
    vertex's heights on its own (bit for bit, long groups included)."""
    from lidar2city.roof.solid import _level_sets

    rng = np.random.default_rng(5)
    levels = {}
    for k in range(300):
        n = int(rng.integers(1, 14))
        base = rng.choice([0.0, 3.0, 7.5], n) + rng.normal(0, 0.003, n)
        levels[(k, -k)] = list(base) + ([1.0] * 9 if k % 50 == 0 else [])
    got = _level_sets(levels, 5e-3)
    assert list(got) == list(levels)
    for k, zs in levels.items():
        zs = np.sort(np.asarray(zs))
        want = [g.mean() for g in np.split(zs, np.flatnonzero(np.diff(zs) > 5e-3) + 1)]
        assert np.array_equal(got[k], np.array(want))
