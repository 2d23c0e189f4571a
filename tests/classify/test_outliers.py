"""Stray returns far from the survey (:func:`lidar2city.classify.outliers.far_points`)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.classify.outliers import far_points


def _survey(n=4000, size=200.0, seed=0):
    return np.random.default_rng(seed).uniform(0, size, (n, 2))


def test_far_points_are_found_and_nothing_else():
    xy = _survey()
    strays = np.array([[1e6, 50.0], [100.0, -2e5], [-3e4, -3e4]])
    far = far_points(np.vstack([xy, strays]))
    assert np.flatnonzero(far).tolist() == [4000, 4001, 4002]


def test_a_survey_alone_or_a_clump_beside_it_is_left_alone():
    xy = _survey()
    assert not far_points(xy).any()
    # a clump 150 m off a 200 m survey: it does not blow the extent up
    beside = np.vstack([xy, [[350.0, 10.0], [351.0, 11.0]]])
    assert not far_points(beside).any()
    # two large parts apart (a survey across a wide river): neither is stray
    two = np.vstack([xy, _survey(seed=1) + [5000.0, 0.0]])
    assert not far_points(two).any()


def test_far_points_is_translation_invariant():
    xy = np.vstack([_survey(), [[8e4, 0.0]]])
    a = far_points(xy)
    b = far_points(xy + [1e7, -3e6])
    assert np.array_equal(a, b) and a[-1]


def _far_points_reference(xy, gap=100.0, max_points=100, spread=2.0):
    """far_points' rule written plainly: cells' 8-neighbour clumps by brute force."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    lo = xy.min(axis=0)
    ij = np.floor((xy - lo) / gap).astype(np.int64)
    cells, inverse = np.unique(ij, axis=0, return_inverse=True)
    if np.ptp(ij, axis=0).max() + 1 <= 2:
        return np.zeros(len(xy), dtype=bool)
    near = np.abs(cells[:, None, :] - cells[None, :, :]).max(axis=2) <= 1
    a, b = np.nonzero(near)
    _, comp = connected_components(coo_matrix((np.ones(len(a)), (a, b)),
                                              shape=(len(cells),) * 2), directed=False)
    clump = comp[inverse.reshape(-1)]
    sizes = np.bincount(clump)
    # the survey: the largest clump, the first in raster order on a tie
    first = np.full(len(sizes), len(cells))
    np.minimum.at(first, comp, np.arange(len(cells)))
    survey = min(range(len(sizes)), key=lambda c: (-sizes[c], first[c]))
    small = (sizes[clump] <= max_points) & (clump != survey)
    if not small.any():
        return np.zeros(len(xy), dtype=bool)
    kept = xy[~small]
    if np.any(np.ptp(xy, axis=0) > spread * np.ptp(kept, axis=0) + 2 * gap):
        return small
    return np.zeros(len(xy), dtype=bool)


@pytest.mark.parametrize("seed", range(40))
def test_far_points_matches_plain_rule(seed):
    rng = np.random.default_rng(seed)
    parts = [rng.uniform(0, rng.uniform(50, 800), (rng.integers(200, 2000), 2))]
    for _ in range(rng.integers(0, 5)):  # clumps of a few points, near or far
        centre = rng.uniform(-5000, 5000, 2)
        parts.append(centre + rng.normal(0, rng.uniform(1, 150), (rng.integers(1, 150), 2)))
    xy = np.vstack(parts)
    np.testing.assert_array_equal(far_points(xy), _far_points_reference(xy))


@pytest.mark.parametrize("seed", range(10))
def test_far_points_matches_plain_rule_over_a_huge_extent(seed):
    # strays hundreds of km off: the cells are too many for a dense grid
    rng = np.random.default_rng(seed)
    parts = [rng.uniform(0, 500, (1000, 2))]
    for _ in range(rng.integers(1, 5)):
        centre = rng.uniform(-5e5, 5e5, 2)
        parts.append(centre + rng.normal(0, rng.uniform(1, 150), (rng.integers(1, 150), 2)))
    xy = np.vstack(parts)
    np.testing.assert_array_equal(far_points(xy), _far_points_reference(xy))
