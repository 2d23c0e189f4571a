"""The nearest fill of the minimum surface on sparse surveys (smrf_vote's ``fill``)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import VOTE_FILL, GroundConfig, smrf_vote, vote_features
from lidar2city.ground._grid import nearest_fill
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import make_terrain


def _sparse_grid(seed=0, shape=(30, 40), share=0.8):
    rng = np.random.default_rng(seed)
    grid = rng.normal(size=shape).astype(np.float32)
    grid[rng.random(shape) < share] = np.nan
    return grid


@pytest.mark.parametrize("radius", [1.0, 1.5, 2.5, 3.2])
def test_nearest_fill_takes_a_nearest_known_cell_within_the_radius(radius):
    grid = _sparse_grid()
    out = nearest_fill(grid, radius)
    known = ~np.isnan(grid)
    np.testing.assert_array_equal(out[known], grid[known])
    kr, kc = np.nonzero(known)
    for r, c in zip(*np.nonzero(~known)):
        d = np.hypot(kr - r, kc - c)
        if d.min() > radius:
            assert np.isnan(out[r, c])
        else:  # the value of one of the nearest known cells
            nearest = d <= d.min() + 1e-9
            assert out[r, c] in grid[kr[nearest], kc[nearest]]


def test_nearest_fill_radius_below_one_where_and_ties():
    grid = _sparse_grid(1)
    np.testing.assert_array_equal(nearest_fill(grid, 0.99), grid)
    where = np.zeros(grid.shape, dtype=bool)
    where[:, :10] = True
    out = nearest_fill(grid, 2.0, where)
    np.testing.assert_array_equal(out[:, 10:], grid[:, 10:])
    np.testing.assert_array_equal(out[:, :10], nearest_fill(grid, 2.0)[:, :10])
    # a cell between two known ones at the same distance: always the same one
    line = np.array([[1.0, np.nan, 3.0]])
    assert nearest_fill(line, 1.0)[0, 1] == nearest_fill(line.copy(), 1.0)[0, 1] == 1.0
    # only known cells spread their values, never cells filled here
    far = np.array([[5.0, np.nan, np.nan, np.nan]])
    np.testing.assert_array_equal(nearest_fill(far, 1.0), [[5.0, 5.0, np.nan, np.nan]])


@pytest.mark.parametrize("radius", [-1.0, np.inf, np.nan, "2", None])
def test_nearest_fill_bad_radius(radius):
    with pytest.raises(InputError, match="radius"):
        nearest_fill(_sparse_grid(), radius)


def test_nearest_fill_bad_where():
    with pytest.raises(InputError, match="where"):
        nearest_fill(_sparse_grid(), 2.0, np.zeros((3, 3), dtype=bool))


def _crest_rows(scene, spacing):
    """Ground points of terraced_slope within 1.5 spacings of a lower ground point across a
    retaining wall (a bench's level, its height less the 4 % cross slope, more than 1 m
    above): the first points above each wall."""
    xyz, ground = scene.xyz, scene.ground
    level = xyz[:, 2] - 0.04 * xyz[:, 1]
    d2 = ((xyz[:, None, :2] - xyz[None, :, :2]) ** 2).sum(-1)
    near = (d2 <= (1.5 * spacing) ** 2) & ground[None, :]
    below = (level[:, None] - level[None, :] > 1.0) & (xyz[None, :, 0] < xyz[:, None, 0])
    return ground & (near & below).any(axis=1)


@pytest.mark.parametrize("seed", [1, 2])
def test_fill_keeps_the_crest_rows_of_a_terraced_slope_at_2_5_m(seed):
    """At 2.5 m spacing the vote without the fill calls 26-32 % of the crest rows object
    (the inpainting ramps across each wall and the opening cuts the crest); with it, fewer
    than half of those, and no object point turns ground (the scene's house)."""
    scene = make_terrain("terraced_slope", spacing=2.5, seed=seed)
    crest = _crest_rows(scene, 2.5)
    assert crest.sum() > 200
    off = smrf_vote(scene.xyz, fill=None)
    on = smrf_vote(scene.xyz)
    assert (~off[crest]).sum() > 0.2 * crest.sum()
    assert (~on[crest]).sum() < 0.5 * (~off[crest]).sum()
    assert not (on & ~scene.ground).any()
    total = {k: ground_errors(mask, scene.ground)["total"] for k, mask in (("on", on), ("off", off))}
    assert total["on"] < 0.5 * total["off"]
    # the wall distances do not see the fill (the walls are marked without it)
    np.testing.assert_array_equal(vote_features(scene.xyz)[0][:, 3],
                                  vote_features(scene.xyz, fill=None)[0][:, 3])


@pytest.mark.parametrize("kind", ["terraced_slope", "steep_town", "terraces"])
def test_fill_changes_nothing_on_a_dense_survey(kind):
    """At 1 m spacing half a spacing is less than a cell: nothing is filled, the same
    features and mask as without the fill (the urban ISPRS samples, ~1 m, are untouched)."""
    scene = make_terrain(kind, spacing=1.0, seed=1)
    np.testing.assert_array_equal(vote_features(scene.xyz)[0],
                                  vote_features(scene.xyz, fill=None)[0])
    np.testing.assert_array_equal(smrf_vote(scene.xyz), smrf_vote(scene.xyz, fill=None))
    np.testing.assert_array_equal(smrf_vote(scene.xyz, fill=0.0), smrf_vote(scene.xyz, fill=None))


def test_fill_is_deterministic_and_independent_of_the_point_order():
    scene = make_terrain("terraced_slope", spacing=2.5, seed=1)
    first = smrf_vote(scene.xyz)
    np.testing.assert_array_equal(smrf_vote(scene.xyz.copy()), first)
    order = np.random.default_rng(0).permutation(len(scene.xyz))
    np.testing.assert_array_equal(smrf_vote(scene.xyz[order]), first[order])
    assert (first != smrf_vote(scene.xyz, fill=None)).any()  # the fill acts here


@pytest.mark.parametrize("fill", [-0.5, np.nan, np.inf, "0.5", True])
def test_fill_bad_values(fill):
    xyz = make_terrain("terraces", spacing=2.5, seed=1).xyz
    with pytest.raises(InputError, match="fill"):
        smrf_vote(xyz, fill=fill)
    with pytest.raises(InputError, match="fill"):
        vote_features(xyz, fill=fill)


def test_fill_in_the_ground_config():
    assert VOTE_FILL == 0.5
    assert GroundConfig(method="smrf_vote").method_params()["fill"] == VOTE_FILL
    assert GroundConfig(method="smrf_vote", fill=0.0).method_params()["fill"] == 0.0
    assert "fill" not in GroundConfig(method="smrf", fill=1.0).method_params()
    with pytest.raises(ConfigError, match="ground.fill"):
        GroundConfig(fill=-1.0)


def test_fill_variants_of_the_benchmark():
    """The private variants ``bench_ground_vote.py`` measures: "limited" continues a plane
    from the nearest cell by the plane's own slope (so it fills a plane exactly, away from
    the last known row and column, beyond which the inpainting is flat), "max" /
    "min" bound the nearest height by the harmonic inpainting's, "gated" with a gate above
    every difference fills nothing; unknown variants raise InputError."""
    from lidar2city.ground.smrf_filter import _filled, _smrf_grids

    rows, cols = np.mgrid[0:20, 0:24].astype(np.float32)
    plane = 0.3 * rows - 0.2 * cols
    grid = plane.copy()
    grid[(rows % 3 != 0) | (cols % 3 != 0)] = np.nan
    done = ~np.isnan(_filled(grid, 1.5))
    inside = done.copy()
    inside[16:, :] = inside[:, 19:] = False
    limited = _filled(grid, 1.5, value="limited", step=3)
    np.testing.assert_allclose(limited[inside], plane[inside], atol=1e-4)
    near = _filled(grid, 1.5)
    assert np.abs(near[inside] - plane[inside]).max() > 0.15
    high, low = _filled(grid, 1.5, value="max"), _filled(grid, 1.5, value="min")
    assert (high[done] >= near[done]).all() and (low[done] <= near[done]).all()
    assert (high[done] >= low[done]).all()
    np.testing.assert_array_equal(np.isnan(high), np.isnan(near))
    from lidar2city.ground import smrf_filter

    gate = smrf_filter.FILL_GATE
    try:
        smrf_filter.FILL_GATE = 1e6
        np.testing.assert_array_equal(_filled(grid, 1.5, value="gated"), grid)
    finally:
        smrf_filter.FILL_GATE = gate
    xyz = make_terrain("terraces", spacing=2.5, seed=1).xyz
    for bad in ({"fill_value": "mean"}, {"fill_where": "x"}):
        with pytest.raises(InputError, match=next(iter(bad))):
            _smrf_grids(xyz, cell=1.0, slope=0.1, window=24.0, fill_radius=1.5, **bad)
