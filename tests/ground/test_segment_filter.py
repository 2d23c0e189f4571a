"""smrf_segments: SMRF's cut-away terrain segments given back (terrace tops), buildings kept."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import ConfigError, InputError
from lidar2city.ground import (
    GroundConfig,
    ground_mask,
    restore_segments,
    smrf_refined,
    smrf_segments,
)
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import make_terrain


def _terrace_and_building():
    """40 x 40 cells of flat ground at 0 m with a terrace band (x 20..29: a smooth ramp
    up to 2 m from its left side, a 2 m wall on its right side, running across the whole
    grid) and a 5 m building (x 5..12, y 5..12); both judged object."""
    z = np.zeros((40, 40), dtype=np.float32)
    z[:, 20:24] = np.linspace(0.5, 2.0, 4, dtype=np.float32)
    z[:, 24:30] = 2.0
    z[5:13, 5:13] = 5.0
    objects = np.zeros(z.shape, dtype=bool)
    objects[:, 20:30] = True
    objects[5:13, 5:13] = True
    return z, objects


def test_restore_gives_back_a_terrace_and_keeps_a_building():
    z, objects = _terrace_and_building()
    kept = restore_segments(z, objects, jump=0.6, raised=0.6)
    assert not kept[:, 20:30].any()            # the terrace joins the ground on one side
    assert kept[5:13, 5:13].all()              # walls all round: still object
    # empty cells (no points) do not count as boundary; a stricter fraction keeps the terrace
    z[::3, 14:18] = np.nan
    assert not restore_segments(z, objects, jump=0.6, raised=0.6)[:, 20:30].any()
    assert restore_segments(z, objects, jump=0.6, raised=0.4)[:, 20:30].all()
    # fragments smaller than min_cells stay object
    assert restore_segments(z, objects, jump=0.6, raised=0.6, min_cells=10**4)[:, 20:30].all()


def test_restore_degenerate_grids():
    empty = np.full((5, 5), np.nan, dtype=np.float32)
    objects = np.ones((5, 5), dtype=bool)
    np.testing.assert_array_equal(restore_segments(empty, objects, jump=1, raised=0.5), objects)
    flat = np.zeros((5, 5), dtype=np.float32)
    none = np.zeros((5, 5), dtype=bool)
    np.testing.assert_array_equal(restore_segments(flat, none, jump=1, raised=0.5), none)
    # all cells object: no terrain boundary, nothing given back
    np.testing.assert_array_equal(restore_segments(flat, objects, jump=1, raised=0.5), objects)


def test_segments_give_back_ground_smrf_cuts_between_buildings_on_a_slope():
    """Town on a slope at 1 m spacing: the opening (with edge extension) cuts ground
    between the buildings; the segments give it back and keep the buildings."""
    scene = make_terrain("town_on_slope", spacing=1.0, seed=3)
    plain = ground_errors(smrf_segments(scene.xyz, seg_rounds=0), scene.ground)
    seg = ground_errors(smrf_segments(scene.xyz), scene.ground)
    assert plain["type_i"] > 0.02                      # measured 2.67 % total
    assert seg["total"] < 0.005 and seg["type_ii"] < 0.005


@pytest.mark.parametrize("kind", ["hillside", "terraces", "cliff", "embankment", "bridge"])
def test_segments_on_synthetic_terrains(kind):
    scene = make_terrain(kind, spacing=1.0, seed=5)
    e = ground_errors(smrf_segments(scene.xyz), scene.ground)
    assert e["total"] < 0.03


def test_segments_rounds_zero_is_extended_smrf_and_params_validated():
    scene = make_terrain("cliff", spacing=2.0, seed=1)
    a = smrf_segments(scene.xyz)
    assert a.dtype == bool and a.shape == (len(scene.xyz),)
    shifted = smrf_segments(scene.xyz + np.array([500.0, -300.0, 80.0]))
    np.testing.assert_array_equal(a, shifted)
    np.testing.assert_array_equal(smrf_segments(scene.xyz, seg_rounds=0), smrf_refined(scene.xyz))
    for bad in ({"seg_rounds": -1}, {"min_cells": 1.5}, {"raised": 0.0}, {"raised": 1.5},
                {"jump": 0.0}, {"extend": -1.0}, {"scalar": -1.0}):
        with pytest.raises(InputError):
            smrf_segments(scene.xyz, **bad)
    assert smrf_segments(np.zeros((0, 3))).shape == (0,)
    assert ground_mask(scene.xyz, method="smrf_segments").shape == (len(scene.xyz),)


def test_segments_config():
    p = GroundConfig(method="smrf_segments").method_params()
    assert {"jump", "raised", "min_cells", "seg_rounds", "extend", "slope"} <= set(p)
    assert "rounds" not in p and "jump" not in GroundConfig(method="smrf").method_params()
    for bad, match in (({"raised": 0.0}, "ground.raised"), ({"jump": 0.0}, "ground.jump"),
                       ({"min_cells": -1}, "ground.min_cells"),
                       ({"seg_rounds": 1.5}, "ground.seg_rounds")):
        with pytest.raises(ConfigError, match=match):
            GroundConfig(method="smrf_segments", **bad)
