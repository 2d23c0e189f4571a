import numpy as np
import pytest
import shapely

from lidar2city.roof.building import reconstruct_lod22
from lidar2city.synthetic import make_town


@pytest.fixture(scope="module")
def town():
    return make_town(density=8, seed=0)


@pytest.fixture(scope="module")
def models(town):
    xyz = town.cloud.xyz
    pts = xyz[town.cloud.get("classification") == 6]
    return {b.id: reconstruct_lod22(b.footprint, pts, b.ground_z) for b in town.buildings}


def test_roof_types(town, models):
    expected = {"gable": "gable", "hip": "hip", "flat": "flat", "shed": "shed", "L": "flat",
                "courtyard": "flat", "stepped": "flat"}
    for b in town.buildings:
        assert models[b.id].attributes["roof_type"] == expected[b.roof_type], b.id


def test_roof_surface_matches_truth(town, models):
    from tests.roof.test_roof_solid import shell_errors

    for b in town.buildings:
        (solid,) = models[b.id].solids
        bad, vol = shell_errors(solid)
        assert not bad
        V = solid.vertices
        roofs = [s for s in solid.surfaces if s.semantic == "RoofSurface"]
        # the roof faces cover the footprint: their 2-D union is the footprint
        union = shapely.union_all([shapely.Polygon(V[s.rings[0], :2], [V[h, :2] for h in s.rings[1:]])
                                   for s in roofs])
        assert union.symmetric_difference(b.footprint).area < 1e-3 * b.footprint.area
        for s in roofs:
            P = V[s.rings[0]]
            poly = shapely.Polygon(P[:, :2]).buffer(-0.4)
            if poly.is_empty:
                continue
            # the face's plane against the true roof, on a grid inside the face
            (a, bb, c), *_ = np.linalg.lstsq(np.column_stack([P[:, :2], np.ones(len(P))]),
                                             P[:, 2], rcond=None)
            x0, y0, x1, y1 = poly.bounds
            gx, gy = np.meshgrid(np.arange(x0, x1, 0.5), np.arange(y0, y1, 0.5))
            q = np.column_stack([gx.ravel(), gy.ravel()])
            q = q[shapely.contains_xy(poly, q[:, 0], q[:, 1])]
            if not len(q):
                continue
            dz = a * q[:, 0] + bb * q[:, 1] + c - b.roof_z(q)
            dz = dz[np.isfinite(dz)]
            # within noise except next to a step edge placed a grid step off
            assert np.mean(np.abs(dz) < 0.2) > 0.95, (b.id, b.roof_type)


def test_step_edge_position(town, models):
    b = next(x for x in town.buildings if x.roof_type == "stepped")
    (solid,) = models[b.id].solids
    V = solid.vertices
    walls = [s for s in solid.surfaces if s.semantic == "WallSurface"]
    high = max(p.planes[0, 2] for p in b.parts)
    low_part, high_part = sorted(b.parts, key=lambda p: p.planes[0, 2])
    true_step = low_part.polygon.boundary.intersection(high_part.polygon.boundary)
    inner = [s for s in walls if np.all(shapely.contains_xy(b.footprint.buffer(-0.2),
                                                            V[s.rings[0], 0], V[s.rings[0], 1]))
             or np.isclose(V[s.rings[0], 2].max(), high, atol=0.3)
             and true_step.distance(shapely.Point(V[s.rings[0]][:, :2].mean(axis=0))) < 1.0]
    assert inner
    # the step edge comes from the label grid (0.5 m cells here) through the snake's grid:
    # within one and a half label cells of the truth
    for s in inner:
        for p in V[s.rings[0], :2]:
            assert true_step.distance(shapely.Point(p)) < 0.75


def test_ridges_land_on_truth(town, models):
    for b in town.buildings:
        if b.roof_type not in ("gable", "hip"):
            continue
        (solid,) = models[b.id].solids
        top = solid.vertices[np.isclose(solid.vertices[:, 2], solid.vertices[:, 2].max(), atol=0.05)]
        (x0, y0, z0), (x1, y1, z1) = b.ridges[0]
        assert abs(top[:, 2].max() - z0) < 0.15
        # ridge end points: horizontal distance to the true ridge segment
        seg = shapely.LineString([(x0, y0), (x1, y1)])
        d = [seg.distance(shapely.Point(p[:2])) for p in top]
        assert max(d) < 0.3, (b.id, d)


def test_eave_corners_land_on_truth(town, models):
    """Roof corners over the footprint corners sit at the true eave height."""
    for b in town.buildings:
        if b.roof_type not in ("gable", "hip", "shed", "flat"):
            continue
        (solid,) = models[b.id].solids
        V = solid.vertices
        roof_ids = np.unique(np.concatenate([np.concatenate(s.rings) for s in solid.surfaces
                                             if s.semantic == "RoofSurface"]))
        R = V[roof_ids]
        planes = b.parts[0].planes
        for cx, cy in np.asarray(b.footprint.exterior.coords)[:-1]:
            at = R[np.hypot(R[:, 0] - cx, R[:, 1] - cy) < 0.05]
            assert len(at), (b.id, cx, cy)
            true_z = np.min(planes[:, 0] * cx + planes[:, 1] * cy + planes[:, 2])
            assert abs(at[:, 2].max() - true_z) < 0.15, (b.id, b.roof_type)


def test_solids_are_validated_once_as_written():
    """With ``precision`` the solids come back on the output grid with the validator's
    issues of exactly those solids, and set_lod22 stores them without checking again."""
    from lidar2city.datamodel import BuildingResult
    from lidar2city.roof.solid import on_grid
    from lidar2city.synthetic_roofs import roof_sample
    from lidar2city.tools.reconstruct import set_lod22
    from lidar2city.validate.solid import check_solid

    s = roof_sample("hip", density=8, seed=0)
    plain = reconstruct_lod22(s.footprint, s.xyz, s.ground_z)
    res = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, precision=0.001)
    assert plain.issues is None and len(res.issues) == len(res.solids) == len(plain.solids)
    for a, b, found in zip(plain.solids, res.solids, res.issues, strict=True):
        assert np.array_equal(on_grid(a, 0.001).vertices, b.vertices)
        assert [str(i) for i in found] == [str(i) for i in check_solid(b)] == []
    r = BuildingResult("b")
    set_lod22(r, res.solids, res.attributes, checked=res.issues)
    assert r.solids["2.2"] is res.solids[0] and "lod22_fallback" not in r.attributes
    # issues found by the caller make the LoD1.2 prism stand in, with why
    from lidar2city.validate.solid import Issue

    r = BuildingResult("b")
    r.solids["1.2"] = "prism"
    set_lod22(r, res.solids, res.attributes, checked=[[Issue(306, 1, "crossing")]])
    assert r.solids["2.2"] == "prism" and "306" in r.attributes["lod22_fallback"]


def test_model_cost_is_bic_with_three_parameters_per_corner():
    """n log(SSE / n) + 3 log(n) corners, on a flat box roof: exact points cost the 1 mm floor,
    a point 0.5 m off adds its squared distance, and each corner costs 3 log(n)."""
    from lidar2city.roof.building import CORNER_PARAMETERS, model_cost

    fp = shapely.box(0, 0, 10, 6)
    g = np.stack(np.meshgrid(np.arange(0.5, 10, 1.0), np.arange(0.5, 6, 1.0)), -1).reshape(-1, 2)
    xyz = np.column_stack([g, np.full(len(g), 5.0)])
    res = reconstruct_lod22(fp, xyz, 0.0)
    n = len(xyz)
    assert CORNER_PARAMETERS == 3
    assert model_cost(xyz, res.solids) == pytest.approx(n * np.log(1e-6) + 3 * np.log(n) * 4)
    off = xyz.copy()
    off[27, 2] += 0.5
    assert model_cost(off, res.solids) == pytest.approx(n * np.log(0.25 / n) + 3 * np.log(n) * 4)


def test_select_keeps_the_model_of_least_cost():
    """With ``select`` the roof built three ways comes back as the one of least BIC (recomputed
    here from each variant alone), named in ``roof_model``; without it nothing changes."""
    from lidar2city.roof.building import Lod22Config, model_cost, select_variants
    from lidar2city.synthetic_roofs import roof_sample
    from lidar2city.validate.solid import check_solid

    s = roof_sample("dormer", density=8, seed=1)
    own = s.xyz[shapely.contains_xy(s.footprint, s.xyz[:, 0], s.xyz[:, 1])]
    cfg = Lod22Config(select=True)
    chosen = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=cfg, precision=0.001)
    costs = {}
    for name, c in select_variants(cfg):
        assert not c.select
        r = reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=c, precision=0.001)
        costs[name] = (model_cost(own, r.solids), r)
    best = min(costs, key=lambda k: costs[k][0])
    assert chosen.attributes["roof_model"] == best
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(chosen.solids, costs[best][1].solids,
                                                                       strict=True))
    assert all(not check_solid(x) for x in chosen.solids) and not any(chosen.issues)
    assert "roof_model" not in costs["default"][1].attributes
    # the variants differ on this roof (else the choice would test nothing)
    assert len({round(v[0], 6) for v in costs.values()}) > 1


def test_select_keeps_bad_input_reasons():
    """A roof cloud on one line gives the same stated reason with ``select``."""
    from lidar2city.errors import FitError
    from lidar2city.roof.building import Lod22Config

    xyz = np.column_stack([np.linspace(0, 9, 50), np.full(50, 3.0), np.full(50, 5.0)])
    with pytest.raises(FitError, match="one line"):
        reconstruct_lod22(shapely.box(0, 0, 10, 6), xyz, 0.0, config=Lod22Config(select=True))


def test_select_and_raised_parts_deterministic():
    """The same roof, points and options give the same solids and model twice."""
    from lidar2city.roof.building import Lod22Config
    from lidar2city.synthetic_roofs import roof_sample

    s = roof_sample("dormer", density=8, seed=2)
    cfg = Lod22Config(select=True, raised_parts=True)
    a, b = (reconstruct_lod22(s.footprint, s.xyz, s.ground_z, config=cfg, precision=0.001) for _ in range(2))
    assert a.attributes["roof_model"] == b.attributes["roof_model"]
    for x, y in zip(a.solids, b.solids, strict=True):
        assert np.array_equal(x.vertices, y.vertices)
        assert [[list(map(list, f.rings)), f.semantic] for f in x.surfaces] == \
            [[list(map(list, f.rings)), f.semantic] for f in y.surfaces]


def _roof_only_gable(slope_deg=45.0, spacing=0.35, seed=0):
    """A 5 x 4 m gable's roof points only (no walls, no ground), as a small City3D cloud."""
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.arange(0.1, 5.0, spacing), np.arange(0.1, 4.0, spacing))
    xy = np.column_stack([gx.ravel(), gy.ravel()]) + rng.normal(0, 0.03, (gx.size, 2))
    z = 10.0 + np.tan(np.radians(slope_deg)) * (2.0 - np.abs(xy[:, 1] - 2.0))
    return np.column_stack([xy, z + rng.normal(0, 0.03, len(z))])


@pytest.mark.parametrize("slope", [30.0, 50.0])
def test_roof_standing_on_the_floor_keeps_its_slopes(slope):
    # a cloud of roof points only, the floor taken at its lowest point (the eaves): the
    # sloped planes its points fit are the roof, not faces to flatten below the floor
    from lidar2city.metrics.model import model_rmse

    xyz = _roof_only_gable(slope)
    res = reconstruct_lod22(shapely.box(0, 0, 5, 4), xyz, float(xyz[:, 2].min()))
    assert res.attributes["roof_type"] == "gable"
    assert abs(res.attributes["main_slope"] - slope) < 3
    assert model_rmse(xyz, res.solids) < 0.1
    (solid,) = res.solids
    assert solid.vertices[:, 2].min() < xyz[:, 2].min() - 0.4  # walls below the eaves
    assert res.attributes["floor_lowered"] > 0


def test_part_floor_ignores_low_clutter_facets():
    # a sloped facet of a few points at ground level (clutter, a ramp) under a high roof
    # keeps the floor as given; the same roof standing on the floor lowers it
    from lidar2city.roof.building import part_floor

    roof = _roof_only_gable(40.0)
    gx, gy = np.meshgrid(np.arange(0.2, 1.4, 0.35), np.arange(0.2, 1.4, 0.35))
    clutter = np.column_stack([gx.ravel(), gy.ravel(), 0.1 + 0.3 * gx.ravel()])
    xyz = np.vstack([roof, clutter])
    labels = np.r_[np.where(roof[:, 1] < 2.0, 0, 1), np.full(len(clutter), 2)]
    t = np.tan(np.radians(40.0))
    planes = np.array([[0.0, t, 10.0], [0.0, -t, 10.0 + 4 * t], [0.3, 0.0, 0.1]])
    poly = shapely.box(0, 0, 5, 4)
    kw = dict(min_height=0.5, spacing=0.35)
    assert part_floor(poly, xyz, labels, planes, 0.0, **kw) == 0.0
    floor = part_floor(poly, roof, labels[:len(roof)], planes[:2], 10.0, **kw)
    assert floor == pytest.approx(10.0 - 1.0, abs=0.05)


def _flat_points(x1, y1, z, step=0.5):
    g = np.mgrid[step / 2:x1:step, step / 2:y1:step].reshape(2, -1).T
    return np.column_stack([g, np.full(len(g), z)])


def test_face_on_a_plane_far_above_its_points_is_replaned():
    """A small face given a steep plane fitted elsewhere (extrapolated 10 m above the
    points under it) must not make a spike: no roof vertex rises more than the
    tolerance above the building's points, and ridge_height is the model's top."""
    from shapely.geometry import box

    from lidar2city.roof.building import Lod22Config, _finish_solid

    poly = box(0, 0, 10, 10)
    pts = _flat_points(10, 10, 10.0)
    faces = [box(0, 0, 8, 10), box(8, 0, 10, 10)]
    planes = np.array([[0.0, 0.0, 10.0], [5.0, 0.0, -30.0]])  # z = 10 at x = 8, 20 at x = 10
    solid, faces2, labels2, planes2, _ = _finish_solid(
        "grid", poly, pts, faces, np.array([0, 1]), planes, 0.0, cell=0.5, cfg=Lod22Config(), info={})
    assert solid.vertices[:, 2].max() <= 10.0 + 2 * Lod22Config().elevation_error + 1e-9
    assert not _closed_shell_errors(solid)


def test_true_gable_faces_keep_their_planes():
    """The spike check leaves a roof whose planes the points support alone, ridge included."""
    from shapely.geometry import box

    from lidar2city.roof.building import _fix_high_faces

    rng = np.random.default_rng(0)
    g = rng.uniform(0, 10, (400, 2))
    z = 10.0 + 0.8 * (5 - np.abs(g[:, 0] - 5)) + rng.normal(0, 0.03, len(g))  # ridge at x = 5, 14 m
    pts = np.column_stack([g, z])
    faces = [box(0, 0, 5, 10), box(5, 0, 10, 10)]
    planes = np.array([[0.8, 0.0, 10.0], [-0.8, 0.0, 18.0]])
    faces2, labels, planes2 = _fix_high_faces(faces, np.array([0, 1]), planes, pts, spacing=0.5, t_step=0.3)
    assert faces2 is faces and labels.tolist() == [0, 1] and np.array_equal(planes2, planes)


def test_face_whose_plane_fits_its_points_is_capped_at_the_highest_point():
    """A shed face whose points stop 2 m before its high end keeps its plane up to a
    step above the highest point and gets a level cap beyond (the roof follows its points)."""
    from shapely.geometry import box

    from lidar2city.roof.building import _fix_high_faces

    g = np.mgrid[0.25:8:0.5, 0.25:10:0.5].reshape(2, -1).T  # no points over 8 < x < 10
    pts = np.column_stack([g, 10.0 + 1.5 * g[:, 0]])  # highest point 10 + 1.5 * 7.75
    faces, labels, planes = _fix_high_faces([box(0, 0, 10, 10)], np.array([0]),
                                            np.array([[1.5, 0.0, 10.0]]), pts, spacing=0.5, t_step=0.3)
    top = pts[:, 2].max() + 0.3
    assert len(faces) == 2 and sum(f.area for f in faces) == pytest.approx(100.0)
    assert planes[labels[1]].tolist() == [0.0, 0.0, top] and labels[0] == 0
    assert faces[0].bounds[2] == pytest.approx((top - 10.0) / 1.5)


def _closed_shell_errors(solid):
    from tests.roof.test_roof_solid import shell_errors

    return shell_errors(solid)[0]


def test_flat_roof_only_cloud_keeps_its_roof_at_its_points():
    """A flat roof of roof points only (City3D style: no wall, no ground), its floor at
    its lowest point: the floor goes under the roof, the roof stays at its points
    (it was lifted to floor + 2 min_height, ~0.9 m above every point)."""
    from lidar2city.metrics.model import model_rmse
    from lidar2city.roof.building import Lod22Config

    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform([0, 0], [6, 5], (300, 2)), 10.0 + rng.normal(0, 0.03, 300)])
    res = reconstruct_lod22(shapely.box(0, 0, 6, 5), xyz, float(xyz[:, 2].min()))
    (solid,) = res.solids
    t_step = 2 * Lod22Config().elevation_error
    assert res.attributes["roof_type"] == "flat"
    assert abs(solid.vertices[:, 2].max() - np.median(xyz[:, 2])) < t_step
    assert solid.vertices[:, 2].max() <= xyz[:, 2].max()
    assert solid.vertices[:, 2].min() < xyz[:, 2].min() - 0.5  # a wall under the roof
    assert res.attributes["floor_lowered"] > 0.5
    assert model_rmse(xyz, res.solids) < 0.1
    assert not _closed_shell_errors(solid)


def test_flat_low_part_of_a_higher_building_keeps_its_floor():
    """A traced part that is mostly ground at the floor (City3D cloud 8: ground behind the
    house) holds too few of the building's points to lower the building's floor."""
    from lidar2city.roof.building import part_floor

    ground_part = _flat_points(4, 3, 0.0)
    planes = np.array([[0.0, 0.0, 0.0]])
    labels = np.zeros(len(ground_part), dtype=np.int64)
    poly = shapely.box(0, 0, 4, 3)
    kw = dict(min_height=0.5, spacing=0.5)
    # alone (a flat roof-only cloud) its floor goes under it; as a sixth of a building, not
    assert part_floor(poly, ground_part, labels, planes, 0.0, **kw) == pytest.approx(-1.0)
    assert part_floor(poly, ground_part, labels, planes, 0.0, building_points=6 * len(ground_part),
                      **kw) == 0.0


def test_steep_face_of_a_sparse_survey_is_capped_half_a_spacing_up():
    """A 60 deg face sampled 2.8 m apart whose outline reaches 2.5 m past its last points:
    its plane puts that corner 4.3 m above every point (a rise over one spacing, the
    old allowance, is 4.8 m). Half a spacing is the most a ridge can lie from its
    nearest point, so the face is capped a step above its highest point."""
    from shapely.geometry import box

    from lidar2city.roof.building import _fix_high_faces

    t, s = np.tan(np.radians(60.0)), 2.8
    g = np.mgrid[0.2:7.0:s, 0.2:12:s].reshape(2, -1).T  # points up to x = 5.8, face to 8.3
    pts = np.column_stack([g, 300.0 + t * g[:, 0]])
    faces, labels, planes = _fix_high_faces([box(0, 0, 8.3, 12)], np.array([0]),
                                            np.array([[t, 0.0, 300.0]]), pts, spacing=s, t_step=0.3)
    assert len(faces) == 2 and planes[labels[1]][2] == pytest.approx(pts[:, 2].max() + 0.3)
    # the same face on a dense survey (0.35 m), a spacing past its points: a step of rise
    # allowed (Delft's steep mansard faces), the face keeps its plane
    g = np.mgrid[0.1:7.95:0.35, 0.1:12:0.35].reshape(2, -1).T
    pts = np.column_stack([g, 300.0 + t * g[:, 0]])
    faces2, labels2, _ = _fix_high_faces([box(0, 0, 8.3, 12)], np.array([0]),
                                         np.array([[t, 0.0, 300.0]]), pts, spacing=0.35, t_step=0.3)
    assert len(faces2) == 1 and labels2.tolist() == [0]


def test_saddle_repair_takes_a_plane_that_does_not_rise_over_the_face():
    """At a saddle the face takes a neighbour's plane: the longest-shared one unless that
    plane, carried over the face, rises above both faces (a slope extended over a large
    flat part: CSite1's b250 stood 1.97 m over its points); then the next neighbour's."""
    from shapely.geometry import box

    from lidar2city.roof.building import _plane_donor

    faces = [box(0, 0, 10, 10), box(10, 0, 11, 10), box(0, 10, 5, 11)]
    planes = np.array([[0.0, 0.0, 5.0], [-0.5, 0.0, 10.5], [0.0, 0.0, 4.9]])  # 10.5 m at x = 0
    labels = np.array([0, 1, 2])
    assert _plane_donor(faces, labels, planes, 0, [(10.0, 1), (5.0, 2)], 0.25) == 2
    planes[1] = [0.0, 0.0, 5.2]  # a level neighbour: the longest-shared, as before
    assert _plane_donor(faces, labels, planes, 0, [(10.0, 1), (5.0, 2)], 0.25) == 1
    planes[2] = [0.5, 0.0, 4.9]  # both rise (2.5 and 5 m): the one rising least
    planes[1] = [-0.5, 0.0, 10.5]
    assert _plane_donor(faces, labels, planes, 0, [(10.0, 1), (5.0, 2)], 0.25) == 2


def _gable_points():
    g = np.mgrid[0.25:10:0.5, 0.25:10:0.5].reshape(2, -1).T
    return np.column_stack([g, 10.0 + 0.8 * (5 - np.abs(g[:, 0] - 5))])  # ridge at x = 5


def test_an_open_last_variant_gives_way_to_the_first_one_repaired(monkeypatch):
    """When the partition left as refined (the last variant) gives an open shell whatever its
    saddle repair does, the short-edge-collapsed partition (the first variant) is repaired
    and kept when its shell closes and validates: the caller then needs no other partition
    (traced Delft's 1049 and 1293 m2 blocks built theirs twice). When the first variant's
    repaired shell is not valid either, the last variant's solid is returned as before."""
    from shapely.geometry import box

    import lidar2city.roof.building as B
    from lidar2city.datamodel import Solid

    poly = box(0, 0, 10, 10)
    faces = [box(0, 0, 5, 10), box(5, 0, 10, 10)]
    planes = np.array([[0.8, 0.0, 10.0], [-0.8, 0.0, 18.0]])
    collapsed = [box(0, 0, 5, 10), box(5, 0, 10, 5), box(5, 5, 10, 10)]  # another partition
    monkeypatch.setattr(B, "collapse_short_edges", lambda f, p, **kw: (collapsed, np.array([0, 1, 1])))
    real = B._variant_solid
    calls = []

    def opened(variants, planes, **kw):  # the first variant refused, the last one's shell open
        calls.append(len(variants))
        out = real(variants[-1:], planes, **kw)
        if len(variants) > 1 or fail_first[0]:
            out = (Solid(out[0].vertices, out[0].surfaces[1:]),) + out[1:]
        return out

    monkeypatch.setattr(B, "_variant_solid", opened)
    fail_first = [False]
    cfg = B.Lod22Config()
    solid, faces2, labels2, _, _ = B._finish_solid("arrangement", poly, _gable_points(), faces, np.array([0, 1]),
                                                   planes, 0.0, cell=0.5, cfg=cfg, info={})
    assert calls == [2, 1]
    assert B._closed_shell(solid) and not _closed_shell_errors(solid)
    assert len(faces2) == 3 and labels2.tolist() == [0, 1, 1]  # the collapsed partition's faces
    fail_first[0], calls[:] = True, []
    solid, faces2, _, _, _ = B._finish_solid("arrangement", poly, _gable_points(), faces, np.array([0, 1]),
                                             planes, 0.0, cell=0.5, cfg=cfg, info={})
    assert calls == [2, 1] and not B._closed_shell(solid) and len(faces2) == 2  # the last variant, open
