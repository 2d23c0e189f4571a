"""smrf_vote: a learnt vote over three SMRF surfaces (strict, lenient, plain)."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.errors import InputError
from lidar2city.ground import (
    VOTE_ABOVE,
    VOTE_ANCHOR,
    VOTE_FILL,
    VOTE_RULE,
    VOTE_VETO,
    GroundConfig,
    ground_mask,
    ring_ratios,
    smrf_vote,
    vote_features,
)
from lidar2city.ground.vote_filter import vote_rule
from lidar2city.metrics.ground import ground_errors
from lidar2city.synthetic_terrain import make_terrain


def _box_scene():
    g = np.stack(np.meshgrid(np.arange(80.0), np.arange(80.0)), -1).reshape(-1, 2)
    box = (abs(g[:, 0] - 40) < 6) & (abs(g[:, 1] - 40) < 6)
    return np.column_stack([g, np.where(box, 8.0, 0.0)]), ~box


def test_box_on_flat_ground_exact():
    xyz, ground = _box_scene()
    np.testing.assert_array_equal(smrf_vote(xyz), ground)


def test_features_are_the_three_surface_ratios_and_the_wall_distance():
    """On flat ground every ratio is 0; on the box roof (8 m up, tolerance 0.5 m) 16 for
    all three surfaces: the opening cuts a box at any slope and nothing gives it back.
    The wall distance is 0 on the box (all of it is cut at 45 degrees and steeper) and
    grows by a cell per cell away from it."""
    xyz, ground = _box_scene()
    features, out = vote_features(xyz)
    assert features.shape == (len(xyz), 4) and not out.any()
    np.testing.assert_allclose(features[ground, :3], 0.0, atol=1e-6)
    inner = (abs(xyz[:, 0] - 40) < 4) & (abs(xyz[:, 1] - 40) < 4)
    np.testing.assert_allclose(features[inner, :3], 16.0, atol=1e-3)
    box = ~ground
    assert (features[box, 3] == 0).all()
    east = (xyz[:, 1] == 40) & (xyz[:, 0] > 45)  # the box's last column is x = 45
    np.testing.assert_array_equal(features[east, 3], xyz[east, 0] - 45)


def test_wall_distance_far_from_walls_is_inf():
    """A plain 45 m hillside at 20 degrees has no wall: every distance is inf."""
    g = np.stack(np.meshgrid(np.arange(45.0), np.arange(45.0)), -1).reshape(-1, 2)
    features, _ = vote_features(np.column_stack([g, 0.36 * g[:, 0]]))
    assert np.isinf(features[:, 3]).all()


def test_rule_is_the_documented_tree():
    far = VOTE_RULE["clear"] + 1
    r = np.array([[1.0, 0.5, 9.0, 0],     # near strict, near lenient: ground
                  [1.0, 1.5, 0.0, far],   # near strict, off lenient: object
                  [2.0, 0.0, 0.9, 0],     # off strict, near plain SMRF: ground
                  [2.0, 0.0, 1.1, 0],     # off strict and plain, by a wall: object
                  [2.0, 0.95, 1.1, far],  # the same far from walls, lenient test passes: ground
                  [2.0, 1.05, 1.1, far],  # ... fails: object
                  [np.inf, np.inf, np.inf, far]])
    np.testing.assert_array_equal(vote_rule(r, **VOTE_RULE),
                                  [True, False, True, False, True, False, False])


def test_default_rule_is_a_vote_of_smrf_tests():
    """The default thresholds are SMRF's own test (ratio 1) on each surface (session 17:
    fitting them did not carry over to left-out samples, ``bench_ground_vote.py --fit
    selected``), so the default rule is a vote of SMRF tests: near the strict segment surface,
    the lenient one's test (and the veto's); farther, plain SMRF's, or the lenient one's away
    from walls or under walls that rise more than ``above``."""
    assert VOTE_RULE == {"near": 1.0, "steep": 1.0, "plain": 1.0, "clear": VOTE_RULE["clear"]}
    scene = make_terrain("town_on_slope", spacing=2.5, seed=2)
    f, out = vote_features(scene.xyz, fourth=0.4, rise=VOTE_RULE["clear"], anchor=VOTE_ANCHOR)
    ok = f[:, :3] <= 1.0
    away = (f[:, 3] > VOTE_RULE["clear"]) | (f[:, 5] > VOTE_ABOVE)
    expected = np.where(ok[:, 0], ok[:, 1] & (f[:, 4] <= VOTE_VETO),
                        ok[:, 2] | (ok[:, 1] & away)) & ~out
    assert expected.any() and not expected.all()
    np.testing.assert_array_equal(smrf_vote(scene.xyz), expected)


def test_steep_terraces_and_a_town_on_a_slope():
    """Scenes with known ground (bench_ground_vote.py: 0.65 % over the 14 synthetic
    scenes with the defaults of session 17, smrf_segments 1.11 %): terraces (measured
    0.00 %; 2.02 % without the wall distance), a town on a slope and an embankment
    (0.00 %)."""
    for kind, bound in (("terraces", 0.005), ("town_on_slope", 0.005), ("embankment", 0.005)):
        scene = make_terrain(kind, spacing=1.0, seed=1)
        assert ground_errors(smrf_vote(scene.xyz), scene.ground)["total"] <= bound, kind


def test_deterministic_translation_invariant_and_not_mutating():
    scene = make_terrain("town_on_slope", spacing=1.0, seed=3)
    xyz = scene.xyz.copy()
    a = smrf_vote(xyz)
    np.testing.assert_array_equal(xyz, scene.xyz)
    np.testing.assert_array_equal(a, smrf_vote(scene.xyz))
    np.testing.assert_array_equal(a, smrf_vote(scene.xyz + [0.0, 0.0, 250.0]))


def test_config_and_bad_parameters():
    params = GroundConfig(method="smrf_vote").method_params()
    assert "slope" not in params and params["extend"] == 10.0
    xyz, ground = _box_scene()
    np.testing.assert_array_equal(ground_mask(xyz, method="smrf_vote", **params), ground)
    with pytest.raises(InputError, match="near"):
        smrf_vote(xyz, near=0)
    with pytest.raises(InputError, match="slopes"):
        vote_features(xyz, slopes=(0.1,))
    with pytest.raises(InputError, match="lenient"):
        vote_features(xyz, slopes=(0.1, -1.0))
    assert smrf_vote(np.zeros((0, 3))).shape == (0,)


def test_veto_option_adds_a_fourth_surface_and_only_takes_ground_away():
    """``veto`` (VOTE_VETO by default) builds smrf_segments' surface at VETO_SLOPE as column 4
    of the features (the first four unchanged) and calls object a point near the strict surface
    but farther than the veto from the fourth one: never more ground than without it."""
    scene = make_terrain("town_on_slope", spacing=1.0, seed=1)
    base, out = vote_features(scene.xyz)
    more, out4 = vote_features(scene.xyz, fourth=0.4)
    assert more.shape == (len(scene.xyz), 5)
    np.testing.assert_array_equal(more[:, :4], base)
    np.testing.assert_array_equal(out4, out)
    plain = smrf_vote(scene.xyz, veto=None)
    np.testing.assert_array_equal(smrf_vote(scene.xyz, veto=np.inf), plain)
    default = smrf_vote(scene.xyz)
    np.testing.assert_array_equal(default, smrf_vote(scene.xyz, veto=VOTE_VETO))
    assert not (default & ~plain).any()
    strict = smrf_vote(scene.xyz, veto=0.05)
    assert not (strict & ~plain).any() and (plain & ~strict).any()
    near = more[:, 0] <= VOTE_RULE["near"]
    np.testing.assert_array_equal(plain & ~strict, plain & near & (more[:, 4] > 0.05))


def test_veto_bad_input():
    xyz, _ = _box_scene()
    with pytest.raises(InputError, match="veto"):
        smrf_vote(xyz, veto=0.0)
    with pytest.raises(InputError, match="fourth"):
        vote_rule(vote_features(xyz)[0], **VOTE_RULE, veto=1.0)


def test_veto_in_the_ground_config():
    """``ground.veto`` reaches smrf_vote (and only it); it must be > 0; inf turns it off."""
    from lidar2city.errors import ConfigError

    assert GroundConfig(method="smrf_vote", veto=0.8).method_params()["veto"] == 0.8
    assert "veto" not in GroundConfig(method="smrf_segments", veto=0.8).method_params()
    for bad in (0.0, -1.0):
        with pytest.raises(ConfigError, match="ground.veto"):
            GroundConfig(veto=bad)
    scene = make_terrain("terraces", spacing=1.0, seed=1)
    np.testing.assert_array_equal(
        ground_mask(scene.xyz, method="smrf_vote",
                    **GroundConfig(method="smrf_vote", veto=np.inf).method_params()),
        smrf_vote(scene.xyz, veto=None))


def test_above_option_gives_back_ground_at_the_foot_of_buildings():
    """Large buildings on a 22 % slope scanned at 2.5 m (``steep_town``, a kind held out of
    every fit): without ``above`` (nor the wall anchor) the vote calls a quarter of the
    narrow ground between them object (the walls are within ``clear``); with ``above`` the
    walls rising over that ground no longer count (bench_ground_vote.py: 25.6 % type I ->
    2.0 %). It only adds ground, only in the far branch, and needs the rise column. (Without
    the session-17 ``fill``, as measured then: with it the crest of the slope's scan at
    2.5 m changes too, 5.2 % type I.)"""
    scene = make_terrain("steep_town", spacing=2.5, seed=1)
    off = smrf_vote(scene.xyz, above=None, wall_anchor=None, fill=None)
    above = smrf_vote(scene.xyz, above=3.0, wall_anchor=None, fill=None)
    assert not (off & ~above).any()
    assert ground_errors(off, scene.ground)["type_i"] > 0.15
    assert ground_errors(above, scene.ground)["type_i"] < 0.05
    assert ground_errors(above, scene.ground)["type_ii"] == 0
    np.testing.assert_array_equal(smrf_vote(scene.xyz, above=np.inf, wall_anchor=None, fill=None),
                                  off)
    f, _ = vote_features(scene.xyz, fourth=0.4, rise=VOTE_RULE["clear"])
    assert f.shape == (len(scene.xyz), 6)
    np.testing.assert_array_equal(f[:, :5], vote_features(scene.xyz, fourth=0.4)[0])
    with pytest.raises(InputError, match="rise"):
        vote_rule(f[:, :5], **VOTE_RULE, veto=VOTE_VETO, above=3.0)
    with pytest.raises(InputError, match="above"):
        smrf_vote(scene.xyz, above=0.0)


def test_rise_is_the_lowest_wall_top_within_reach_above_the_point():
    """Beside the box of _box_scene (8 m, every cell of it a wall cell) the rise is 8 m
    within reach and inf beyond it."""
    xyz, ground = _box_scene()
    f, _ = vote_features(xyz, rise=5.0)
    east = (xyz[:, 1] == 40) & (xyz[:, 0] > 45)
    d = xyz[east, 0] - 45
    np.testing.assert_allclose(f[east, -1][d <= 5], 8.0, atol=1e-4)
    assert np.isinf(f[east, -1][d > 5]).all()


def test_above_in_the_ground_config():
    from lidar2city.errors import ConfigError

    assert GroundConfig(method="smrf_vote", above=3.0).method_params()["above"] == 3.0
    assert GroundConfig(method="smrf_vote").method_params()["above"] == VOTE_ABOVE
    with pytest.raises(ConfigError, match="ground.above"):
        GroundConfig(above=0.0)
    scene = make_terrain("steep_town", spacing=2.5, seed=1)
    np.testing.assert_array_equal(   # inf (what a TOML file can say) turns it off
        ground_mask(scene.xyz, method="smrf_vote",
                    **GroundConfig(method="smrf_vote", above=np.inf).method_params()),
        smrf_vote(scene.xyz, above=None))


def test_rise_bad_input():
    xyz, _ = _box_scene()
    with pytest.raises(InputError, match="rise"):
        vote_features(xyz, rise=0.0)


def _bench_between_houses():
    """A flat bench built up to 2 m out of a 20 % hillside between two 6 m high houses."""
    g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    row = (g[:, 1] >= 27) & (g[:, 1] < 33)
    bench = row & (g[:, 0] >= 20) & (g[:, 0] < 40)
    house = row & ((abs(g[:, 0] - 14) < 6) | (abs(g[:, 0] - 46) < 6))
    z = np.where(bench, 7.5, 0.2 * g[:, 1]) + np.where(house, 6.0, 0.0)
    return np.column_stack([g, z]), bench, house


def test_ring_ratios_bench_on_the_hillside_plane_roofs_above_it():
    """The bench's ratio to the plane of the hillside's ground around it is its fill over that
    plane (at most 2 m over a tolerance of 0.5 + 1.25 x 0.2 m), the roofs' their height; the
    hillside itself (no object patch) and excluded points are inf."""
    xyz, bench, house = _bench_between_houses()
    hill = ~(bench | house)
    r = ring_ratios(xyz, hill, cell=1.0)
    assert np.isinf(r[hill]).all()
    fill = xyz[bench, 2] - 0.2 * xyz[bench, 1]
    np.testing.assert_allclose(r[bench], np.abs(fill) / 0.75, atol=1e-6)
    assert (r[house] > 7).all()
    out = np.zeros(len(xyz), dtype=bool)
    out[np.flatnonzero(bench)[:3]] = True
    r2 = ring_ratios(xyz, hill, exclude=out, cell=1.0)
    assert np.isinf(r2[out]).all()
    # no ground around: nothing to fit
    assert np.isinf(ring_ratios(xyz, np.zeros(len(xyz), bool), cell=1.0)).all()


def test_ring_ratios_bad_input():
    xyz = _box_scene()[0]
    ok = np.ones(len(xyz), dtype=bool)
    with pytest.raises(InputError, match="ground_like"):
        ring_ratios(xyz, ok[:-1])
    with pytest.raises(InputError, match="reaches"):
        ring_ratios(xyz, ok, reaches=(6.0, 3.0))
    with pytest.raises(InputError, match="rms"):
        ring_ratios(xyz, ok, rms=0.0)
    with pytest.raises(InputError, match="xyz"):
        ring_ratios(xyz[:, :2], ok)


@pytest.mark.parametrize("neighbourhood", ["box", "dilation"])
def test_ring_option_only_gives_ground_back_near_the_lenient_surface(neighbourhood):
    """``ring`` (off by default) only adds ground, only where the lenient surface's test
    passes; on the town on a 22 % slope at 2.5 m (a kind held out of every fit) it gives back
    ground between the buildings (bench_ground_vote.py --ring: 5.50 -> 4.62 % with the box,
    as much with the exact ring of the dilation form; measured without the wall anchor and
    ``above``, the defaults until session 16, which give most of that ground back)."""
    scene = make_terrain("steep_town", spacing=2.5, seed=1)
    default = smrf_vote(scene.xyz, wall_anchor=None, above=None)
    ring = smrf_vote(scene.xyz, ring=1.25, ring_neighbourhood=neighbourhood, wall_anchor=None,
                     above=None)
    added = ring & ~default
    assert added.any() and not (default & ~ring).any()
    f, _ = vote_features(scene.xyz)
    assert (f[added, 1] <= 1.0).all()
    assert ground_errors(ring, scene.ground)["total"] < ground_errors(default,
                                                                      scene.ground)["total"]
    with pytest.raises(InputError, match="ring"):
        smrf_vote(scene.xyz, ring=0.0)


def test_ring_in_the_ground_config():
    from lidar2city.errors import ConfigError

    assert GroundConfig(method="smrf_vote", ring=1.25).method_params()["ring"] == 1.25
    assert GroundConfig(method="smrf_vote").method_params()["ring"] is None
    assert "ring" not in GroundConfig(method="smrf_segments", ring=1.25).method_params()
    with pytest.raises(ConfigError, match="ground.ring"):
        GroundConfig(ring=0.0)


def _ring_by_loop(xyz, ground_like, exclude, reaches=(3.0, 6.0, 12.0, 24.0), rms=0.3):
    """``ring_ratios(..., neighbourhood="dilation")`` the slow way: patch by patch, the ground
    cells within each reach (Chebyshev distance to the nearest cell of the patch, by brute
    force), a least-squares plane through their centres."""
    from lidar2city.ground._grid import grid_spec
    from lidar2city.ground.connect_filter import surface_patches

    p = surface_patches(xyz, exclude=exclude, cell=None, jump=0.6)
    h, w = p["shape"]
    cell = p["cell"]
    spec = grid_spec(xyz[:, :2], cell=cell)
    label, cells = p["label"], p["cells"]
    is_ground = ground_like[p["lowest"]]
    ratio = np.full(len(xyz), np.inf)
    point_label = np.where(exclude, -1, label[p["flat"]])
    for lab in np.unique(label[cells]):
        own = cells[label[cells] == lab]
        if len(own) < 4 or 2 * is_ground[label[cells] == lab].sum() >= len(own):
            continue
        ground = cells[is_ground & (label[cells] != lab)]
        dist = np.max(np.abs(np.stack([ground // w, ground % w])[:, :, None]
                             - np.stack([own // w, own % w])[:, None, :]), axis=0).min(axis=1)
        chosen = None
        for reach in reaches:
            ring = ground[dist <= np.ceil(reach / cell)]
            if len(ring) < 6:
                continue
            a = np.column_stack([(ring % w + 0.5) * cell, -(ring // w + 0.5) * cell,
                                 np.ones(len(ring))])
            coef, _, rank, _ = np.linalg.lstsq(a, p["zmin"][ring], rcond=None)
            if rank < 3:
                continue
            fit = np.sqrt(np.mean((a @ coef - p["zmin"][ring]) ** 2))
            if chosen is None or fit <= rms:
                chosen = coef
            if fit > rms:
                break
        if chosen is not None:
            pts = point_label == lab
            plane = (chosen[0] * (xyz[pts, 0] - spec.x0) + chosen[1] * (xyz[pts, 1] - spec.y_top)
                     + chosen[2])
            ratio[pts] = np.abs(xyz[pts, 2] - plane) / (0.5 + 1.25 * np.hypot(*chosen[:2]))
    return ratio


@pytest.mark.parametrize("kind,spacing", [("steep_town", 2.5), ("terraced_slope", 1.0),
                                          ("town_on_slope", 1.0)])
def test_ring_dilation_equals_the_loop_over_patches(kind, spacing):
    """The stacked, summed-area form of the ring (no loop over patches) gives the ratios of
    fitting each patch's ring of ground cells one by one."""
    scene = make_terrain(kind, spacing=spacing, seed=1)
    f, out = vote_features(scene.xyz, fourth=0.4)
    agreed = (f[:, :3] <= 1).all(axis=1) & (f[:, 4] <= 1)
    fast = ring_ratios(scene.xyz, agreed, exclude=out, neighbourhood="dilation")
    slow = _ring_by_loop(scene.xyz, agreed, out)
    assert np.isfinite(slow).sum() > 0
    np.testing.assert_array_equal(np.isfinite(fast), np.isfinite(slow))
    finite = np.isfinite(slow)
    np.testing.assert_allclose(fast[finite], slow[finite], rtol=1e-9, atol=1e-9)


def test_ring_dilation_keeps_the_plane_of_its_own_ground():
    """An L-shaped roof on a 20 % hillside with a terrace 3 m up beside its inner corner: the
    box grown around the L takes in the terrace (so its plane is off), the cells within
    reach of the L do not; the roof stays off the plane by its height either way."""
    g = np.stack(np.meshgrid(np.arange(60.0), np.arange(60.0)), -1).reshape(-1, 2)
    ell = (((g[:, 0] >= 20) & (g[:, 0] < 40) & (g[:, 1] >= 20) & (g[:, 1] < 26))
           | ((g[:, 0] >= 20) & (g[:, 0] < 26) & (g[:, 1] >= 20) & (g[:, 1] < 40)))
    terrace = (g[:, 0] >= 30) & (g[:, 1] >= 30)
    z = 0.2 * g[:, 1] + np.where(terrace, 3.0, 0.0) + np.where(ell, 6.0, 0.0)
    xyz = np.column_stack([g, z])
    box = ring_ratios(xyz, ~ell, cell=1.0, reaches=(3.0,))
    dil = ring_ratios(xyz, ~ell, cell=1.0, reaches=(3.0,), neighbourhood="dilation")
    # the roof is 6 m over the hillside: 6 / 0.75 = 8 tolerances off its plane
    assert np.allclose(dil[ell], 8.0 - 0.1 / 0.75, atol=1e-6)
    assert np.isfinite(box[ell]).all() and np.abs(box[ell] - 8.0).max() > 0.5


def test_ring_neighbourhood_bad_values_and_config():
    from lidar2city.errors import ConfigError

    scene = make_terrain("steep_town", spacing=2.5, seed=1)
    with pytest.raises(InputError, match="ring_neighbourhood"):
        smrf_vote(scene.xyz, ring=1.25, ring_neighbourhood="disk")
    with pytest.raises(InputError, match="neighbourhood"):
        ring_ratios(scene.xyz, scene.ground, neighbourhood="disk")
    config = GroundConfig(method="smrf_vote", ring=1.25, ring_neighbourhood="dilation")
    assert config.method_params()["ring_neighbourhood"] == "dilation"
    assert GroundConfig(method="smrf_vote").method_params()["ring_neighbourhood"] == "box"
    with pytest.raises(ConfigError, match="ground.ring_neighbourhood"):
        GroundConfig(ring_neighbourhood="disk")


@pytest.mark.parametrize("neighbourhood", ["box", "dilation"])
def test_ring_wanted_points_keep_their_ratios(neighbourhood):
    """``wanted`` only skips patches: a wanted point's ratio is the one computed for every
    point, and smrf_vote's ring (which asks only for the points it may give back) equals the
    rule on the full ratios."""
    scene = make_terrain("steep_town", spacing=2.5, seed=1)
    f, out = vote_features(scene.xyz, fourth=0.4)
    agreed = (f[:, :3] <= 1).all(axis=1) & (f[:, 4] <= 1)
    full = ring_ratios(scene.xyz, agreed, exclude=out, neighbourhood=neighbourhood)
    rule = vote_rule(f, **VOTE_RULE, veto=VOTE_VETO) & ~out
    wanted = (f[:, 1] <= 1.0) & ~rule & ~out
    assert 0 < wanted.sum() < np.isfinite(full).sum()
    part = ring_ratios(scene.xyz, agreed, exclude=out, neighbourhood=neighbourhood,
                       wanted=wanted)
    np.testing.assert_array_equal(part[wanted], full[wanted])
    assert np.isfinite(part).sum() < np.isfinite(full).sum()
    expected = rule | ((full <= 1.25) & (f[:, 1] <= 1.0) & ~out)
    got = smrf_vote(scene.xyz, ring=1.25, ring_neighbourhood=neighbourhood, wall_anchor=None,
                    above=None)
    np.testing.assert_array_equal(got, expected)
    with pytest.raises(InputError, match="wanted"):
        ring_ratios(scene.xyz, agreed, wanted=wanted[:-1])


def test_wall_anchor_keeps_a_building_and_frees_an_embankment():
    """``wall_anchor`` only removes walls: every wall distance stays or grows, and it is the
    same as without the option when the anchor slope is not steeper than WALL_SLOPE (every
    wall cell is then its own anchor). A box's vertical step anchors its region (the box
    scene is unchanged); the 20 % hillside cut into benches by continuous 45-60 degree
    risers (terraced_slope at 1 m, a kind held out of every fit) loses the risers' walls, so
    the lenient surface decides there (bench_ground_vote.py --wall-anchors: 9.58 -> 0.22 %
    at 2, the vote's rule at its defaults)."""
    from lidar2city.ground.vote_filter import WALL_SLOPE

    xyz, ground = _box_scene()
    np.testing.assert_array_equal(vote_features(xyz, anchor=2.0)[0], vote_features(xyz)[0])
    np.testing.assert_array_equal(smrf_vote(xyz, wall_anchor=2.0), ground)
    scene = make_terrain("terraced_slope", spacing=1.0, seed=1)
    plain, _ = vote_features(scene.xyz)
    anchored, _ = vote_features(scene.xyz, anchor=2.0)
    np.testing.assert_array_equal(anchored[:, :3], plain[:, :3])
    assert (anchored[:, 3] >= plain[:, 3]).all() and (anchored[:, 3] > plain[:, 3]).any()
    np.testing.assert_array_equal(vote_features(scene.xyz, anchor=WALL_SLOPE)[0], plain)
    before = ground_errors(smrf_vote(scene.xyz, wall_anchor=None), scene.ground)["total"]
    after = ground_errors(smrf_vote(scene.xyz, wall_anchor=2.0), scene.ground)["total"]
    assert after < 0.5 * before
    with pytest.raises(InputError, match="wall_anchor"):
        smrf_vote(scene.xyz, wall_anchor=0.0)
    with pytest.raises(InputError, match="anchor"):
        vote_features(scene.xyz, anchor=-1.0)


def test_wall_anchor_in_the_ground_config():
    from lidar2city.errors import ConfigError

    assert GroundConfig(method="smrf_vote", wall_anchor=2.0).method_params()["wall_anchor"] == 2.0
    assert GroundConfig(method="smrf_vote").method_params()["wall_anchor"] == VOTE_ANCHOR
    assert "wall_anchor" not in GroundConfig(method="smrf", wall_anchor=2.0).method_params()
    with pytest.raises(ConfigError, match="ground.wall_anchor"):
        GroundConfig(wall_anchor=0.0)
    scene = make_terrain("terraced_slope", spacing=1.0, seed=1)
    np.testing.assert_array_equal(   # 1 (what a TOML file can say) turns it off
        ground_mask(scene.xyz, method="smrf_vote",
                    **GroundConfig(method="smrf_vote", wall_anchor=1.0).method_params()),
        smrf_vote(scene.xyz, wall_anchor=None))


def test_anchor_at_most_the_wall_slope_is_no_anchor():
    """An anchor slope not steeper than WALL_SLOPE anchors every wall region: the same mask
    as no anchor, on scenes where the anchor 2 changes it."""
    from lidar2city.ground.vote_filter import WALL_SLOPE

    for kind, spacing in (("terraced_slope", 1.0), ("steep_town", 2.5)):
        scene = make_terrain(kind, spacing=spacing, seed=1)
        off = smrf_vote(scene.xyz, wall_anchor=None, large=None)
        assert (smrf_vote(scene.xyz, wall_anchor=2.0, large=None) != off).any()
        for anchor in (0.5, WALL_SLOPE):
            np.testing.assert_array_equal(
                smrf_vote(scene.xyz, wall_anchor=anchor, large=None), off)


def test_defaults_free_terrace_risers_and_ground_between_tall_buildings():
    """The defaults (session 16: ``wall_anchor`` VOTE_ANCHOR and ``above`` VOTE_ABOVE) on the
    kinds held out of every fit (bench_ground_vote.py --above-fixed): terraced_slope at 1 m
    9.58 -> 0.22 % total error, at 2.5 m 6.88 -> 6.25 %; steep_town at 2.5 m 5.50 -> 1.81 %
    (1 m: 0.00 % both). Each option alone moves only one of them: the anchor the risers,
    ``above`` the ground between the buildings. Measured without the session-17 ``fill``,
    which then (its default) takes both kinds at 2.5 m further down: terraced_slope 6.25 ->
    2.50 %, steep_town 1.81 -> 1.19 % (bench_ground_vote.py --fill 0 against the default);
    all without session 17's ``large``."""
    assert (VOTE_ANCHOR, VOTE_ABOVE) == (2.0, 6.0)

    def total(kind, spacing, **options):
        options.setdefault("fill", None)
        options.setdefault("large", None)  # session 17's large roofs: tests/ground/test_large.py
        scene = make_terrain(kind, spacing=spacing, seed=1)
        return ground_errors(smrf_vote(scene.xyz, **options), scene.ground)["total"]

    off = {"wall_anchor": None, "above": None}
    for kind, spacing in (("terraced_slope", 1.0), ("terraced_slope", 2.5),
                          ("steep_town", 1.0), ("steep_town", 2.5)):
        before, now = total(kind, spacing, **off), total(kind, spacing)
        assert now <= before, (kind, spacing)
        assert now == total(kind, spacing, wall_anchor=VOTE_ANCHOR, above=VOTE_ABOVE)
    assert total("terraced_slope", 1.0) < 0.01 < 0.05 < total("terraced_slope", 1.0, **off)
    assert total("steep_town", 2.5) < 0.03 < 0.05 < total("steep_town", 2.5, **off)
    assert total("terraced_slope", 1.0, above=None) < 0.01      # the anchor frees the risers
    assert total("steep_town", 2.5, wall_anchor=None) < 0.01    # above frees the ground
    assert total("steep_town", 2.5, above=None) > 0.05
    assert total("terraced_slope", 2.5, fill=VOTE_FILL) < 0.5 * total("terraced_slope", 2.5)
    assert total("steep_town", 2.5, fill=VOTE_FILL) < 0.8 * total("steep_town", 2.5)
    assert total("terraced_slope", 1.0, fill=VOTE_FILL) == total("terraced_slope", 1.0)
