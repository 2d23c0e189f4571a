"""A footprint much larger than its points, and a footprint without ground around it."""

import time

import numpy as np
import pytest
import shapely
from shapely.geometry import box

from lidar2city.lod import Lod1Config, reconstruct_building
from lidar2city.lod.coverage import reach_coverage
from lidar2city.lod.lod1 import MIN_COVERAGE


def _points(x0, y0, x1, y1, z, density, seed=0):
    rng = np.random.default_rng(seed)
    n = int(round((x1 - x0) * (y1 - y0) * density))
    xy = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
    return np.column_stack([xy, np.full(n, float(z)) + rng.normal(0, 0.02, n)])


def _ground(x0, y0, x1, y1, density=2.0):
    g = _points(x0 - 3, y0 - 3, x1 + 3, y1 + 3, 0.0, density, seed=1)
    inside = (g[:, 0] > x0) & (g[:, 0] < x1) & (g[:, 1] > y0) & (g[:, 1] < y1)
    return g[~inside]


@pytest.mark.parametrize("density", [1.0, 2.0, 20.0])
def test_a_fully_covered_footprint_stays_covered_at_any_density(density):
    # scan-line gaps of a 1 pts/m2 survey do not count as uncovered
    share, reach = reach_coverage(box(0, 0, 12, 8), _points(0, 0, 12, 8, 6, density)[:, :2])
    assert share > 0.9
    assert reach == pytest.approx(3.0 / np.sqrt(density), rel=0.5)


def test_coverage_of_a_corner_is_its_share_and_bounded_by_the_points():
    xy = _points(0, 0, 20, 20, 6, 10.0)[:, :2]
    t0 = time.perf_counter()
    share, _ = reach_coverage(box(0, 0, 2000, 2000), xy)  # 4 km2 over 400 m2 of points
    assert time.perf_counter() - t0 < 1.0
    assert 0.0001 < share < 0.00015  # 400 m2 (+ the reach) of 4e6 m2


def test_a_footprint_over_a_corner_of_points_gets_a_prism_only_with_its_reason():
    fp = box(0, 0, 1000, 1000)  # 1 km2 over a 30 m x 20 m roof
    pts = _points(100, 100, 130, 120, 8.0, 10.0)
    cfg = Lod1Config(lods=("1.2", "1.3"))
    t0 = time.perf_counter()
    res = reconstruct_building(fp, pts, _ground(100, 100, 130, 120), config=cfg, id="big")
    assert time.perf_counter() - t0 < 5.0  # was a 4-million-cell LoD1.3 raster
    assert res.ok and res.attributes["valid"]
    assert res.attributes["point_coverage"] < MIN_COVERAGE
    assert "cover 0.1 % of its 1000000 m2" in res.attributes["low_coverage"]
    assert res.attributes["lod13_parts"] == 1 and len(res.parts["1.3"]) == 1
    assert np.array_equal(res.parts["1.3"][0].vertices, res.solids["1.2"].vertices)


def test_a_covered_footprint_has_no_coverage_attribute():
    fp = box(0, 0, 12, 8)
    res = reconstruct_building(fp, _points(0, 0, 12, 8, 6, 2.0), _ground(0, 0, 12, 8),
                               config=Lod1Config(lods=("1.2", "1.3")), id="a")
    assert res.ok
    assert "low_coverage" not in res.attributes and "point_coverage" not in res.attributes


def test_the_lod13_raster_of_a_huge_covered_footprint_is_capped(monkeypatch):
    # a 1 km2 footprint its (sparse) points cover: a real, huge building; its LoD1.3 raster
    # at the 0.5 m cell would hold 4 million cells
    import lidar2city.lod.lod1 as lod1

    cells = []
    real = lod1.height_parts

    def spy(poly, pts, *, cell, **kw):
        x0, y0, x1, y1 = poly.bounds
        cells.append((x1 - x0) * (y1 - y0) / cell ** 2)
        return real(poly, pts, cell=cell, **kw)

    monkeypatch.setattr(lod1, "height_parts", spy)
    fp = box(0, 0, 1000, 1000)
    pts = _points(0, 0, 1000, 1000, 9.0, 0.05)
    res = reconstruct_building(fp, pts, _ground(0, 0, 1000, 1000, 0.05),
                               config=Lod1Config(lods=("1.2", "1.3")), id="estate")
    assert res.ok and "low_coverage" not in res.attributes
    assert cells and max(cells) <= 512 * 512
    # a normal building keeps the configured cell
    cells.clear()
    reconstruct_building(box(0, 0, 30, 20), _points(0, 0, 30, 20, 9.0, 5.0),
                         _ground(0, 0, 30, 20), config=Lod1Config(lods=("1.2", "1.3")))
    assert cells == [pytest.approx(30 * 20 / 0.25)]


def test_a_part_far_from_every_point_is_named_and_gets_no_invented_parts():
    # a two-part footprint, the second part 5 km off (a misplaced copy): it used to get a
    # prism at the building's height with no word of it
    near, far = box(0, 0, 12, 8), box(5000, 0, 5012, 8)
    fp = shapely.MultiPolygon([near, far])
    res = reconstruct_building(fp, _points(0, 0, 12, 8, 6, 10.0), _ground(0, 0, 12, 8),
                               config=Lod1Config(lods=("1.2", "1.3")), id="mp")
    assert res.ok
    assert "part 2 of its 2 (96 m2) has no building point within" in res.attributes["low_coverage"]
    assert "part 1" not in res.attributes["low_coverage"]
    assert res.attributes["lod13_parts"] == 2  # the LoD1.2 prisms stand in


def test_two_covered_parts_have_no_coverage_attribute():
    fp = shapely.MultiPolygon([box(0, 0, 12, 8), box(20, 0, 32, 8)])
    pts = np.vstack([_points(0, 0, 12, 8, 6, 10.0), _points(20, 0, 32, 8, 6, 10.0, seed=3)])
    res = reconstruct_building(fp, pts, _ground(0, 0, 32, 8),
                               config=Lod1Config(lods=("1.2", "1.3")), id="mp2")
    assert res.ok and "low_coverage" not in res.attributes
