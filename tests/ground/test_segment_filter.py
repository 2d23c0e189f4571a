"""smrf_segments: SMRF with terrain-like object segments given back (terrace tops, embankments)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import (
    GROUND_METHODS,
    anchored_objects,
    GroundConfig,
    ground_mask,
    smrf_refined,
    smrf_segments,
    terrain_segments,
)
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import TERRAIN_KINDS, make_terrain


def _plateau_grid():
    """40 x 40 cells: ground at 0 west of column 10 and a terrace level at 3 m east of it
    (a 3 m wall between), with a band of the terrace along the wall judged object (as an
    opening cuts a convex edge), and a 4 m box standing on the terrace, judged object."""
    z = np.zeros((40, 40), dtype=np.float32)
    z[:, 10:] = 3.0
    z[24:34, 22:32] = 7.0
    objects = np.zeros(z.shape, dtype=bool)
    objects[4:16, 10:18] = True
    objects[24:34, 22:32] = True
    return z, objects


def test_terrain_segments_gives_back_a_terrace_edge_and_keeps_a_box():
    z, objects = _plateau_grid()
    kept = terrain_segments(z, objects)
    assert not kept[4:16, 10:18].any()  # raised (the wall) on one side of four: terrain
    assert kept[24:34, 22:32].all()  # raised all round: object
    assert not (kept & ~objects).any()


def test_terrain_segments_on_coarse_blocks():
    """With block 2 the segments are cut on 2 x 2 blocks of lowest heights; the same
    answer here, and empty cells between sparse points no longer break a surface."""
    z, objects = _plateau_grid()
    np.testing.assert_array_equal(terrain_segments(z, objects, block=2),
                                  terrain_segments(z, objects))
    sparse = z.copy()
    sparse[::2, :] = np.nan  # one filled cell in four, as with twice the point spacing
    sparse[:, ::2] = np.nan
    kept = terrain_segments(sparse, objects, block=2)
    assert not kept[4:16, 10:18].any() and kept[24:34, 22:32].all()
    with pytest.raises(InputError, match="block"):
        terrain_segments(z, objects, block=0)


def test_terrain_segments_edge_cases():
    z, objects = _plateau_grid()
    nothing = np.zeros_like(objects)
    np.testing.assert_array_equal(terrain_segments(z, nothing), nothing)
    empty = np.full(z.shape, np.nan, dtype=np.float32)
    np.testing.assert_array_equal(terrain_segments(empty, objects), objects)
    # every cell object: no terrain to join, nothing given back
    np.testing.assert_array_equal(terrain_segments(z, np.ones_like(objects)),
                                  np.ones_like(objects))


@pytest.mark.parametrize("kind", TERRAIN_KINDS)
@pytest.mark.parametrize("spacing", [1.0, 2.5])
def test_segments_on_synthetic_terrains(kind, spacing):
    """Within one point of smrf_refined on every synthetic kind, and under 8 %.

    Measured (total error %, segments / smrf_refined): town on a slope at 1 m
    0.00 / 2.63, cliff at 2.5 m 1.94 / 2.81, terraces at 2.5 m 7.25 / 7.88;
    forest at 2.5 m 2.62 / 1.94 (sparse canopy given back); the rest equal.
    """
    scene = make_terrain(kind, spacing=spacing, seed=1)
    seg = ground_errors(smrf_segments(scene.xyz), scene.ground)["total"]
    ref = ground_errors(smrf_refined(scene.xyz), scene.ground)["total"]
    assert seg <= ref + 0.01
    assert seg < 0.08
    if kind == "town_on_slope" and spacing == 1.0:
        assert seg < 0.005 < ref


def test_segments_gives_back_a_terrace_edge_that_smrf_refined_cuts():
    """A shelf cut into a 0.5 slope with a 7.5 m wall below it: the opening cuts its
    outer edge like a building's, the segments give it back; a house stays an object."""
    rng = np.random.default_rng(5)
    xy = rng.uniform(0, 100, (12000, 2))
    x, y = xy[:, 0], xy[:, 1]
    z = 0.5 * x
    shelf = (x >= 40) & (x < 55) & (y > 20) & (y < 60)
    z[shelf] = 27.5
    house = (x > 70) & (x < 80) & (y > 60) & (y < 75)
    z[house] = 47.0
    xyz = np.column_stack([xy, z])
    refined = smrf_refined(xyz)
    seg = smrf_segments(xyz)
    assert refined[shelf].mean() < 0.95
    assert seg[shelf].mean() > 0.99 and seg[~shelf & ~house].all()
    assert not seg[house].any()


def test_segments_registered_validated_and_deterministic():
    assert GROUND_METHODS["smrf_segments"] is smrf_segments
    cfg = GroundConfig(method="smrf_segments")
    params = cfg.method_params()
    assert params["slope"] == 0.15 and params["jump"] == 0.6 and params["extend"] == 10.0
    assert params["strong_slope"] is None
    assert "rounds" not in params
    scene = make_terrain("town_on_slope", spacing=1.0, seed=3)
    a = ground_mask(scene.xyz, method="smrf_segments", **params)
    np.testing.assert_array_equal(a, smrf_segments(scene.xyz.copy()))
    shifted = smrf_segments(scene.xyz + np.array([1000.0, 2000.0, 300.0]))
    np.testing.assert_array_equal(a, shifted)
    for bad in ({"jump": 0}, {"raised": 0}, {"raised": 1.5}, {"min_cells": 0}, {"scalar": -1},
                {"strong_slope": 0}, {"strong_slope": "0.4"}):
        with pytest.raises(InputError):
            smrf_segments(scene.xyz, **bad)
    for name, value in (("jump", 0.0), ("raised", 2.0), ("min_cells", 0), ("strong_slope", 0.0)):
        with pytest.raises(ConfigError, match=f"ground.{name}"):
            GroundConfig(method="smrf_segments", **{name: value})
    assert smrf_segments(np.zeros((0, 3))).shape == (0,)


def test_segments_keeps_the_ground_of_a_small_tile_with_a_building():
    """A 10 m tile with a 4 m building in its middle: reflected across the edges the
    building becomes pits that make the whole tile object (smrf_refined keeps 16 % right);
    smrf_segments then keeps SMRF's own edges."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (20000, 2))
    z = np.where((np.abs(xy[:, 0] - 5) < 2) & (np.abs(xy[:, 1] - 5) < 2), 7.0, 1.0)
    xyz = np.column_stack([xy, z])
    assert (smrf_refined(xyz) == (z == 1.0)).mean() < 0.5
    assert (smrf_segments(xyz) == (z == 1.0)).mean() > 0.95


def test_anchored_objects_keeps_only_regions_holding_a_strong_cell():
    objects = np.zeros((12, 12), dtype=bool)
    objects[1:4, 1:4] = True  # holds a strong cell: stays
    objects[6:10, 6:11] = True  # cut only at the strict slope: terrain
    objects[1, 8] = True  # a lone strong cell stays
    strong = np.zeros_like(objects)
    strong[2, 3] = strong[1, 8] = True
    strong[5, 5] = True  # a strong cell outside the objects anchors nothing
    kept = anchored_objects(objects, strong)
    expected = np.zeros_like(objects)
    expected[1:4, 1:4] = True
    expected[1, 8] = True
    np.testing.assert_array_equal(kept, expected)
    # diagonal contact does not join regions (4-neighbours)
    diag = np.zeros((4, 4), dtype=bool)
    diag[0, 0] = diag[1, 1] = True
    only = np.zeros_like(diag)
    only[0, 0] = True
    np.testing.assert_array_equal(anchored_objects(diag, only), only)


def test_strong_slope_at_or_below_slope_changes_nothing():
    """Every object cell is then strong itself: the hysteresis is a no-op."""
    scene = make_terrain("hillside", spacing=2.5, seed=2)
    np.testing.assert_array_equal(smrf_segments(scene.xyz, slope=0.2, strong_slope=0.2),
                                  smrf_segments(scene.xyz, slope=0.2, strong_slope=None))


@pytest.mark.parametrize("kind", ["terraces", "bridge", "hillside"])
def test_strong_slope_gives_back_what_only_the_strict_slope_cuts(kind):
    """At slope 0.1 the opening cuts the convex edges of 2.5 m-spaced terraces, bridge
    ramps and a 45 degree hillside; without a cell cut at 0.4 such regions are terrain.
    Measured (total error %, strong_slope 0.4 / none): terraces 0.56 / 9.75, bridge
    0.00 / 1.12, hillside 1.31 / 2.62."""
    scene = make_terrain(kind, spacing=2.5, seed=1)
    with_ = ground_errors(smrf_segments(scene.xyz, slope=0.1, strong_slope=0.4),
                          scene.ground)["total"]
    without = ground_errors(smrf_segments(scene.xyz, slope=0.1), scene.ground)["total"]
    assert with_ < without
    assert with_ < 0.015


@pytest.mark.parametrize("kind", ["town_on_slope", "forest", "cliff", "hillside"])
def test_strong_slope_keeps_buildings_and_trees(kind):
    """Houses and canopies hold cells cut at 0.4 (walls, crown edges): the hysteresis gives
    none of them back. Measured (objects called ground %, at 1 m / 2.5 m, with or without
    it): town on a slope 0.00 / 0.92, forest 1.01 / 3.56, cliff and hillside 0."""
    for spacing in (1.0, 2.5):
        scene = make_terrain(kind, spacing=spacing, seed=4)
        with_ = smrf_segments(scene.xyz, slope=0.1, strong_slope=0.4)[~scene.ground]
        without = smrf_segments(scene.xyz, slope=0.1)[~scene.ground]
        assert with_.mean() <= without.mean() + 0.001
        assert with_.mean() < 0.04
