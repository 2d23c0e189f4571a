"""connect_ground: a ground mask revised per smooth surface patch (segment connectivity)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import (
    GroundConfig,
    connect_ground,
    ground_mask,
    smrf_vote,
    surface_patches,
)
from lidar2city.synthetic_terrain import make_terrain


def _grid(n=20):
    return np.stack(np.meshgrid(np.arange(float(n)), np.arange(float(n))), -1).reshape(-1, 2)


def _box(n=20, height=3.0):
    g = _grid(n)
    box = (abs(g[:, 0] - n / 2) < 4) & (abs(g[:, 1] - n / 2) < 4)
    return np.column_stack([g, np.where(box, height, 0.0)]), box


def _terrace():
    """Ground at 0 m (x < 10) and a bench 1 m lower (x >= 10) behind a riser; 1 m cells."""
    g = _grid(20)
    return np.column_stack([g, np.where(g[:, 0] >= 10, -1.0, 0.0)]), g[:, 0] >= 10


def test_patches_are_cut_at_steps_and_joined_across_smooth_ground():
    xyz, box = _box()
    p = surface_patches(xyz, cell=1.0)
    lab = p["label"][p["flat"]]
    assert len(np.unique(lab[box])) == 1 and len(np.unique(lab[~box])) == 1
    assert lab[box][0] != lab[~box][0]
    # a 25 % slope is one patch at jump 0.3 m only with step_slope allowing its rise
    g = _grid(20)
    slope = np.column_stack([g, 0.5 * g[:, 0]])
    many = surface_patches(slope, cell=1.0)
    assert len(np.unique(many["label"][many["flat"]])) > 1
    one = surface_patches(slope, cell=1.0, step_slope=0.5)
    assert len(np.unique(one["label"][one["flat"]])) == 1
    # every boundary edge between patches is a step larger than the join threshold
    assert (np.abs(p["dz"]) > 0.3).all()


def test_raised_patch_taken_from_the_ground_and_lower_patch_given_to_it():
    xyz, box = _box()
    every = np.ones(len(xyz), dtype=bool)
    np.testing.assert_array_equal(connect_ground(xyz, every, cell=1.0, raised=0.9), ~box)
    # with the default rules only (lower): nothing to give, nothing taken
    np.testing.assert_array_equal(connect_ground(xyz, every, cell=1.0), every)
    xyz, bench = _terrace()
    mask = ~bench  # the bench below the riser called object
    np.testing.assert_array_equal(connect_ground(xyz, mask, cell=1.0), np.ones(len(xyz), bool))
    np.testing.assert_array_equal(connect_ground(xyz, mask, cell=1.0, lower=None), mask)


def test_share_spreads_ground_within_a_patch_and_pit_removes_a_hole():
    g = _grid(20)
    xyz = np.column_stack([g, 0.1 * g[:, 0]])  # one smooth patch
    mask = g[:, 0] < 18  # its last two columns called object
    assert connect_ground(xyz, mask, cell=1.0, share=0.85).all()
    assert not connect_ground(xyz, mask, cell=1.0, share=0.95)[~mask].any()
    pit = (g[:, 0] == 5) & (g[:, 1] == 5)
    xyz = np.column_stack([g, np.where(pit, -2.0, 0.0)])
    every = np.ones(len(xyz), dtype=bool)
    np.testing.assert_array_equal(connect_ground(xyz, every, cell=1.0, pit=1), ~pit)
    np.testing.assert_array_equal(connect_ground(xyz, every, cell=1.0), every)


def test_points_above_the_lowest_of_their_cell_are_not_given():
    xyz, bench = _terrace()
    tree = np.array([[15.2, 5.2, 2.0]])  # 3 m above the bench's lowest point in its cell
    xyz = np.vstack([xyz, tree])
    mask = np.r_[~bench, False]
    out = connect_ground(xyz, mask, cell=1.0)
    assert out[:-1].all() and not out[-1]


def test_excluded_points_never_ground_and_rounds_zero_changes_nothing():
    xyz, bench = _terrace()
    out = np.zeros(len(xyz), dtype=bool)
    out[:3] = True
    mask = ~bench
    revised = connect_ground(xyz, mask, exclude=out, cell=1.0)
    assert not revised[out].any() and revised[bench].all()
    np.testing.assert_array_equal(connect_ground(xyz, mask, cell=1.0, rounds=0), mask)


def test_deterministic_translation_invariant_and_not_mutating():
    scene = make_terrain("town_on_slope", spacing=1.0, seed=3)
    mask = smrf_vote(scene.xyz)
    copy = scene.xyz.copy()
    a = connect_ground(scene.xyz, mask, share=0.9, raised=0.9, pit=4)
    np.testing.assert_array_equal(scene.xyz, copy)
    shifted = scene.xyz + np.array([1000.0, -2000.0, 50.0])
    np.testing.assert_array_equal(a, connect_ground(shifted, mask, share=0.9, raised=0.9, pit=4))
    np.testing.assert_array_equal(a, connect_ground(scene.xyz, mask, share=0.9, raised=0.9,
                                                    pit=4))


def test_smrf_vote_connect_option_and_config():
    scene = make_terrain("terraces", spacing=1.0, seed=1)
    plain = smrf_vote(scene.xyz)
    np.testing.assert_array_equal(smrf_vote(scene.xyz, connect=0), plain)
    np.testing.assert_array_equal(smrf_vote(scene.xyz, connect=3),
                                  connect_ground(scene.xyz, plain, rounds=3))
    params = GroundConfig(method="smrf_vote", connect=3).method_params()
    assert params["connect"] == 3
    np.testing.assert_array_equal(ground_mask(scene.xyz, method="smrf_vote", **params),
                                  smrf_vote(scene.xyz, connect=3))
    assert GroundConfig().method_params()["connect"] is None
    with pytest.raises(ConfigError, match="ground.connect"):
        GroundConfig(connect=-1)


@pytest.mark.parametrize("kwargs, match", [
    ({"share": 0.0}, "share"), ({"lower": 1.5}, "lower"), ({"raised": "x"}, "raised"),
    ({"pit": -1}, "pit"), ({"rounds": 1.5}, "rounds"), ({"tolerance": 0}, "tolerance"),
    ({"jump": -1}, "jump"), ({"step_slope": -0.1}, "step_slope"), ({"cell": 0}, "cell"),
])
def test_bad_parameters(kwargs, match):
    xyz, box = _box()
    with pytest.raises(InputError, match=match):
        connect_ground(xyz, ~box, **kwargs)


def test_bad_shapes():
    xyz, box = _box()
    with pytest.raises(InputError, match="ground must be a mask"):
        connect_ground(xyz, ~box[:-1])
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        surface_patches(xyz[:, :2])
    with pytest.raises(InputError, match="connect"):
        smrf_vote(xyz, connect=-2)


def test_lowest_point_of_a_cell_is_the_first_of_the_equally_low():
    """Each filled cell's lowest point, ties to the lowest index (as a stable sort by cell and
    height gives), the cells in increasing order, and excluded points never chosen."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 20, (4000, 2))
    z = np.round(rng.uniform(0, 3, 4000), 1)  # many equal heights per cell
    xyz = np.column_stack([xy, z])
    out = rng.random(4000) < 0.2
    p = surface_patches(xyz, exclude=out, cell=1.0)
    kept = np.flatnonzero(~out)
    order = kept[np.lexsort((z[kept], p["flat"][kept]))]
    first = np.ones(len(order), dtype=bool)
    first[1:] = p["flat"][order[1:]] != p["flat"][order[:-1]]
    np.testing.assert_array_equal(p["lowest"], order[first])
    np.testing.assert_array_equal(p["cells"], p["flat"][order[first]])
    assert not out[p["lowest"]].any()
