import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import Polygon

from lidar2city.roof.building import _direction, reconstruct_lod22
from lidar2city.roof.rooftype import ROOF_TYPES, classify_roof
from lidar2city.synthetic_roofs import ROOF_KINDS, roof_sample

EXPECTED = {"gable": "gable", "hip": "hip", "half_hip": "half_hip", "mansard": "mansard",
            "L": "cross_gable", "T": "cross_gable", "U": "cross_gable", "dormer": "gable",
            "stepped": "complex", "parapet": "flat"}


def test_every_kind_has_a_type():
    assert set(EXPECTED) == set(ROOF_KINDS)
    assert set(EXPECTED.values()) <= set(ROOF_TYPES)


@pytest.mark.parametrize("kind", ROOF_KINDS)
def test_true_faces_typed(kind):
    for seed in range(3):
        s = roof_sample(kind, density=8, seed=seed)
        assert classify_roof(s.faces, s.face_planes, _direction(s.footprint)) == EXPECTED[kind], seed


def _pyramid(side=10.0, slope=0.8, z0=5.0):
    h = side / 2
    c = (h, h)
    corners = [(0, 0), (side, 0), (side, side), (0, side)]
    faces, planes = [], []
    for (x0, y0), (x1, y1) in zip(corners, corners[1:] + corners[:1], strict=True):
        faces.append(Polygon([(x0, y0), (x1, y1), c]))
        # plane through the eave edge at z0, rising towards the centre
        mid = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        g = (np.array(c) - mid) / h * slope
        planes.append([g[0], g[1], z0 - g @ mid])
    return faces, np.array(planes)


def test_pyramid_and_rotation():
    faces, planes = _pyramid()
    assert classify_roof(faces, planes, 0.0) == "pyramid"
    # the same roof turned by 30 deg, with the building direction turned alike
    t = np.radians(30)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    turned = [affinity.rotate(f, 30, origin=(0, 0)) for f in faces]
    p2 = np.column_stack([planes[:, :2] @ R.T, planes[:, 2]])
    assert classify_roof(turned, p2, t) == "pyramid"


def test_noise_split_and_chimney_keep_a_gable():
    s = roof_sample("gable", density=8, seed=1)
    faces, planes = list(s.faces), np.array(s.face_planes)
    d = _direction(s.footprint)
    # one slope cut in two faces whose planes differ by a little noise
    big = int(np.argmax([f.area for f in faces]))
    c = faces[big].centroid
    cut = shapely.box(c.x - 1.5, c.y - 1.5, c.x + 1.5, c.y + 1.5)
    piece, rest = faces[big].intersection(cut), faces[big].difference(cut)
    faces[big] = rest
    faces.append(piece)
    planes = np.vstack([planes, planes[big] + [0.002, -0.002, 0.01]])
    # and a flat chimney top
    faces.append(cut.centroid.buffer(0.4, quad_segs=1))
    planes = np.vstack([planes, [0.0, 0.0, 20.0]])
    assert classify_roof(faces, planes, d) == "gable"


def test_flat_shed_and_bad_input():
    sq = shapely.box(0, 0, 8, 6)
    assert classify_roof([sq], [[0.0, 0.0, 7.0]], 0.0) == "flat"
    assert classify_roof([sq], [[0.3, 0.0, 7.0]], 0.0) == "shed"
    with pytest.raises(ValueError, match="planes"):
        classify_roof([sq], np.zeros((2, 3)), 0.0)
    with pytest.raises(ValueError, match="faces"):
        classify_roof([], np.zeros((0, 3)), 0.0)


@pytest.mark.parametrize("kind", ["gable", "hip", "mansard", "L", "parapet"])
def test_reconstructed_roofs_typed(kind):
    # at 25 pts/m2 the facet graph of these kinds is complete
    s = roof_sample(kind, density=25, seed=0)
    assert reconstruct_lod22(s.footprint, s.xyz, s.ground_z).attributes["roof_type"] == EXPECTED[kind]
