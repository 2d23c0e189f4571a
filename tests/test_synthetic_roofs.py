import numpy as np
import pytest
import shapely

from lidar2city.synthetic_roofs import ROOF_KINDS, roof_sample


@pytest.mark.parametrize("kind", ROOF_KINDS)
def test_faces_tile_the_footprint(kind):
    s = roof_sample(kind, density=4, seed=1)
    assert sum(f.area for f in s.faces) == pytest.approx(s.footprint.area, rel=1e-6)
    assert shapely.union_all(s.faces).symmetric_difference(s.footprint).area < 1e-6 * s.footprint.area
    assert len(s.faces) == len(s.face_planes)
    assert len(s.wireframe.corners) >= 4


def test_known_wireframes():
    gable = roof_sample("gable", density=4, seed=0)
    assert len(gable.faces) == 2
    assert (len(gable.wireframe.corners), len(gable.wireframe.edges)) == (6, 7)
    hip = roof_sample("hip", density=4, seed=0)
    assert len(hip.faces) == 4
    assert (len(hip.wireframe.corners), len(hip.wireframe.edges)) == (6, 9)
    mansard = roof_sample("mansard", density=4, seed=0)
    assert len(mansard.faces) == 8


def test_points_on_the_roof_within_noise():
    s = roof_sample("L", density=10, seed=3)
    z = np.full(len(s.xyz), np.nan)
    for f, pl in zip(s.faces, s.face_planes, strict=True):
        m = shapely.contains_xy(f, s.xyz[:, 0], s.xyz[:, 1])
        z[m] = s.xyz[m, :2] @ pl[:2] + pl[2]
    ok = ~np.isnan(z)
    assert ok.mean() > 0.99
    assert np.std(s.xyz[ok, 2] - z[ok]) < 0.06
    assert len(s.xyz) == pytest.approx(10 * s.footprint.area, rel=0.1)


def test_deterministic():
    a, b = roof_sample("dormer", seed=5), roof_sample("dormer", seed=5)
    assert np.array_equal(a.xyz, b.xyz)
    assert not np.array_equal(a.xyz[:10], roof_sample("dormer", seed=6).xyz[:10])


def test_bad_kind():
    with pytest.raises(ValueError, match="kind"):
        roof_sample("dome")
