"""Building blocks of the classifier: spacing, local PCA, planar regions, height above ground."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.classify import (
    local_shape,
    planar_regions,
    point_spacing,
)


def height_above_ground(xyz, ground):
    from lidar2city.ground import dtm_from_ground
    from lidar2city.ground import height_above_ground as hag

    return hag(xyz, dtm_from_ground(xyz, ground, cell=1.0))


def _plane(n_side, step, a, b, c, rng, noise=0.0):
    xs, ys = np.meshgrid(np.arange(n_side) * step, np.arange(n_side) * step)
    x, y = xs.ravel(), ys.ravel()
    return np.column_stack([x, y, a * x + b * y + c + rng.normal(0, noise, x.size) if noise else a * x + b * y + c])


def test_point_spacing_of_a_grid():
    rng = np.random.default_rng(0)
    xyz = _plane(60, 0.5, 0, 0, 0, rng)
    assert point_spacing(xyz[:, :2]) == pytest.approx(0.5, rel=0.05)
    # a gap (water) does not lower the measured density much
    keep = ~((xyz[:, 0] > 10) & (xyz[:, 0] < 20))
    assert point_spacing(xyz[keep, :2]) == pytest.approx(0.5, rel=0.1)


def test_local_shape_on_a_tilted_plane():
    rng = np.random.default_rng(1)
    a, b = 0.5, -0.3
    xyz = _plane(30, 0.4, a, b, 10.0, rng)
    shape = local_shape(xyz, 8)
    expected = np.array([-a, -b, 1.0]) / np.linalg.norm([-a, -b, 1.0])
    assert np.allclose(shape.normal, expected, atol=1e-6)
    assert np.all(shape.residual < 1e-6)
    assert np.all(shape.normal[:, 2] >= 0)
    assert shape.neighbours.shape == (len(xyz), 8)
    assert np.all(shape.neighbours[:, 0] == np.arange(len(xyz)))


def test_residual_measures_roughness():
    rng = np.random.default_rng(2)
    xyz = _plane(30, 0.4, 0, 0, 0, rng, noise=0.2)
    assert np.median(local_shape(xyz, 12).residual) > 0.1


def test_two_roof_facets_are_two_regions_and_a_blob_none():
    rng = np.random.default_rng(3)
    left = _plane(25, 0.3, 0.8, 0, 5, rng, noise=0.01)
    right = _plane(25, 0.3, -0.8, 0, 5 + 0.8 * 7.2 * 2, rng, noise=0.01)
    right[:, 0] += 7.2
    blob = rng.normal(size=(400, 3)) * 1.5 + np.array([30.0, 3.0, 6.0])
    xyz = np.concatenate([left, right, blob])
    regions = planar_regions(xyz, local_shape(xyz, 8), area_cell=0.5)
    lab = regions.labels
    n1, n2 = len(left), len(right)
    main_left = np.bincount(lab[:n1][lab[:n1] >= 0]).argmax()
    main_right = np.bincount(lab[n1:n1 + n2][lab[n1:n1 + n2] >= 0]).argmax()
    assert main_left != main_right
    assert (lab[:n1] == main_left).mean() > 0.9
    assert (lab[n1:n1 + n2] == main_right).mean() > 0.9
    assert regions.area[main_left] == pytest.approx(7.2 * 7.2, rel=0.15)
    assert regions.rms[main_left] < 0.02
    slope = np.degrees(np.arccos(regions.normal[main_left, 2]))
    assert slope == pytest.approx(np.degrees(np.arctan(0.8)), abs=1.0)
    blob_lab = lab[n1 + n2:]
    blob_regions = np.unique(blob_lab[blob_lab >= 0])
    assert all(regions.area[r] < 2.0 for r in blob_regions)


def _ground_sample(rng, side, density, a, b, c):
    """Ground points at random positions (as a scan samples them) on z = a x + b y + c."""
    n = int(side * side * density)
    xy = rng.uniform(0, side, (n, 2))
    return np.column_stack([xy, a * xy[:, 0] + b * xy[:, 1] + c])


def test_height_above_ground_on_a_slope_with_a_hole():
    rng = np.random.default_rng(4)
    g = _ground_sample(rng, 40.0, 4.0, 0.1, 0.05, 2.0)
    hole = (g[:, 0] > 10) & (g[:, 0] < 25) & (g[:, 1] > 10) & (g[:, 1] < 25)
    g = g[~hole]
    roof = np.column_stack([rng.uniform(11, 24, 200), rng.uniform(11, 24, 200), np.zeros(200)])
    roof[:, 2] = 0.1 * roof[:, 0] + 0.05 * roof[:, 1] + 2.0 + 6.0
    xyz = np.concatenate([g, roof])
    ground = np.arange(len(xyz)) < len(g)
    hag = height_above_ground(xyz, ground)
    assert np.allclose(hag[ground], 0, atol=0.08)
    # the plane is harmonic: the relaxed fill under the building reproduces it
    assert np.allclose(hag[~ground], 6.0, atol=0.1)


@settings(max_examples=25, deadline=None)
@given(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3), st.floats(-50, 50), st.floats(0.5, 12))
def test_hag_of_points_above_a_plane(a, b, c, h):
    rng = np.random.default_rng(5)
    g = _ground_sample(rng, 30.0, 4.0, a, b, c)
    p = np.column_stack([rng.uniform(2, 27, 20), rng.uniform(2, 27, 20), np.zeros(20)])
    p[:, 2] = a * p[:, 0] + b * p[:, 1] + c + h
    xyz = np.concatenate([g, p])
    hag = height_above_ground(xyz, np.arange(len(xyz)) < len(g))
    # a plane sampled at random (4 points per 1 m cell) is recovered within half the height
    # change across a cell (cells whose points do not span them take their mean)
    assert np.allclose(hag[len(g):], h, atol=0.02 + 0.5 * max(abs(a), abs(b)))


def test_surface_noise_follows_the_height_noise_and_not_the_order():
    from lidar2city.classify.features import surface_noise

    rng = np.random.default_rng(4)
    xy = rng.uniform(0, 100, (40_000, 2))
    levels = [surface_noise(np.column_stack([xy, rng.normal(0, s, len(xy))]), 8,
                            max_points=10_000) for s in (0.01, 0.03, 0.09)]
    assert levels[0] < levels[1] < levels[2]
    assert levels[2] / levels[1] == pytest.approx(3.0, rel=0.1)
    # the blocks are chosen by position: a shuffled copy gives the same level
    pts = np.column_stack([xy, rng.normal(0, 0.03, len(xy))])
    assert surface_noise(pts[rng.permutation(len(pts))], 8, max_points=10_000) == pytest.approx(
        surface_noise(pts, 8, max_points=10_000), rel=1e-9)
    assert surface_noise(pts[:5], 8) == 0.0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), max_size=60),
       st.sampled_from([0.5, -0.25, 1e7]))
def test_distinct_positions_are_numpys_unique_rows(cells, scale):
    from lidar2city.classify.features import distinct_positions

    xy = np.array(cells, dtype=np.float64).reshape(-1, 2) * scale
    xyz = np.column_stack([xy, np.arange(len(xy), dtype=np.float64)])
    got = distinct_positions(xyz)
    assert got.shape == (len(np.unique(xy, axis=0)), 2)
    assert np.array_equal(got, np.unique(xy, axis=0).reshape(-1, 2))


def test_scan_line_gap_on_distinct_positions_is_unchanged():
    from lidar2city.classify.features import distinct_positions, scan_line_gap

    x, y = np.meshgrid(np.arange(0, 40, 0.125), np.arange(0, 40, 1.0))
    xy = np.column_stack([x.ravel(), y.ravel()])
    xy = np.vstack([xy, xy[::3]])  # pulse pairs
    s = point_spacing(xy)
    assert scan_line_gap(distinct_positions(xy), s, distinct=True) == scan_line_gap(xy, s)
