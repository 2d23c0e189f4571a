"""refine_partition: vertices onto plane intersections, faces with holes, rings as given."""

import numpy as np
import pytest
import shapely

from lidar2city.roof.arrangement import _flat_rings
from lidar2city.roof.refine import refine_partition


def _gable(jag):
    """Two faces of a gable roof over a 10 x 6 box whose shared boundary wanders off the
    ridge (y = 3) by ``jag`` m at its middle vertex: planes z = 5 + 0.5 y and z = 8 - 0.5 y."""
    south = shapely.Polygon([(0, 0), (10, 0), (10, 3), (5, 3 + jag), (0, 3)])
    north = shapely.Polygon([(0, 3), (5, 3 + jag), (10, 3), (10, 6), (0, 6)])
    planes = np.array([[0.0, 0.5, 5.0], [0.0, -0.5, 8.0]])
    return [south, north], np.array([0, 1]), planes


def test_a_wandering_ridge_is_moved_onto_the_planes_intersection():
    faces, labels, planes = _gable(0.4)
    out, info = refine_partition(faces, labels, planes, t_step=0.3, max_shift=1.0)
    assert info["intersection"] == 1 and not info["fallback"] and info["moved"] >= 1
    xy = shapely.get_coordinates(shapely.intersection(out[0].boundary, out[1].boundary))
    assert np.allclose(xy[:, 1], 3.0)  # every shared vertex on the ridge line
    assert sum(f.area for f in out) == pytest.approx(60.0)
    assert shapely.union_all(out).equals(shapely.box(0, 0, 10, 6))


def test_a_face_with_a_hole_keeps_it_and_the_partition_still_tiles():
    # a flat roof with a box standing in a hole of it, beside a gable pair: the hole's
    # ring goes through the refinement with the exterior rings of every face
    faces, labels, planes = _gable(0.4)
    outer = shapely.box(10, 0, 16, 6)
    box = shapely.box(12, 2, 14, 4)
    faces = faces + [outer.difference(box), box]
    labels = np.array([0, 1, 2, 3])
    planes = np.vstack([planes, [[0.0, 0.0, 4.0], [0.0, 0.0, 9.0]]])
    out, info = refine_partition(faces, labels, planes, t_step=0.3, max_shift=1.0)
    assert not info["fallback"]
    assert len(out) == 4 and len(out[2].interiors) == 1
    assert out[2].area == pytest.approx(32.0) and out[3].area == pytest.approx(4.0)
    assert shapely.union_all(out).area == pytest.approx(96.0)


def test_flat_rings_are_each_faces_rings_in_order():
    # what refine_partition reads the faces with: every ring (exterior, then holes in
    # order) without its closing vertex, the same doubles as the rings' own coordinates
    rng = np.random.default_rng(3)
    faces = []
    for k in range(12):
        shell = shapely.Point(rng.uniform(0, 50, 2)).buffer(rng.uniform(3, 6), quad_segs=int(rng.integers(1, 5)))
        holes = [shapely.Point(np.asarray(shell.centroid.coords[0]) + (dx, 0)).buffer(0.7, quad_segs=2)
                 for dx in (-1.5, 1.5)[:k % 3]]
        faces.append(shell.difference(shapely.union_all(holes)) if holes else shell)
    xy, owner, sizes = _flat_rings(faces)
    want = [(i, np.asarray(r.coords)[:-1]) for i, f in enumerate(faces) for r in [f.exterior, *f.interiors]]
    assert owner.tolist() == [i for i, _ in want]
    assert sizes.tolist() == [len(c) for _, c in want]
    assert np.array_equal(xy, np.concatenate([c for _, c in want]))
