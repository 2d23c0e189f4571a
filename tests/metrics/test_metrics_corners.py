"""Corner correctness / completeness and coordinate differences."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.metrics.corners import corner_metrics, match_corners, pair_buildings

BOX = np.array([[0, 0, 0], [10, 0, 0], [10, 6, 0], [0, 6, 0],
                [0, 0, 5], [10, 0, 5], [10, 6, 5], [0, 6, 5]], dtype=float)


def test_identical_models_are_perfect():
    m = corner_metrics({"a": BOX}, {"a": BOX})
    assert (m.correctness, m.completeness, m.n_matched) == (1.0, 1.0, 8)
    assert m.rmse_x == m.rmse_y == m.rmse_z == m.rmse_xy == 0.0


def test_known_offsets_give_known_means_and_rmse():
    d = np.zeros_like(BOX)
    d[:, 0] = 0.1
    d[:4, 2] = -0.2
    d[4:, 2] = 0.2
    m = corner_metrics({"a": BOX + d}, {"a": BOX})
    assert m.mean_x == pytest.approx(0.1) and m.rmse_x == pytest.approx(0.1)
    assert m.mean_z == pytest.approx(0.0) and m.rmse_z == pytest.approx(0.2)
    assert m.rmse_xy == pytest.approx(0.1)


def test_missing_and_extra_corners():
    pred = np.vstack([BOX[:6], [[5, 3, 9.0]]])  # two corners missing, one extra
    m = corner_metrics({"a": pred}, {"a": BOX}, tolerance=0.5)
    assert m.n_matched == 6
    assert m.correctness == pytest.approx(6 / 7)
    assert m.completeness == pytest.approx(6 / 8)


def test_tolerance_rejects_far_corners():
    m = corner_metrics({"a": BOX + [0.6, 0, 0]}, {"a": BOX}, tolerance=0.5)
    assert m.n_matched == 0 and np.isnan(m.rmse_x)
    m = corner_metrics({"a": BOX + [0.6, 0, 0]}, {"a": BOX}, tolerance=0.7)
    assert m.n_matched == 8


def test_matching_is_one_to_one():
    ref = np.array([[0, 0, 0], [0.3, 0, 0]], dtype=float)
    pred = np.array([[0.15, 0, 0], [0.16, 0, 0], [0.17, 0, 0]])
    ip, ir, d = match_corners(pred, ref, tolerance=0.5)
    assert len(ip) == 2 and len(set(ip)) == 2 and len(set(ir)) == 2


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1))
def test_matching_equals_brute_force_on_small_sets(seed):
    import itertools

    rng = np.random.default_rng(seed)
    ref = rng.uniform(0, 2, (4, 3))
    pred = rng.uniform(0, 2, (4, 3))
    tol = 0.8
    ip, ir, dist = match_corners(pred, ref, tolerance=tol)
    d = np.linalg.norm(pred[:, None] - ref[None], axis=-1)
    best = 0
    for perm in itertools.permutations(range(4)):
        best = max(best, sum(d[i, j] <= tol for i, j in enumerate(perm)))
    assert len(ip) == best
    assert np.all(dist <= tol)


def test_buildings_paired_by_overlap_when_ids_differ():
    other = BOX + [100, 0, 0]
    pred = {"p1": BOX + [0.05, 0, 0], "p2": other}
    ref = {"r2": other, "r1": BOX}
    assert sorted(pair_buildings(pred, ref)) == [("p1", "r1"), ("p2", "r2")]
    m = corner_metrics(pred, ref)
    assert m.buildings_paired == 2 and m.completeness == 1.0
    m = corner_metrics(pred, ref, by="id")
    assert m.buildings_paired == 0 and m.n_matched == 0 and m.completeness == 0.0


def test_unpaired_buildings_count_as_missing():
    m = corner_metrics({"a": BOX}, {"a": BOX, "b": BOX + [50, 0, 0]})
    assert m.completeness == 0.5 and m.correctness == 1.0


def test_bad_arguments():
    with pytest.raises(ValueError):
        corner_metrics({}, {}, tolerance=0)
    with pytest.raises(ValueError):
        pair_buildings({}, {}, by="name")
    m = corner_metrics({}, {})
    assert m.n_matched == 0 and np.isnan(m.correctness)


def test_bad_arguments_are_lidar2city_errors():
    """User mistakes raise the package's InputError, which the CLI prints as one line."""
    from lidar2city.errors import InputError

    with pytest.raises(InputError):
        corner_metrics({}, {}, tolerance=-1)
    with pytest.raises(InputError):
        pair_buildings({}, {}, by="name")
