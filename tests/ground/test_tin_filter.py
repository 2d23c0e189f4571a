"""ptd: progressive TIN densification."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import GroundConfig, ground_mask, ptd
from lidar2city.ground.tin_filter import _locate, seeded_tin
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import make_terrain


def _block_on_slope(gradient=0.5, height=8.0):
    # a grid shaken by up to 0.2 m (fixed seed): exact grids are co-circular everywhere,
    # which makes every Delaunay build slow
    g = np.stack(np.meshgrid(np.arange(50.0), np.arange(50.0)), -1).reshape(-1, 2)
    g += np.random.default_rng(0).uniform(-0.2, 0.2, g.shape)
    roof = (abs(g[:, 0] - 25) < 6) & (abs(g[:, 1] - 25) < 6)
    z = gradient * g[:, 0] + np.where(roof, height, 0.0)
    return np.column_stack([g, z]), ~roof


def test_block_on_a_slope_is_object_and_slope_is_ground():
    xyz, truth = _block_on_slope()
    ground = ptd(xyz)
    assert ground[truth].all()
    assert not ground[~truth].any()


def test_deterministic_and_translation_invariant():
    scene = make_terrain("town_on_slope", spacing=2.5, seed=3)
    a = ptd(scene.xyz)
    np.testing.assert_array_equal(a, ptd(scene.xyz.copy()))
    np.testing.assert_array_equal(a, ptd(scene.xyz + np.array([4000.0, -700.0, 250.0])))
    assert ground_errors(a, scene.ground)["total"] < 0.15


def test_low_outlier_never_ground_and_empty_input():
    xyz, _ = _block_on_slope(height=0.0)
    xyz = np.vstack([xyz, [[20.0, 20.0, -30.0]]])
    assert not ptd(xyz)[-1]
    assert ptd(np.zeros((0, 3))).shape == (0,)


@pytest.mark.parametrize("bad", [{"seed_cell": 0}, {"iteration_angle": 95.0},
                                 {"iteration_distance": -1.0}, {"max_iterations": -1},
                                 {"scalar": -1.0}])
def test_bad_parameters(bad):
    xyz, _ = _block_on_slope()
    with pytest.raises(InputError):
        ptd(xyz, **bad)


def test_registered_in_config_and_ground_mask():
    xyz, truth = _block_on_slope()
    params = GroundConfig(method="ptd").method_params()
    assert {"seed_cell", "iteration_angle", "iteration_distance", "threshold"} <= set(params)
    assert "slope" not in params and "max_distance" not in params
    np.testing.assert_array_equal(ground_mask(xyz, method="ptd", **params), ptd(xyz, **params))
    with pytest.raises(ConfigError):
        GroundConfig(method="ptd", iteration_angle=90.0)
    with pytest.raises(ConfigError):
        GroundConfig(method="ptd", max_iterations=-2)


def test_locate_matches_delaunay_find_simplex_off_edges():
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(2)
    tri = Delaunay(rng.uniform(0, 100, (300, 2)))
    q = rng.uniform(-10, 110, (800, 2))
    np.testing.assert_array_equal(_locate(tri.points, tri.simplices, q), tri.find_simplex(q))


def test_seeded_tin_grows_along_connected_terrain_not_onto_a_roof():
    # seeds on the lower third of a slope only; a roof on it
    xyz, truth = _block_on_slope(gradient=0.2, height=6.0)
    seeds = truth & (xyz[:, 0] < 15)
    surface, grad = seeded_tin(xyz, seeds)
    off = np.abs(xyz[:, 2] - surface) / (0.5 + 1.25 * grad)
    assert (off[truth] <= 1).mean() > 0.99       # the TIN reached the ground it was not seeded on
    assert (off[~truth] > 1).all()               # but not the roof
    nan = seeded_tin(xyz, np.zeros(len(xyz), dtype=bool))
    assert np.isnan(nan[0]).all()
    with pytest.raises(InputError):
        seeded_tin(xyz, seeds[:-1])
