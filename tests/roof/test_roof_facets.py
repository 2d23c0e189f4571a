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


def test_smallest_eigenpairs_match_eigh():
    from lidar2city.roof.facets import _smallest_eigenpairs

    rng = np.random.default_rng(7)
    # roof-like neighbourhoods (flat, tilted, noisy), lines, single points, random matrices
    pts = rng.normal(0.0, 1.0, (500, 10, 3)) * np.array([1.0, 0.7, 0.01])
    pts[100:200] *= np.array([1.0, 1e-9, 1.0])  # lines: a double smallest eigenvalue
    pts[200:210] = 0.0  # one point: a zero matrix
    rot = np.linalg.qr(rng.normal(size=(500, 3, 3)))[0]
    pts = np.einsum("nij,nkj->nki", rot, pts)
    c = pts - pts.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", c, c) / 10
    w, v = np.linalg.eigh(cov)
    lam, vec = _smallest_eigenpairs(cov[:, 0, 0], cov[:, 0, 1], cov[:, 0, 2], cov[:, 1, 1],
                                    cov[:, 1, 2], cov[:, 2, 2])
    assert np.all(np.abs(lam - w[:, 0]) <= 1e-11 * np.maximum(w[:, 2], 1e-300))
    np.testing.assert_allclose(np.linalg.norm(vec, axis=1), 1.0)
    # an eigenvector of the smallest eigenvalue: A v = lam v
    np.testing.assert_allclose(np.einsum("nij,nj->ni", cov, vec), lam[:, None] * vec, atol=1e-9)
    well = (w[:, 1] - w[:, 0]) > 1e-6 * w[:, 2]
    assert well[:100].all()
    np.testing.assert_allclose(np.abs(np.einsum("ni,ni->n", vec[well], v[well, :, 0])), 1.0, atol=1e-9)


def test_refit_of_changed_facets_only_is_a_full_refit():
    from lidar2city.roof.facets import _group_planes, _refit, fit_plane

    rng = np.random.default_rng(3)
    n = 400
    xyz = rng.uniform(0, 10, (n, 3))
    xyz[:, 2] = 0.3 * xyz[:, 0] - 0.1 * xyz[:, 1] + rng.normal(0, 0.3, n)  # outliers to trim
    labels = rng.integers(-1, 6, n)
    full = _refit(xyz, labels, 6, 0.2)
    # facets 0 and 1 merged, facet 4 loses its points to -1, the others unchanged
    after = np.where(labels == 1, 0, np.where(labels >= 2, labels - 1, labels))
    after[after == 3] = -1
    again = _refit(xyz, after, 5, 0.2, (labels, full))
    np.testing.assert_array_equal(again, _refit(xyz, after, 5, 0.2))
    np.testing.assert_array_equal(again[1], full[2])
    # one group's plane is fit_plane's, to rounding
    a, b, c, ok = _group_planes(xyz[:, 0], xyz[:, 1], xyz[:, 2], np.maximum(labels, 0), 6)
    for k in range(6):
        p = fit_plane(xyz[np.maximum(labels, 0) == k])
        np.testing.assert_allclose([a[k], b[k], c[k]], p, rtol=1e-9, atol=1e-9)
