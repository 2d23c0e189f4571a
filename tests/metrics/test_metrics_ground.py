"""ISPRS ground-filter errors (Sithole & Vosselman 2004)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from lidar2city.errors import InputError
from lidar2city.metrics.ground import ground_errors


def test_exact_confusion_counts():
    # reference: 6 ground, 4 object; 1 ground missed, 2 objects called ground
    ref = np.array([1, 1, 1, 1, 1, 1, 0, 0, 0, 0], dtype=bool)
    pred = np.array([1, 1, 1, 1, 1, 0, 1, 1, 0, 0], dtype=bool)
    e = ground_errors(pred, ref)
    assert (e["ground_ground"], e["ground_object"], e["object_ground"], e["object_object"]) == (5, 1, 2, 2)
    assert e["type_i"] == pytest.approx(1 / 6)
    assert e["type_ii"] == pytest.approx(2 / 4)
    assert e["total"] == pytest.approx(3 / 10)
    po = 7 / 10
    pe = (6 * 7 + 4 * 3) / 100
    assert e["kappa"] == pytest.approx((po - pe) / (1 - pe))
    assert e["points"] == 10


def test_perfect_and_inverted():
    ref = np.array([True, False, True, False])
    assert ground_errors(ref, ref)["kappa"] == 1.0
    assert ground_errors(ref, ref)["total"] == 0.0
    inv = ground_errors(~ref, ref)
    assert inv["total"] == 1.0 and inv["kappa"] == -1.0


def test_degenerate_classes():
    e = ground_errors(np.ones(5, bool), np.ones(5, bool))
    assert e["type_i"] == 0.0 and math.isnan(e["type_ii"]) and e["kappa"] == 1.0
    e = ground_errors(np.zeros(0, bool), np.zeros(0, bool))
    assert math.isnan(e["total"]) and math.isnan(e["kappa"])


def test_length_mismatch():
    with pytest.raises(InputError, match="points"):
        ground_errors(np.ones(3, bool), np.ones(4, bool))
    with pytest.raises(InputError):
        ground_errors(np.ones((2, 2), bool), np.ones((2, 2), bool))


@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=200))
def test_invariants(pairs):
    pred = np.array([p for p, _ in pairs])
    ref = np.array([r for _, r in pairs])
    e = ground_errors(pred, ref)
    assert e["ground_ground"] + e["ground_object"] + e["object_ground"] + e["object_object"] == len(pairs)
    assert e["total"] == pytest.approx((pred != ref).mean())
    assert -1.0 <= e["kappa"] <= 1.0 or math.isnan(e["kappa"])
    # swapping roles of prediction and reference keeps total error and kappa
    s = ground_errors(ref, pred)
    assert s["total"] == pytest.approx(e["total"])
    if not math.isnan(e["kappa"]):
        assert s["kappa"] == pytest.approx(e["kappa"])
