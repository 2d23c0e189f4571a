import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.errors import InputError
from lidar2city.metrics.classification import (
    ASPRS_MAPPING,
    classification_scores,
    confusion_matrix,
    map_classes,
)


def test_hand_computed_example():
    # reference: 4 building, 3 vegetation (3/4/5), 3 ground
    ref = np.array([6, 6, 6, 6, 5, 4, 3, 2, 2, 2])
    pred = np.array([6, 6, 6, 5, 5, 5, 6, 2, 2, 1])
    s = classification_scores(ref, pred)
    assert s.categories == ("building", "ground", "other", "vegetation")
    cm = s.confusion
    b, g, o, v = range(4)
    assert cm[b, b] == 3 and cm[b, v] == 1
    assert cm[v, v] == 2 and cm[v, b] == 1
    assert cm[g, g] == 2 and cm[g, o] == 1
    assert s.precision["building"] == pytest.approx(3 / 4)
    assert s.recall["building"] == pytest.approx(3 / 4)
    assert s.f1["vegetation"] == pytest.approx(2 * 2 / (3 + 3))
    assert s.recall["ground"] == pytest.approx(2 / 3)
    assert s.precision["ground"] == pytest.approx(1.0)
    assert s.overall_accuracy == pytest.approx(0.7)
    # kappa: p_e = sum(row * col) / n^2
    pe = (4 * 4 + 3 * 2 + 0 * 1 + 3 * 3) / 100
    assert s.kappa == pytest.approx((0.7 - pe) / (1 - pe))
    assert s.precision["other"] == 0.0 and np.isnan(s.recall["other"])


def test_mapping_and_ignore_for_ahn():
    ref = np.array([1, 1, 6, 6, 26, 9, 2])
    pred = np.array([5, 1, 6, 5, 6, 6, 2])
    s = classification_scores(
        ref, pred, mapping={6: "building", 1: "vegetation", 2: "ground"},
        predicted_mapping=ASPRS_MAPPING, ignore=(9, 26))
    assert s.confusion.sum() == 5
    assert s.precision["building"] == pytest.approx(1.0)
    assert s.recall["building"] == pytest.approx(0.5)
    assert s.recall["vegetation"] == pytest.approx(0.5)


def test_perfect_and_undefined():
    ref = np.array([2, 6, 5])
    s = classification_scores(ref, ref)
    assert s.kappa == pytest.approx(1.0) and s.overall_accuracy == 1.0
    assert all(v == 1.0 for k, v in s.f1.items() if k != "other")
    assert np.isnan(s.precision["other"])


def test_confusion_matrix_and_map_classes():
    names = map_classes(np.array([2, 3, 6, 17]), ASPRS_MAPPING)
    assert names.tolist() == ["ground", "vegetation", "building", "other"]
    cm = confusion_matrix(names, np.array(["ground", "ground", "building", "x"]),
                          ["building", "ground", "vegetation"])
    assert cm.tolist() == [[1, 0, 0], [0, 1, 0], [0, 1, 0]]


def test_bad_inputs():
    with pytest.raises(InputError, match="shape"):
        classification_scores(np.array([1, 2]), np.array([1]))
    with pytest.raises(InputError, match="integers"):
        classification_scores(np.array([1.5, 2.0]), np.array([1.0, 2.0]))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([1, 2, 3, 5, 6]), st.sampled_from([1, 2, 3, 5, 6])),
                min_size=1, max_size=60))
def test_invariants(pairs):
    ref = np.array([p[0] for p in pairs])
    pred = np.array([p[1] for p in pairs])
    s = classification_scores(ref, pred)
    assert s.confusion.sum() == len(pairs)
    assert s.overall_accuracy == pytest.approx(np.trace(s.confusion) / len(pairs))
    assert s.kappa <= 1.0 + 1e-12
    # swapping reference and prediction swaps precision and recall
    t = classification_scores(pred, ref)
    for k in s.categories:
        a, b = s.precision[k], t.recall[k]
        assert (np.isnan(a) and np.isnan(b)) or a == pytest.approx(b)
