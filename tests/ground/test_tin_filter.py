"""ptd: progressive TIN densification."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import GroundConfig, ground_mask, ptd
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import make_terrain


def _block_on_slope(gradient=0.5, height=8.0):
    g = np.stack(np.meshgrid(np.arange(80.0), np.arange(80.0)), -1).reshape(-1, 2)
    roof = (abs(g[:, 0] - 40) < 8) & (abs(g[:, 1] - 40) < 8)
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
