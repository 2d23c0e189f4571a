import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Polygon, box

from lidar2city.metrics.footprints import area_metrics, axis_alignment, match_objects, pixel_metrics


def test_area_metrics_exact():
    ref = [box(0, 0, 10, 10)]
    pred = [box(5, 0, 15, 10)]
    m = area_metrics(pred, ref)
    assert m["completeness"] == pytest.approx(0.5)
    assert m["correctness"] == pytest.approx(0.5)
    assert m["quality"] == pytest.approx(50 / 150)


def test_match_objects_one_to_one():
    ref = [box(0, 0, 10, 10), box(20, 0, 30, 10), box(40, 0, 41, 1)]
    pred = [box(0, 0, 10, 9), box(21, 0, 30, 10), box(100, 100, 101, 101)]
    m = match_objects(pred, ref)
    assert m["matched"] == 2
    assert m["recall"] == pytest.approx(2 / 3)
    assert m["precision"] == pytest.approx(2 / 3)
    assert m["hausdorff_mean"] == pytest.approx(1.0)


def test_axis_alignment_rotated_rectangle_and_oblique():
    rect = affinity.rotate(box(0, 0, 20, 10), 33, origin=(0, 0))
    assert axis_alignment([rect])["aligned_share"] == pytest.approx(1.0)
    tri = Polygon([(0, 0), (10, 0), (0, 10)])  # hypotenuse at 45 deg is not on the axes
    share = axis_alignment([tri])["aligned_share"]
    assert share == pytest.approx(20 / (20 + np.sqrt(200)))


def test_pixel_metrics_exact():
    ref = np.zeros((10, 10), bool)
    ref[:5] = True
    pred = ref.copy()
    pred[5, :] = True  # 10 false positives
    m = pixel_metrics(pred, ref)
    assert m["overall_accuracy"] == pytest.approx(0.9)
    assert m["users_accuracy"] == pytest.approx(50 / 60)
    assert m["producers_accuracy"] == 1.0
    # kappa by hand: po = .9, pe = .6*.5 + .4*.5 = .5
    assert m["kappa"] == pytest.approx(0.8)


def test_axis_alignment_multipolygon():
    from shapely.geometry import MultiPolygon

    rect = affinity.rotate(box(0, 0, 20, 10), 12, origin=(0, 0))
    assert axis_alignment([MultiPolygon([rect])])["aligned_share"] == pytest.approx(1.0)


def test_report_pixel_scores():
    from lidar2city.metrics.footprints import footprint_report

    ref = [box(0, 0, 10, 10)]
    rep = footprint_report(ref, ref, pixel_cell=0.5)
    assert rep["pixels"]["kappa"] == pytest.approx(1.0)
    rep = footprint_report([box(0, 0, 10, 5)], ref, pixel_cell=0.5, area=box(-10, -10, 20, 20))
    # 50 of 100 m2 found, no false positive, inside a 900 m2 area
    assert rep["pixels"]["producers_accuracy"] == pytest.approx(0.5)
    assert rep["pixels"]["users_accuracy"] == pytest.approx(1.0)
    assert rep["pixels"]["overall_accuracy"] == pytest.approx(1 - 50 / 900)
