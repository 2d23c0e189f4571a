import numpy as np
import pytest

from lidar2city.metrics.wireframe import faces_wireframe, pooled_scores, roof_cleanliness, wireframe_scores


def square(z=0.0, size=4.0, mid=False):
    r = [(0, 0), (size, 0), (size, size), (0, size)]
    if mid:
        r.insert(1, (size / 2, 0))  # a straight-through vertex: not a corner
    return [[np.array([(x, y, z) for x, y in r], dtype=float)]]


def test_corners_and_edges_of_a_square():
    wf = faces_wireframe(square(mid=True))
    assert len(wf.corners) == 4
    assert len(wf.edges) == 4
    # the straight-through vertex splits the drawn ring: 5 segments
    assert len(wf.face_edge_lengths) == 5
    n, short, total = roof_cleanliness(wf, short=2.5)
    assert n == 4
    assert total == pytest.approx(16.0)
    assert short == pytest.approx(4.0)  # the two 2 m halves


def test_shared_edges_and_corners_counted_once():
    a = square()[0]
    b = [a[0] + [4.0, 0, 0]]
    wf = faces_wireframe([a, b])
    assert len(wf.corners) == 6
    assert len(wf.edges) == 7


def test_scores_exact_and_shifted():
    ref = faces_wireframe(square())
    assert wireframe_scores(ref, ref)["corner_f1"] == 1.0
    assert wireframe_scores(ref, ref)["edge_f1"] == 1.0
    near = faces_wireframe(square(z=0.3))
    s = wireframe_scores(near, ref, tolerance=0.5)
    assert s["corner_f1"] == 1.0 and s["edge_f1"] == 1.0
    far = faces_wireframe(square(z=0.6))
    s = wireframe_scores(far, ref, tolerance=0.5)
    assert s["corner_f1"] == 0.0 and s["edge_f1"] == 0.0


def test_nearby_corners_merge():
    # two faces meeting at a corner 3 cm apart in height are one corner
    a = square()[0][0]
    b = a - [0.0, 4.0, 0.0]
    b[2, 2] = 0.03  # (4, 0) of the lower face
    assert len(faces_wireframe([[a], [b]], merge=0).corners) == 7
    assert len(faces_wireframe([[a], [b]], merge=0.1).corners) == 6


def test_pooled_scores():
    p = pooled_scores({"corners_matched": 9, "corners_pred": 10, "corners_ref": 9,
                       "edges_matched": 0, "edges_pred": 0, "edges_ref": 3})
    assert p["corner_precision"] == pytest.approx(0.9)
    assert p["corner_recall"] == 1.0
    assert p["edge_f1"] == 0.0
