"""Stray returns far from the survey (:func:`lidar2city.classify.outliers.far_points`)."""

from __future__ import annotations

import numpy as np

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
