import numpy as np
import pytest
import shapely

from lidar2city.roof.facets import Plane, segment_planes
from lidar2city.synthetic import make_town


@pytest.fixture(scope="module")
def town():
    return make_town(density=8, seed=0)


def _roof_points(town, b):
    xyz = town.cloud.xyz
    c = town.cloud.get("classification")
    m = (c == 6) & shapely.contains_xy(b.footprint, xyz[:, 0], xyz[:, 1])
    return xyz[m]


def test_plane_from_points_exact_and_falsy():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (50, 2))
    xyz = np.column_stack([xy, 0.5 * xy[:, 0] - 0.2 * xy[:, 1] + 3])
    p = Plane.from_points(xyz)
    assert p and np.allclose(p.params, [0.5, -0.2, 3])
    assert np.allclose(p.residuals(xyz), 0, atol=1e-9)
    bad = Plane.from_points(xyz[:2])
    assert not bad and "too few" in bad.reason
    line = np.column_stack([np.arange(5.0), np.arange(5.0), np.zeros(5)])
    assert not Plane.from_points(line)


def test_segment_planes_recovers_truth(town):
    for b in town.buildings:
        pts = _roof_points(town, b)
        labels, planes = segment_planes(pts)
        truth = np.vstack([p.planes for p in b.parts])
        truth = np.unique(truth, axis=0)
        assert len(planes) == len(truth), b.roof_type
        # every true plane has a found plane with close slope and height
        for t in truth:
            nt = np.array([-t[0], -t[1], 1]) / np.linalg.norm([t[0], t[1], 1])
            best = max(planes, key=lambda p: abs(np.dot(nt, np.array([-p[0], -p[1], 1]) /
                                                           np.linalg.norm([p[0], p[1], 1]))))
            nb = np.array([-best[0], -best[1], 1]) / np.linalg.norm([best[0], best[1], 1])
            assert np.degrees(np.arccos(min(1, abs(nt @ nb)))) < 2.0
        assert (labels >= 0).mean() > 0.9


def test_segment_planes_joins_apart_pieces_of_one_plane():
    """Two rim strips on one plane with a lower roof between them end as one facet; at a
    different height they stay two."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 10, (900, 2))
    strip = (xy[:, 0] < 0.8) | (xy[:, 0] > 9.2)
    z = np.where(strip, 8.0, 7.0) + rng.normal(0, 0.03, len(xy))
    labels, planes = segment_planes(np.column_stack([xy, z]))
    assert len(np.unique(labels[strip & (labels >= 0)])) == 1
    z2 = np.where(xy[:, 0] > 9.2, 8.6, z)
    labels, _ = segment_planes(np.column_stack([xy, z2]))
    assert len(np.unique(labels[strip & (labels >= 0)])) == 2
