"""Objects wider than SMRF's window (``ground.large``) and smrf_vote's ``large`` option."""

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import GroundConfig, LARGE_REACH, large_objects, smrf_vote
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import LARGE_KINDS, make_terrain


def _plane(h=300, w=300, grade=0.03):
    return (np.arange(h, dtype=np.float32)[:, None] * grade + np.zeros((1, w), np.float32))


def test_a_hall_wider_than_the_window_is_found_whole_and_nothing_else():
    z = _plane()
    z[100:170, 60:180] += 12.0           # 120 m x 70 m, 12 m high
    z[200:220, 200:215] += 7.0           # a house the window removes anyway
    big = large_objects(z, cell=1.0, window=24.0)
    hall = np.zeros(z.shape, dtype=bool)
    hall[100:170, 60:180] = True
    np.testing.assert_array_equal(big, hall)


def test_a_courtyard_stays_out_and_empty_cells_are_never_marked():
    z = _plane()
    z[60:160, 60:200] += 15.0            # a 140 m x 100 m block round a 40 m x 30 m courtyard
    z[95:125, 110:150] -= 15.0
    z[130:132, 70:80] = np.nan           # cells without a point on the roof
    big = large_objects(z, cell=1.0, window=24.0)
    assert big[62:158, 62:198][~np.isnan(z[62:158, 62:198]) & (z[62:158, 62:198] > 10)].all()
    assert not big[95:125, 110:150].any()
    assert not big[np.isnan(z)].any()


@pytest.mark.parametrize("grade", [0.0, 0.2, 1.0])
def test_plain_slopes_hills_and_edge_plateaus_are_not_large_objects(grade):
    z = _plane(grade=grade)
    yy, xx = np.mgrid[:300, :300]
    z += (10 * np.sin(xx / 40.0) + 10 * np.cos(yy / 50.0)).astype(np.float32)
    z[:, 240:] += 8.0                    # a step up running out of the grid: maybe terrain
    assert not large_objects(z, cell=1.0, window=24.0).any()


def test_smrf_vote_calls_large_roofs_object_and_leaves_terrain_alone():
    """The synthetic halls: every roof called ground without the option, none with it; the
    mesa (terrain with 56 degree flanks and an edge bench) is unchanged."""
    assert LARGE_KINDS == ("large_hall", "mesa")
    for spacing in (1.0, 2.5):
        scene = make_terrain("large_hall", spacing=spacing, seed=2)
        off = ground_errors(smrf_vote(scene.xyz, large=None), scene.ground)
        on = ground_errors(smrf_vote(scene.xyz), scene.ground)
        assert off["type_ii"] > 0.5 and on["type_ii"] < 0.01, (spacing, off, on)
        assert on["type_i"] <= off["type_i"] + 0.001
        mesa = make_terrain("mesa", spacing=spacing, seed=2)
        np.testing.assert_array_equal(smrf_vote(mesa.xyz), smrf_vote(mesa.xyz, large=None))


def test_large_option_values_and_config():
    scene = make_terrain("large_hall", spacing=2.5, seed=0)
    off = smrf_vote(scene.xyz, large=None)
    np.testing.assert_array_equal(smrf_vote(scene.xyz, large=np.inf), off)
    assert (smrf_vote(scene.xyz, large=LARGE_REACH) != off).any()
    assert GroundConfig(method="smrf_vote").method_params()["large"] == LARGE_REACH
    assert "large" not in GroundConfig(method="smrf_segments").method_params()
    with pytest.raises(ConfigError, match="ground.large"):
        GroundConfig(large=0)
    with pytest.raises(InputError, match="large"):
        smrf_vote(scene.xyz, large=-1.0)
    for bad in ({"cell": 0}, {"window": -1}, {"reach": 0}, {"coarse": 0}, {"share": 0},
                {"share": 1.5}, {"jump": 0}):
        kwargs = {"cell": 1.0, "window": 24.0, **bad}
        with pytest.raises(InputError):
            large_objects(_plane(), **kwargs)


def test_large_objects_are_deterministic_and_grid_sized():
    z = _plane(120, 90)
    z[20:100, 10:80] += 9.0
    a = large_objects(z, cell=1.0, window=24.0)
    b = large_objects(z.copy(), cell=1.0, window=24.0)
    np.testing.assert_array_equal(a, b)
    assert a.shape == z.shape and a.dtype == bool
    assert not large_objects(np.full((2, 2), np.nan, np.float32), cell=1.0, window=24.0).any()


def test_plain_smrf_the_classifiers_filter_finds_large_roofs_too():
    from lidar2city.ground import smrf

    scene = make_terrain("large_hall", spacing=1.0, seed=3)
    off = ground_errors(smrf(scene.xyz, large=None), scene.ground)
    on = ground_errors(smrf(scene.xyz), scene.ground)
    assert off["type_ii"] > 0.5 and on["type_ii"] < 0.01
    assert GroundConfig(method="smrf").method_params()["large"] == LARGE_REACH
    np.testing.assert_array_equal(smrf(scene.xyz, large=np.inf), smrf(scene.xyz, large=None))
