"""Batched triangulation of a solid's faces: the same triangles as face by face."""

from __future__ import annotations

import numpy as np

from lidar2city.lod.mesh import triangulate_polygon, triangulate_surfaces


def _faces(rng):
    """Rings of many kinds in 3-D: convex (fanned), non-convex, collinear vertices
    (a T-junction on a wall), degenerate and with holes."""
    verts, faces = [], []

    def add(pts2, tilt, holes=()):
        rot = np.linalg.qr(rng.normal(size=(3, 3)))[0] if tilt else np.eye(3)
        base = len(verts)
        rings, k = [], 0
        for ring in (pts2, *holes):
            p = np.column_stack([ring, np.zeros(len(ring))]) @ rot.T + rng.normal(size=3) * 50
            verts.extend(p)
            rings.append(np.arange(base + k, base + k + len(ring)))
            k += len(ring)
        faces.append(rings)

    for _ in range(40):
        k = int(rng.integers(3, 9))
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        add(np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(0.5, 20), rng.random() < 0.5)
    add(np.array([[0, 0], [1, 0], [2, 0], [2, 1], [0, 1]], float), True)  # collinear vertex
    add(np.array([[0, 0], [2, 0], [2, 2], [1, 0.5], [0, 2]], float), True)  # non-convex
    add(np.array([[0, 0], [1, 0], [2, 0]], float), False)  # zero area
    add(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)[::-1], True)  # clockwise
    add(np.array([[0, 0], [4, 0], [4, 4], [0, 4]], float), True,
        holes=(np.array([[1, 1], [1, 2], [2, 2], [2, 1]], float),))
    return np.array(verts), faces


def test_batched_triangulation_equals_face_by_face():
    rng = np.random.default_rng(7)
    verts, faces = _faces(rng)
    tris, face = triangulate_surfaces(verts, faces)
    want = [triangulate_polygon(verts, rings) for rings in faces]
    assert np.array_equal(tris, np.concatenate(want))
    assert np.array_equal(face, np.repeat(np.arange(len(faces)), [len(t) for t in want]))
    assert len(want[-3]) == 0 and len(want[-2]) == 2


def test_vertex_ids_exact_last_match_then_nearest():
    """CDT corners map back to the last of equal vertices, else to the first nearest one."""
    from lidar2city.lod.mesh import _vertex_ids

    p2 = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [-0.0, 0.0], [0.0, 1.0]])
    ids = np.array([10, 11, 12, 13, 14])
    q = np.array([[0.0, 0.0], [1.0, 1.0], [0.9, 0.1], [0.5, 1.0], [0.0, 1.0]])
    # (0, 0) twice (as 0.0 and -0.0): the later one; (0.5, 1) is as near 12 as 14: the first
    assert _vertex_ids(p2, ids, q).tolist() == [13, 12, 11, 12, 14]
