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


def test_solid_mesh_of_a_moved_vertex_is_the_mesh_anew():
    """A solid sharing its surfaces with one meshed before, a few vertices moved (as
    nudge_on_grid moves one): only the surfaces using them are triangulated again, and the
    mesh is the one of the whole solid triangulated anew; rings changed in place, many
    vertices moved or other surfaces: the whole solid is triangulated."""
    from lidar2city.datamodel import Solid, Surface
    from lidar2city.lod import mesh
    from lidar2city.lod.mesh import solid_mesh

    rng = np.random.default_rng(11)
    verts, faces = _faces(rng)
    surfaces = [Surface([np.asarray(r, dtype=np.int64) for r in rings], "RoofSurface")
                for rings in faces]
    first = Solid(verts, surfaces)
    assert all(np.array_equal(a, b) for a, b in zip(
        solid_mesh(first), triangulate_surfaces(verts, surfaces), strict=True))
    calls = []
    real = mesh.triangulate_surfaces

    def counting(v, s):
        calls.append(len(s))
        return real(v, s)

    mesh.triangulate_surfaces = counting
    try:
        for moved_rows in ([5], [5, 6], [len(verts) - 3], [0, 40, 100]):
            moved = verts.copy()
            moved[moved_rows, :2] += rng.normal(size=(len(moved_rows), 2)) * 0.3
            s = Solid(moved, surfaces)
            got = solid_mesh(s)
            want = real(moved, surfaces)
            assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
            # the surfaces of the vertices moved since the last solid meshed only
            assert calls[-1] <= 4 < len(surfaces)
        same = solid_mesh(Solid(verts.copy(), surfaces))  # nothing moved: the mesh kept
        assert all(np.array_equal(a, b) for a, b in zip(same, real(verts, surfaces), strict=True))
        n = len(calls)
        solid_mesh(Solid(verts + 0.5, surfaces))  # every vertex moved: all again
        assert calls[n:] == [len(surfaces)]
        # a ring reversed in place (the list is the same object): not reused
        surfaces[3].rings[0] = surfaces[3].rings[0][::-1].copy()
        moved = verts.copy()
        moved[1] += 0.1
        got = solid_mesh(Solid(moved, surfaces))
        assert calls[-1] == len(surfaces)
        assert all(np.array_equal(a, b) for a, b in zip(got, real(moved, surfaces), strict=True))
    finally:
        mesh.triangulate_surfaces = real
