"""A footprint without ground around it whose lowest building point is on its roof."""

import numpy as np
import pytest
from shapely.geometry import box

from lidar2city.lod import reconstruct_building


def _points(x0, y0, x1, y1, z, density, seed=0):
    rng = np.random.default_rng(seed)
    n = int(round((x1 - x0) * (y1 - y0) * density))
    xy = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
    return np.column_stack([xy, np.full(n, float(z)) + rng.normal(0, 0.02, n)])


def test_the_lowest_roof_point_is_no_ground():
    # a 1 m x 1 m crop of a roof: no ground anywhere, the lowest point 0.9 m under the roof
    pts = _points(0, 0, 1, 1, 10.0, 12.0)
    pts[:, 2] = np.linspace(9.1, 10.0, len(pts))
    res = reconstruct_building(box(-2, -2, 3, 3), pts, np.zeros((0, 3)), id="tiny")
    # a roof-only cloud: the floor stays at its lowest point (as documented), and the
    # model says it stands on its roof
    assert res.ok and res.attributes["ground_source"] == "lowest building point"
    assert "on the roof" in res.attributes["ground_note"]
    # the area's ground level, when known, stands in
    res = reconstruct_building(box(-2, -2, 3, 3), pts, np.zeros((0, 3)), id="tiny",
                               fallback_ground_z=1.0)
    assert res.ok and res.attributes["ground_source"] == "fallback"
    assert res.attributes["ground_height"] == 1.0


def test_a_roof_only_building_with_walls_keeps_its_lowest_point():
    pts = _points(0, 0, 10, 10, 9.0, 5.0)
    pts[:5, 2] = 0.5  # wall foot points
    res = reconstruct_building(box(0, 0, 10, 10), pts, np.zeros((0, 3)), id="w")
    assert res.ok and res.attributes["ground_source"] == "lowest building point"


def test_a_flat_roof_only_cloud_gets_its_floor_under_the_roof():
    # every point on a flat roof, no ground anywhere: the lowest point is 0.1 m under the
    # roof, so a floor there would leave no wall; the floor goes 2 min_height under the roof
    # (the building was refused as less than min_height high)
    pts = _points(0, 0, 6, 5, 10.0, 10.0)
    res = reconstruct_building(box(0, 0, 6, 5), pts, np.zeros((0, 3)), id="flat")
    assert res.ok and res.attributes["ground_source"] == "below the roof"
    assert res.attributes["ground_height"] == pytest.approx(res.attributes["roof_height"] - 1.0)
    assert "1 m under its roof" in res.attributes["ground_note"]
