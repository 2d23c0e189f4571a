"""classify_points on a synthetic scene with known classes, invariants, and Delft."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.classify import ClassifyConfig, classify_points
from lidar2city.classify.core import _classify
from lidar2city.errors import ConfigError, EmptyInputError, InputError

GROUND, VEG, BUILDING, NOISE, WALL, CHIMNEY, OVERHANG = 2, 5, 6, 7, 66, 61, 55


def _grid(x0, x1, y0, y1, step, rng, jitter=0.3):
    xs = np.arange(x0 + step / 2, x1, step)
    ys = np.arange(y0 + step / 2, y1, step)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    return xy + rng.uniform(-jitter * step, jitter * step, xy.shape)


def scene(seed=0, step=0.35):
    """Ground with a gentle slope, a flat and a gable roof with walls, three trees, noise.

    Returns xyz, truth (2 ground, 5 tree, 6 roof, 66 wall, 7 noise),
    return_number, number_of_returns.
    """
    rng = np.random.default_rng(seed)
    parts, truth, rn, nr = [], [], [], []

    def terrain(xy):
        return 0.02 * xy[:, 0] + 0.01 * xy[:, 1]

    def add(xyz, label, r=None, n=None):
        parts.append(xyz)
        truth.append(np.full(len(xyz), label))
        rn.append(np.ones(len(xyz), int) if r is None else r)
        nr.append(np.ones(len(xyz), int) if n is None else n)

    # flat roof 14 x 10 m at 6 m, gable roof 10 x 16 m, eaves 5 m, ridge 8 m
    flat = (8.0, 22.0, 8.0, 18.0)
    gable = (34.0, 44.0, 6.0, 22.0)
    g = _grid(0, 60, 0, 50, step, rng)
    inside = np.zeros(len(g), bool)
    for x0, x1, y0, y1 in (flat, gable):
        inside |= (g[:, 0] > x0) & (g[:, 0] < x1) & (g[:, 1] > y0) & (g[:, 1] < y1)
    g = g[~inside]
    add(np.column_stack([g, terrain(g) + rng.normal(0, 0.02, len(g))]), GROUND)

    xy = _grid(*flat, step, rng)
    add(np.column_stack([xy, terrain(np.array([[15.0, 13.0]]))[0] + 6.0
                         + rng.normal(0, 0.02, len(xy))]), BUILDING)
    xy = _grid(*gable, step, rng)
    base = terrain(np.array([[39.0, 14.0]]))[0]
    z = base + 8.0 - 3.0 * np.abs(xy[:, 0] - 39.0) / 5.0
    add(np.column_stack([xy, z + rng.normal(0, 0.02, len(xy))]), BUILDING)
    # sparse wall points along the long sides of both buildings
    for x0, x1, y0, y1, top in ((*flat, 6.0), (*gable, 5.0)):
        for x in (x0, x1):
            yy = rng.uniform(y0, y1, 60)
            zz = rng.uniform(0.6, top - 0.3, 60)
            add(np.column_stack([np.full(60, x), yy, zz + terrain(np.column_stack([np.full(60, x), yy]))]), WALL)

    # a chimney 0.9 m x 0.9 m rising 2.5 m above the ridge: sides and a rough cap
    top = base + 10.5
    cx0, cy0 = 38.8, 12.0
    u = rng.uniform(0, 0.9, (40, 2))
    pts = [np.column_stack([cx0 + u[:, 0], cy0 + u[:, 1], top + rng.uniform(-0.4, 0.4, 40)])]
    for side in range(4):
        t = rng.uniform(0, 0.9, 25)
        zz = rng.uniform(base + 8.0 - 3.0 * 0.9 / 5.0, top, 25)
        x = cx0 + (t if side < 2 else np.full(25, 0.9 * (side - 2)))
        y = cy0 + (np.full(25, 0.9 * side) if side < 2 else t)
        pts.append(np.column_stack([x, y, zz]))
    add(np.concatenate(pts) + rng.normal(0, 0.02, (140, 3)), CHIMNEY)

    # trees: crowns as noisy ellipsoid volumes with multiple returns; one
    # overhangs the flat roof's east edge
    for cx, cy, label in ((52.0, 40.0, VEG), (20.0, 38.0, VEG), (28.0, 30.0, VEG),
                          (23.0, 13.0, OVERHANG)):
        m = 900
        d = rng.normal(size=(m, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        rad = rng.uniform(0.3, 1.0, m) ** 0.5
        zc = 7.0 if label == VEG else 9.5
        crown = np.column_stack([cx + 3.0 * rad * d[:, 0], cy + 3.0 * rad * d[:, 1],
                                 zc + 2.5 * rad * d[:, 2]])
        crown[:, 2] += terrain(crown[:, :2])
        n = rng.integers(2, 5, m)
        r = np.minimum(rng.integers(1, 4, m), n - 1)
        add(crown, label, r, n)
    # noise: birds high above, a multipath point deep under the terrain
    add(np.array([[30.0, 45.0, 40.0], [5.0, 5.0, 35.0]]), NOISE)
    add(np.array([[50.0, 10.0, -6.0]]), NOISE)
    xyz = np.concatenate(parts)
    return xyz, np.concatenate(truth), np.concatenate(rn), np.concatenate(nr)


@pytest.fixture(scope="module")
def synthetic():
    xyz, truth, rn, nr = scene()
    cls = classify_points(xyz, truth == GROUND, return_number=rn, number_of_returns=nr)
    return xyz, truth, rn, nr, cls


def test_ground_kept_exactly(synthetic):
    _, truth, _, _, cls = synthetic
    assert np.array_equal(cls == 2, truth == GROUND)


def test_roofs_are_building(synthetic):
    _, truth, _, _, cls = synthetic
    assert (cls[truth == BUILDING] == 6).mean() >= 0.98


def test_walls_join_their_building(synthetic):
    _, truth, _, _, cls = synthetic
    assert (cls[truth == WALL] == 6).mean() >= 0.8


def test_trees_are_high_vegetation(synthetic):
    _, truth, _, _, cls = synthetic
    assert (cls[truth == VEG] == 5).mean() >= 0.95
    assert not np.any(cls[truth == VEG] == 6)


def test_chimney_is_building(synthetic):
    _, truth, _, _, cls = synthetic
    assert (cls[truth == CHIMNEY] == 6).mean() >= 0.98


def test_tree_over_a_roof_is_vegetation(synthetic):
    xyz, truth, _, _, cls = synthetic
    over = truth == OVERHANG
    assert (cls[over] == 5).mean() >= 0.9
    # its part above the roof too
    above = over & (xyz[:, 0] < 22.0)
    assert above.sum() > 50 and (cls[above] == 5).mean() >= 0.85


def test_noise_points(synthetic):
    _, truth, _, _, cls = synthetic
    assert np.all(cls[truth == NOISE] == 7)
    assert (cls[truth != NOISE] == 7).sum() == 0


def test_every_point_gets_a_class(synthetic):
    xyz, _, _, _, cls = synthetic
    assert cls.dtype == np.uint8 and cls.shape == (len(xyz),)
    assert set(np.unique(cls)) <= {1, 2, 3, 4, 5, 6, 7}


def test_without_returns_roughness_still_separates():
    xyz, truth, _, _ = scene(seed=1)
    cls = classify_points(xyz, truth == GROUND)
    assert (cls[truth == BUILDING] == 6).mean() >= 0.98
    assert (cls[truth == VEG] == 5).mean() >= 0.9


def test_small_planar_object_is_no_building():
    """A 2 m x 2 m flat box at 2.5 m (smaller than min_building_area) is not building."""
    rng = np.random.default_rng(3)
    g = _grid(0, 30, 0, 30, 0.35, rng)
    box = _grid(10, 12, 10, 12, 0.35, rng)
    keep = ~((g[:, 0] > 10) & (g[:, 0] < 12) & (g[:, 1] > 10) & (g[:, 1] < 12))
    xyz = np.concatenate([np.column_stack([g[keep], np.zeros(keep.sum())]),
                          np.column_stack([box, np.full(len(box), 2.5)])])
    ground = np.zeros(len(xyz), bool)
    ground[: keep.sum()] = True
    cls = classify_points(xyz, ground)
    assert not np.any(cls == 6)
    # and a 12 m x 12 m one is
    big = _grid(10, 22, 10, 22, 0.35, rng)
    keep = ~((g[:, 0] > 10) & (g[:, 0] < 22) & (g[:, 1] > 10) & (g[:, 1] < 22))
    xyz = np.concatenate([np.column_stack([g[keep], np.zeros(keep.sum())]),
                          np.column_stack([big, np.full(len(big), 2.5)])])
    ground = np.arange(len(xyz)) < keep.sum()
    cls = classify_points(xyz, ground)
    assert (cls[~ground] == 6).all()


def test_ramp_reaching_the_ground_is_no_building():
    """A 6 m wide deck rising from the terrain to 5 m (a bridge approach)."""
    rng = np.random.default_rng(8)
    g = _grid(0, 50, 0, 30, 0.35, rng)
    deck = _grid(5, 45, 12, 18, 0.35, rng)
    on = (g[:, 1] > 12) & (g[:, 1] < 18) & (g[:, 0] > 5) & (g[:, 0] < 45)
    g = g[~on]
    z = np.minimum(deck[:, 0] - 5.0, 45.0 - deck[:, 0]) * 0.25  # up to 5 m mid-span
    xyz = np.concatenate([np.column_stack([g, np.zeros(len(g))]),
                          np.column_stack([deck, z])])
    ground = np.arange(len(xyz)) < len(g)
    ground[len(g):] = z < 0.05  # the ground filter takes the foot of the ramp
    cls = classify_points(xyz, ground)
    assert not np.any(cls == 6)
    # a flat roof of the same size at 5 m is a building
    roof = np.column_stack([deck, np.full(len(deck), 5.0)])
    xyz = np.concatenate([np.column_stack([g, np.zeros(len(g))]), roof])
    ground = np.arange(len(xyz)) < len(g)
    assert (classify_points(xyz, ground)[~ground] == 6).all()


def _steep_face_on_facade(rng, step=0.25):
    """Ground, and a 12 m long mono-pitch roof face at 60 degrees rising 7 m from
    a 5 m facade, joined by a rounded eave (radius 0.6 m) so that region growing
    chains the facade and the roof face into one region. Returns xyz, ground mask,
    roof-face mask."""
    r, top, rise, length = 0.6, 5.0, 7.0, 12.0
    ys = np.arange(step / 2, length, step)
    # eave arc in the x-z plane: from the facade's top (0, top), vertical,
    # round a centre (r, top) to where the surface rises at 60 degrees
    phi = np.linspace(0.0, np.radians(30.0), 4)
    ax, az = r - r * np.cos(phi), top + r * np.sin(phi)
    x_end, z_end = ax[-1], az[-1]
    run = rise / np.tan(np.radians(60.0))
    g = _grid(-10, 20, -10, 22, step, rng)
    g = g[~((g[:, 0] > 0) & (g[:, 0] < x_end + run) & (g[:, 1] > 0) & (g[:, 1] < length))]
    ground = np.column_stack([g, rng.normal(0, 0.02, len(g))])
    xy = _grid(x_end, x_end + run, 0, length, step, rng)
    face = np.column_stack([xy, z_end + (xy[:, 0] - x_end) * np.tan(np.radians(60.0))])
    gy, gi = np.meshgrid(ys, np.arange(len(phi)))
    eave = np.column_stack([ax[gi.ravel()], gy.ravel(), az[gi.ravel()]])
    wy, wz = np.meshgrid(ys, np.arange(0.3, top, step))
    facade = np.column_stack([np.zeros(wy.size), wy.ravel(), wz.ravel()])
    bld = np.concatenate([face, eave, facade])
    bld += rng.normal(0, 0.02, bld.shape)
    xyz = np.concatenate([ground, bld])
    gmask = np.arange(len(xyz)) < len(ground)
    face_mask = np.zeros(len(xyz), bool)
    face_mask[len(ground):len(ground) + len(face)] = True
    return xyz, gmask, face_mask


def test_steep_roof_face_chained_to_its_facade_is_building():
    """A 60-degree roof face grown into one region with the facade below fits no
    plane; its best-fit plane is steeper than max_facet_slope (70 degrees), so the
    region's steepness is read from its points' local normals: a roof, not a wall."""
    xyz, ground, face = _steep_face_on_facade(np.random.default_rng(21))
    out = _classify(xyz, ground)
    regions, obj = out["regions"], out["obj_idx"]
    lab = out["labels"][np.searchsorted(obj, np.flatnonzero(face))]
    main = np.bincount(lab[lab >= 0]).argmax()
    # the premise: face and facade are one region whose plane is too steep for a roof
    assert np.mean(lab == main) > 0.9
    on_facade = out["labels"][np.searchsorted(obj, np.flatnonzero(~ground & ~face))] == main
    assert on_facade.mean() > 0.5
    assert regions.normal[main, 2] < np.cos(np.radians(70.0))
    assert (out["classes"][face] == 6).mean() > 0.95
    # a lone wall (the facade without its roof) is still no building
    wall = ~face
    cls = classify_points(xyz[wall], ground[wall])
    assert not np.any(cls == 6)


def test_long_narrow_deck_is_no_building():
    """A flat 5 m x 50 m deck 6 m up with no ground contact (a footbridge over a river)
    is a linear structure; an 8 m x 40 m flat roof (a long row of houses) is a building."""
    rng = np.random.default_rng(12)
    g = _grid(0, 70, 0, 40, 0.35, rng)

    def scene_with(x0, x1, y0, y1):
        top = _grid(x0, x1, y0, y1, 0.35, rng)
        under = (g[:, 0] > x0) & (g[:, 0] < x1) & (g[:, 1] > y0) & (g[:, 1] < y1)
        xyz = np.concatenate([np.column_stack([g[~under], np.zeros((~under).sum())]),
                              np.column_stack([top, np.full(len(top), 6.0)])])
        return xyz, np.arange(len(xyz)) < (~under).sum()

    xyz, ground = scene_with(10, 60, 18, 23)
    assert not np.any(classify_points(xyz, ground) == 6)
    # the same deck turned by 35 degrees (a diagonal strip of grid cells)
    c, s_ = np.cos(np.radians(35.0)), np.sin(np.radians(35.0))
    centre = np.array([35.0, 20.0])
    turned = xyz.copy()
    turned[:, :2] = (xyz[:, :2] - centre) @ np.array([[c, s_], [-s_, c]]) + centre
    assert not np.any(classify_points(turned, ground) == 6)
    # the aspect test is what drops it
    off = classify_points(xyz, ground, config=ClassifyConfig(max_linear_aspect=0))
    assert (off[~ground] == 6).mean() > 0.9
    xyz, ground = scene_with(10, 50, 16, 24)
    assert (classify_points(xyz, ground)[~ground] == 6).all()


def test_low_points_by_height():
    """Rough multi-return bushes: medium vegetation above medium_height, low below."""
    rng = np.random.default_rng(4)
    g = _grid(0, 20, 0, 20, 0.35, rng)
    bush = np.column_stack([rng.uniform(8, 12, 400), rng.uniform(8, 12, 400),
                            rng.uniform(0.05, 1.8, 400)])
    xyz = np.concatenate([np.column_stack([g, np.zeros(len(g))]), bush])
    ground = np.arange(len(xyz)) < len(g)
    nr = np.where(ground, 1, 3)
    rn = np.where(ground, 1, 1)
    cls = classify_points(xyz, ground, return_number=rn, number_of_returns=nr)
    hb = bush[:, 2]
    cb = cls[~ground]
    assert np.all(cb[hb >= 0.6] == 4)
    assert np.all(cb[hb < 0.4] == 3)


def test_translation_invariant(synthetic):
    xyz, truth, rn, nr, cls = synthetic
    moved = classify_points(xyz + np.array([512.0, -256.0, 64.0]), truth == GROUND,
                            return_number=rn, number_of_returns=nr)
    assert (moved == cls).mean() >= 0.995


def test_deterministic_and_inputs_untouched():
    xyz, truth, rn, nr = scene(seed=2)
    copy = xyz.copy()
    a = classify_points(xyz, truth == GROUND, return_number=rn, number_of_returns=nr)
    b = classify_points(xyz, truth == GROUND, return_number=rn, number_of_returns=nr)
    assert np.array_equal(a, b)
    assert np.array_equal(xyz, copy)


def test_dense_data_is_thinned_for_features():
    """At ~100 pts/m2 the features run on a thinned copy and the result holds."""
    xyz, truth, rn, nr = scene(seed=5, step=0.1)
    d = _classify(xyz, truth == GROUND, return_number=rn, number_of_returns=nr)
    assert len(d["regions"].labels) < 0.6 * len(d["obj_idx"])
    cls = d["classes"]
    assert (cls[truth == BUILDING] == 6).mean() >= 0.98
    assert (cls[truth == VEG] == 5).mean() >= 0.9


def test_flat_roof_of_a_noisy_dense_survey_is_building():
    """A flat roof under 6 cm of height noise at 50 pts/m2 is building.

    Thinned to 0.2 m cubes, its mean local residual (about 0.044 m) passes the
    constant limit (half of max_residual, 0.04 m) and it was taken for a smooth
    crown; the limit follows the noise measured on the terrain.
    """
    rng = np.random.default_rng(0)
    g = _grid(0, 40, 0, 40, 0.14, rng)
    roof = (g[:, 0] > 12) & (g[:, 0] < 26) & (g[:, 1] > 15) & (g[:, 1] < 25)
    z = np.where(roof, 6.0, 0.0) + rng.normal(0, 0.06, len(g))
    d = _classify(np.column_stack([g, z]), ~roof)
    assert (d["classes"][roof] == 6).mean() >= 0.98
    assert 0.03 < d["noise_level"] < 0.06
    # a quiet survey keeps the configured limit
    z = np.where(roof, 6.0, 0.0) + rng.normal(0, 0.01, len(g))
    d = _classify(np.column_stack([g, z]), ~roof)
    assert d["roughness_limit"] == pytest.approx(ClassifyConfig().max_region_roughness)
    assert (d["classes"][roof] == 6).mean() >= 0.98


def test_hag_argument_is_used():
    xyz, truth, rn, nr = scene(seed=0)
    hag = np.zeros(len(xyz))  # everything on the terrain: nothing elevated
    cls = classify_points(xyz, truth == GROUND, hag=hag)
    assert not np.any(cls == 6) and not np.any(cls == 5)


def test_bad_inputs():
    xyz, truth, _, _ = scene(seed=0)
    with pytest.raises(InputError, match="xyz"):
        classify_points(xyz[:, :2], truth == GROUND)
    with pytest.raises(InputError, match="ground"):
        classify_points(xyz, (truth == GROUND)[:-1])
    with pytest.raises(InputError, match="boolean"):
        classify_points(xyz, (truth == GROUND).astype(int))
    bad = xyz.copy()
    bad[3, 2] = np.nan
    with pytest.raises(InputError, match="NaN"):
        classify_points(bad, truth == GROUND)
    with pytest.raises(EmptyInputError, match="ground"):
        classify_points(xyz, np.zeros(len(xyz), bool))
    with pytest.raises(InputError, match="rgb"):
        classify_points(xyz, truth == GROUND, rgb=np.zeros((3, 3)))
    with pytest.raises(ConfigError, match="classify.bogus"):
        classify_points(xyz, truth == GROUND, bogus=1)
    with pytest.raises(ConfigError, match="classify.min_height"):
        ClassifyConfig(min_height=-1)
    with pytest.raises(ConfigError, match="classify.max_region_roughness"):
        ClassifyConfig(max_region_roughness=0)


def test_empty_input():
    assert classify_points(np.zeros((0, 3)), np.zeros(0, bool)).shape == (0,)


def test_green_colour_is_a_vegetation_cue():
    """A smooth 3 m x 3 m patch at 3 m: 'other' when grey or without colour, vegetation when green."""
    rng = np.random.default_rng(6)
    g = _grid(0, 30, 0, 30, 0.35, rng)
    patch = _grid(10, 13, 10, 13, 0.35, rng)
    xyz = np.concatenate([np.column_stack([g, np.zeros(len(g))]),
                          np.column_stack([patch, np.full(len(patch), 3.0)])])
    ground = np.arange(len(xyz)) < len(g)
    plain = classify_points(xyz, ground)
    assert np.all(plain[~ground] == 1)
    grey = classify_points(xyz, ground, rgb=np.full((len(xyz), 3), 30000))
    assert np.all(grey[~ground] == 1)
    rgb = np.tile([[30000, 50000, 20000]], (len(xyz), 1))
    green = classify_points(xyz, ground, rgb=rgb)
    assert np.all(green[~ground] == 5)


@pytest.mark.slow
def test_delft_subset_building_f1(data):
    """A 100 m x 100 m part of the Delft tile against the AHN classes (ground from AHN).

    Measured: building F1 0.951, vegetation F1 0.930 (AHN class 1 as vegetation).
    """
    from lidar2city.io.las import read_points
    from lidar2city.metrics.classification import classification_scores

    cloud = read_points(data / "delft" / "ahn3_cropped_1.laz", crs="EPSG:28992")
    xyz = cloud.xyz
    sel = (xyz[:, 0] < 100) & (xyz[:, 1] < 100)
    ref = cloud.attributes["classification"][sel]
    cls = classify_points(xyz[sel], ref == 2,
                          return_number=cloud.attributes["return_number"][sel],
                          number_of_returns=cloud.attributes["number_of_returns"][sel])
    s = classification_scores(
        ref, cls, mapping={6: "building", 1: "vegetation", 2: "ground"},
        predicted_mapping={6: "building", 3: "vegetation", 4: "vegetation", 5: "vegetation",
                           2: "ground"}, ignore=(9, 26))
    assert s.f1["building"] >= 0.93, s.f1
    assert s.f1["vegetation"] >= 0.90, s.f1


def test_autzen_feet_rgb_no_false_buildings(data):
    """Autzen (international feet, RGB): a park with trees, a river bank and power
    lines but no building; the power lines and the footbridge must not become buildings,
    and the tree crowns must be high vegetation."""
    from lidar2city.io.las import read_points

    cloud = read_points(data / "misc" / "autzen_trim.laz")
    a = cloud.attributes
    assert cloud.xy_unit == pytest.approx(0.3048)
    rgb = np.column_stack([a["red"], a["green"], a["blue"]])
    cls = classify_points(cloud.xyz, a["classification"] == 2, return_number=a["return_number"],
                          number_of_returns=a["number_of_returns"], rgb=rgb)
    assert (cls == 6).mean() < 0.001
    assert (cls == 5).sum() > 10_000


def test_far_outlier_is_noise_and_changes_nothing(synthetic):
    """A stray point kilometres away (bad GPS) must not inflate grids or spacing."""
    xyz, truth, rn, nr, cls = synthetic
    far = np.vstack([xyz, [[5000.0, -3000.0, 30.0]]])
    out = classify_points(far, np.r_[truth == GROUND, False], return_number=np.r_[rn, 1],
                          number_of_returns=np.r_[nr, 1])
    assert out[-1] == 7
    assert (out[:-1] == cls).mean() >= 0.995


def test_building_grid_geometry_locates_the_points():
    # the building grid's origin and cell, as returned, put every object point in
    # the cell the classifier used for it (diagnostics and figures map the outline with them)
    xyz, truth, rn, nr = scene(seed=2)
    out = _classify(xyz, truth == GROUND, return_number=rn, number_of_returns=nr)
    grid, cell = out["building_grid"], out["cell"]
    x0, y0 = out["grid_origin"]
    assert cell >= ClassifyConfig().cell and grid.any()
    p = xyz[out["obj_idx"]]
    j = np.floor((p[:, 0] - x0) / cell).astype(int)
    i = np.floor((p[:, 1] - y0) / cell).astype(int)
    assert i.min() >= 0 and j.min() >= 0 and i.max() < grid.shape[0] and j.max() < grid.shape[1]
    assert np.array_equal(grid[i, j], out["in_building"])
