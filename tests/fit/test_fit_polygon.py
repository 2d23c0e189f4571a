"""Polygon fitting: exact synthetic shapes come back as that shape, selection, DP ranking."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.errors import EmptyInputError, InputError
from lidar2city.fit.polygon import (
    PolygonFitConfig,
    douglas_peucker_ranking,
    fit_building_outline,
    overlap_error,
    polygon_sequence,
    region_contours,
    region_polygon,
    select_outline,
    split_overlaps,
)


def rasterise(verts, shape=(64, 80)):
    """Pixels whose centres are inside ``verts`` (pixel corner coordinates x, y)."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]] + 0.5
    return shapely.contains_xy(shapely.Polygon(verts), xx, yy)


def rotate(v, deg, c=(40.0, 32.0)):
    a = np.deg2rad(deg)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return (v - c) @ R.T + c


def noisy(mask, rng, n=6):
    """Flip ``n`` random boundary pixels (pixel noise)."""
    from scipy import ndimage

    edge = mask ^ ndimage.binary_erosion(mask)
    out_edge = ndimage.binary_dilation(mask) & ~mask
    m = mask.copy()
    for cand, val in ((np.argwhere(edge), False), (np.argwhere(out_edge), True)):
        pick = cand[rng.choice(len(cand), size=n // 2, replace=False)]
        m[pick[:, 0], pick[:, 1]] = val
    return m


SHAPES = {
    "rectangle": np.array([[22, 20], [58, 20], [58, 43], [22, 43.0]]),
    "right_trapezoid": np.array([[20, 20], [60, 20], [48, 44], [20, 44.0]]),
    "trapezoid": np.array([[26, 20], [54, 20], [64, 44], [16, 44.0]]),
    "composite": np.array([[20, 14], [60, 14], [60, 30], [38, 30], [38, 50], [20, 50.0]]),
}


def corner_errors(poly_m, truth_px):
    got = np.asarray(poly_m.exterior.coords)[:-1] * [1.0, -1.0]  # cell 1, y = -row
    assert len(got) == len(truth_px)
    d = np.hypot(*(got[:, None, :] - truth_px[None]).transpose(2, 0, 1))
    return d.min(axis=0)


@pytest.mark.parametrize("kind", list(SHAPES))
@pytest.mark.parametrize("angle", [0.0, 23.0, -37.0])
def test_shapes_come_back_with_subpixel_corners(kind, angle):
    rng = np.random.default_rng(7)
    truth = rotate(SHAPES[kind], angle)
    mask = noisy(rasterise(truth), rng)
    poly, got_kind, info = fit_building_outline(mask, cell=1.0)
    assert got_kind == kind, info["candidates"]
    assert poly.is_valid and poly.exterior.is_ccw
    # general trapezoids: both oblique legs are free and the overlap-error
    # minimum on a centre-sampled mask sits up to ~1.3 px from the true corner
    # at 23 degrees (the true polygon has a larger overlap error than the fit)
    tolerance = 1.5 if kind == "trapezoid" else 1.0
    assert corner_errors(poly, truth).max() < tolerance


def test_metres_offset_and_cell():
    truth = SHAPES["rectangle"]
    mask = rasterise(truth)
    poly, kind, _ = fit_building_outline(mask, cell=0.5, offset=(100.0, 200.0))
    assert kind == "rectangle"
    assert poly.area == pytest.approx(36 * 23 * 0.25, rel=0.02)
    minx, miny, maxx, maxy = poly.bounds
    assert minx == pytest.approx(100 + 22 * 0.5, abs=0.3)
    assert maxy == pytest.approx(200 - 20 * 0.5, abs=0.3)


def test_courtyard_is_kept():
    outer = np.array([[10, 10], [60, 10], [60, 50], [10, 50.0]])
    inner = np.array([[25, 22], [45, 22], [45, 38], [25, 38.0]])
    mask = rasterise(outer) & ~rasterise(inner)
    poly, kind, info = fit_building_outline(mask, cell=1.0)
    assert kind == "rectangle" and info["courtyards"] == 1
    assert len(poly.interiors) == 1
    assert poly.area == pytest.approx(50 * 40 - 20 * 16, rel=0.01)
    # a small hole is not a courtyard
    tiny = np.array([[30, 28], [32, 28], [32, 30], [30, 30.0]])
    _, _, info2 = fit_building_outline(rasterise(outer) & ~rasterise(tiny), cell=1.0)
    assert info2["courtyards"] == 0


def test_selection_follows_weights():
    truth = rotate(SHAPES["composite"], 12.0)
    mask = rasterise(truth)
    _, kind, info = select_outline(mask)
    assert kind == "composite"
    c = info["candidates"]
    assert c["composite"][0] == min(v[0] for v in c.values())
    # costs are error fraction + weight x complexity
    cfg = PolygonFitConfig()
    for k, (cost, err, cx) in c.items():
        w = cfg.polygon_weight if k == "polygon" else cfg.regular_weight
        assert cost == pytest.approx(err + w * cx)
    assert cfg.polygon_weight > cfg.regular_weight
    # regular shapes made expensive: the free polygon wins
    _, kind2, _ = select_outline(mask, regular_weight=0.2, polygon_weight=0.001)
    assert kind2 == "polygon"
    # restricted candidate list
    _, kind3, _ = select_outline(mask, shapes=("rectangle",))
    assert kind3 == "rectangle"
    with pytest.raises(InputError):
        select_outline(mask, shapes=("hexagon",))


def test_config_is_used():
    mask = rasterise(rotate(SHAPES["trapezoid"], 5.0))
    cfg = PolygonFitConfig(shapes=("rectangle", "polygon"))
    _, kind, _ = fit_building_outline(mask, cell=1.0, config=cfg)
    assert kind in ("rectangle", "polygon")


def test_overlap_error_exact():
    mask = rasterise(SHAPES["rectangle"])
    region = region_polygon(mask)
    assert overlap_error(shapely.box(22, 20, 58, 43), region)[0] == pytest.approx(0.0)
    assert overlap_error(shapely.box(22, 20, 59, 43), region)[0] == pytest.approx(23.0)
    assert overlap_error(shapely.box(23, 20, 58, 43), region)[0] == pytest.approx(23.0)


def test_contours_exterior_then_holes():
    m = np.zeros((20, 20), bool)
    m[2:18, 2:18] = True
    m[8:12, 8:12] = False
    rings = region_contours(m)
    assert len(rings) == 2
    assert rings[0][:, 0].min() == pytest.approx(2.0) and rings[0][:, 0].max() == pytest.approx(18.0)
    with pytest.raises(EmptyInputError):
        region_contours(np.zeros((5, 5), bool))


def test_dp_ranking_keeps_corners_first():
    sq = np.array([[0, 0], [5, 0], [10, 0], [10, 5], [10, 10], [5, 10], [0, 10], [0, 5.0]])
    cost, depth, order = douglas_peucker_ranking(sq)
    corners = {0, 2, 4, 6}
    assert set(order[:4].tolist()) == corners
    assert np.all(cost[[1, 3, 5, 7]] == 0)
    coords, offsets, counts = polygon_sequence(sq)
    assert counts.tolist() == [8, 7, 6, 5, 4]
    last = coords[offsets[-2]:offsets[-1]]
    assert shapely.Polygon(last).area == pytest.approx(100.0)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 50), st.floats(0, 50)), min_size=5, max_size=40, unique=True))
def test_dp_sequence_invariants(points):
    """Each polygon of the sequence keeps a subset of the previous one's vertices, in ring order."""
    pts = np.asarray(points)
    cost, depth, order = douglas_peucker_ranking(pts)
    assert sorted(order.tolist()) == list(range(len(pts)))
    assert np.all(cost >= 0)
    coords, offsets, counts = polygon_sequence(pts)
    prev = None
    for k in range(len(counts)):
        poly = coords[offsets[k]:offsets[k + 1]]
        assert len(poly) == counts[k]
        if prev is not None:
            assert {tuple(p) for p in poly} <= {tuple(p) for p in prev}
        prev = poly


def test_bad_inputs():
    with pytest.raises(EmptyInputError):
        fit_building_outline(np.zeros((10, 10), bool), cell=1.0)
    with pytest.raises(InputError):
        fit_building_outline(np.ones((10, 10), bool), cell=0.0)
    with pytest.raises(InputError):
        fit_building_outline(np.ones(10, bool), cell=1.0)


def test_small_noisy_buildings_select_their_shape():
    """Default weights on building-sized regions (4-8 x 6-14 px, 2 noisy pixels)."""
    rng = np.random.default_rng(0)
    hits = {"rectangle": 0, "right_trapezoid": 0}
    n = 12
    for _ in range(n):
        w, h = rng.uniform(4, 8), rng.uniform(6, 14)
        ang = rng.uniform(-45, 45)
        c = (30 + h / 2, 30 + w / 2)
        rect = np.array([[30, 30], [30 + h, 30], [30 + h, 30 + w], [30, 30 + w]])
        trap = np.array([[30, 30], [30 + h, 30], [30 + h - 0.6 * w, 30 + w], [30, 30 + w]])
        for kind, v in (("rectangle", rect), ("right_trapezoid", trap)):
            m = noisy(rasterise(rotate(v, ang, c)), rng, n=2)
            _, got, _ = fit_building_outline(m, cell=1.0)
            hits[kind] += got == kind
    assert hits["rectangle"] == n
    assert hits["right_trapezoid"] >= 0.7 * n


def test_oblique_legs_are_charged():
    """A leg off the main axes costs ``oblique_leg`` extra degrees of freedom."""
    # a rectangle with one leg 12 degrees off square: a right trapezoid by a small margin
    v = np.array([[20, 20], [60, 20], [60 - 24 * np.tan(np.deg2rad(12.0)), 44], [20, 44.0]])
    mask = rasterise(v)
    _, kind0, info0 = select_outline(mask, oblique_leg=0.0)
    assert kind0 == "right_trapezoid"
    assert info0["candidates"]["right_trapezoid"][2] == 5
    assert select_outline(mask)[1] == "right_trapezoid"  # the default charge keeps it
    _, kind1, info1 = select_outline(mask, oblique_leg=3.0)
    assert kind1 == "rectangle"
    c = info1["candidates"]
    assert c["right_trapezoid"][2] == pytest.approx(8.0)
    assert c["trapezoid"][2] == pytest.approx(12.0)
    # the leg is kept where it removes enough overlap error (30 degrees off square)
    v2 = np.array([[20, 20], [60, 20], [60 - 24 * np.tan(np.deg2rad(30.0)), 44], [20, 44.0]])
    assert select_outline(rasterise(v2))[1] == "right_trapezoid"
    with pytest.raises(InputError):
        select_outline(mask, oblique_leg=-1.0)


def test_large_regions_afford_more_edges():
    """The regular shapes' weight shrinks as sqrt(regular_cells / cells) on large regions."""
    # 40 x 50 cells with a 4 x 8 notch (1.6 % of the area): worth two more edges on a block of
    # 2,000 cells (weight 0.02 x sqrt(40 / 1960)), not at a flat 0.02 per edge
    v = np.array([[10, 8], [60, 8], [60, 40], [56, 40], [56, 48], [10, 48.0]])
    mask = rasterise(v, shape=(60, 72))
    _, kind, info = fit_building_outline(mask, cell=0.5)
    assert kind == "composite"
    assert info["error"] < 0.005
    _, kind0, info0 = fit_building_outline(mask, cell=0.5, regular_cells=0.0)
    assert kind0 == "rectangle"
    assert info0["error"] > 0.015
    # the same shape at a fifth of the size (80 cells) keeps the flat weight's choice
    small = rasterise(v / 5.0 + 2.0, shape=(16, 16))
    assert fit_building_outline(small, cell=0.5)[1] == fit_building_outline(
        small, cell=0.5, regular_cells=0.0)[1]
    with pytest.raises(InputError):
        fit_building_outline(mask, cell=0.5, regular_cells=-1.0)


def test_oblique_legs_keep_their_charge_on_large_regions():
    """The size scaling spares the oblique-leg charge: weight x oblique_leg at any size."""
    v = np.array([[10, 8], [60, 8], [60 - 40 * np.tan(np.deg2rad(10.0)), 48], [10, 48.0]])
    mask = rasterise(v, shape=(60, 72))
    _, kind, info = fit_building_outline(mask, cell=0.5)
    assert kind == "right_trapezoid"
    cells = float(mask.sum())
    w = 0.02 * np.sqrt(40.0 / cells)  # the scaled weight per degree of freedom
    cost, err, _ = info["candidates"]["right_trapezoid"]
    assert cost - err == pytest.approx(5 * w + 0.5 * 0.02)
    cost, err, _ = info["candidates"]["rectangle"]
    assert cost - err == pytest.approx(4 * w)


@pytest.mark.parametrize("angle", [0.0, 23.0, -37.0])
def test_split_overlaps_on_a_common_axis(angle):
    """Two row houses overlapping at their wall end on one straight wall; other axes stay."""
    import shapely.affinity

    c = (84900.0, 447500.0)  # world-sized coordinates: the cut must survive them
    a = shapely.affinity.rotate(shapely.box(84890.0, 447495.0, 84900.6, 447505.0), angle, c)
    b = shapely.affinity.rotate(shapely.box(84899.5, 447496.0, 84910.0, 447504.0), angle, c)
    pa, pb = split_overlaps([a, b])
    assert pa.is_valid and pb.is_valid
    assert pa.intersection(pb).area < 1e-3
    assert pa.union(pb).area == pytest.approx(a.union(b).area, abs=1e-2)
    # each keeps the half of the overlap on its side, cut along the shared axis
    assert pa.area == pytest.approx(a.area - 0.55 * 8.0, abs=1e-2)
    assert pb.area == pytest.approx(b.area - 0.55 * 8.0, abs=1e-2)
    from lidar2city.metrics.footprints import axis_alignment

    assert axis_alignment([pa, pb], tolerance_deg=0.1)["aligned_share"] == pytest.approx(1.0)
    # a neighbour 20 degrees off the first one's axes keeps its overlap
    d = shapely.affinity.rotate(b, 20.0, b.centroid)
    qa, qd = split_overlaps([a, d])
    assert qa.equals(a) and qd.equals(d)
    assert split_overlaps([a]) == [a]


@pytest.mark.parametrize("angle", [0.0, 30.0, 45.0])
def test_inset_outer_edges_moves_outer_edges_by_the_distance_in_any_direction(angle):
    """The inset is the same in metres on an axis and on a diagonal; shared edges stay."""
    from shapely import affinity
    from shapely.geometry.polygon import orient

    from lidar2city.fit.polygon import inset_outer_edges

    box = orient(affinity.rotate(shapely.box(0, 0, 12, 6), angle, origin=(0, 0)), 1.0)
    all_outer = [np.ones(4, bool)]
    g = inset_outer_edges(box, all_outer, 0.2)
    assert g.area == pytest.approx(11.6 * 5.6, rel=1e-9)
    assert g.within(box) and box.boundary.distance(g.boundary) == pytest.approx(0.2)
    # one edge shared: its line does not move
    flags = [np.array([True, False, True, True])]
    g1 = inset_outer_edges(box, flags, 0.2)
    xy = np.asarray(box.exterior.coords)
    shared = shapely.LineString(xy[1:3])
    long_shared = shared.length > 9
    assert g1.area == pytest.approx(11.6 * 5.8 if long_shared else 11.8 * 5.6, rel=1e-9)
    assert g1.boundary.distance(shared.interpolate(0.5, normalized=True)) < 1e-9
    assert inset_outer_edges(box, [np.zeros(4, bool)], 0.2) is box
    assert inset_outer_edges(box, all_outer, 0.0) is box
    assert inset_outer_edges(box, all_outer, 5.0) is box  # nothing sensible left
    with pytest.raises(InputError):
        inset_outer_edges(box, all_outer, -0.1)


def test_inset_outer_edges_grows_courtyards():
    from shapely.geometry.polygon import orient

    from lidar2city.fit.polygon import inset_outer_edges

    ring = orient(shapely.box(0, 0, 10, 10).difference(shapely.box(3, 3, 6, 6)), 1.0)
    g = inset_outer_edges(ring, [np.ones(4, bool), np.ones(4, bool)], 0.5)
    assert g.exterior.bounds == (0.5, 0.5, 9.5, 9.5)
    assert shapely.Polygon(g.interiors[0]).bounds == (2.5, 2.5, 6.5, 6.5)


def test_outer_edges_tells_background_from_neighbours():
    from lidar2city.fit.polygon import outer_edges

    lab = np.zeros((20, 30), np.int32)
    lab[4:14, 4:14] = 1
    lab[4:14, 14:24] = 2  # east of region 1
    cell = 0.5
    # region 1's outline in local metres (y north, the raster's top-left at 0, 0), ccw
    poly = shapely.Polygon([(2, -7), (7, -7), (7, -2), (2, -2)])
    flags = outer_edges(poly, lab, 1, cell=cell)[0]
    assert flags.tolist() == [True, False, True, True]  # the edge x = 7 faces region 2
    # near the raster's edge points off the grid count as background
    edge = shapely.Polygon([(0, -10), (15, -10), (15, 0), (0, 0)])
    assert outer_edges(edge, np.zeros((20, 30), np.int32), 1, cell=cell)[0].all()


def test_give_overlaps_to_the_pixel_owner_while_the_loser_stays_aligned():
    from lidar2city.fit.polygon import give_overlaps

    lab = np.zeros((20, 40), np.int32)
    lab[:, :20] = 1
    lab[:, 20:] = 2  # the wall at x = 10 m
    a = shapely.box(0, -10, 10, 0)
    b = shapely.Polygon([(9.6, -10), (20, -10), (20, 0), (9.2, 0)])  # 2.4 degrees off, into 1
    ga, gb = give_overlaps([a, b], lab, [1, 2], cell=0.5, min_aligned=0.0)
    assert ga.equals(a) and gb.intersection(ga).area < 1e-6
    assert (gb.union(ga)).area == pytest.approx(a.union(b).area, rel=1e-6)
    # the loser's cut follows the owner's edge on another axis: refused when it must stay
    # aligned and is no longer
    from shapely import affinity

    c = affinity.rotate(shapely.box(9.0, -9.0, 19.0, -1.0), 20.0)  # on axes 20 degrees off
    ga, gc = give_overlaps([a, c], lab, [1, 2], cell=0.5, min_aligned=0.99)
    assert ga.equals(a) and gc.equals(c)
    ga, gc = give_overlaps([a, c], lab, [1, 2], cell=0.5, min_aligned=0.0)
    assert gc.intersection(ga).area < 1e-6
    assert give_overlaps([a], lab, [1], cell=0.5) == [a]


def test_give_overlaps_allows_a_small_notch_off_the_losers_axes():
    from shapely import affinity

    from lidar2city.fit.polygon import _aligned_share, give_overlaps

    lab = np.zeros((40, 40), np.int32)
    lab[:20, :20] = 1  # a house: x 0-10 m, y -10-0 m
    lab[20:, 20:] = 2  # a shed to its south-east on axes 20 degrees off
    house = shapely.box(0, -10, 10, 0)
    # the shed's north-west corner reaches 0.7 m into the house's corner
    shed = affinity.rotate(shapely.box(9.3, -15.0, 14.0, -9.3), 20.0, origin=(9.3, -9.3))
    over = house.intersection(shed).area
    assert 0.1 < over < 1.5
    # the share rule alone refuses the notch in a small outline
    ga, gs = give_overlaps([house, shed], lab, [1, 2], cell=0.5, min_aligned=0.99)
    assert gs.equals(shed)
    ga, gs = give_overlaps([house, shed], lab, [1, 2], cell=0.5, min_aligned=0.99, max_notch=3.0)
    assert ga.equals(house) and gs.intersection(ga).area < 1e-6
    assert gs.area == pytest.approx(shed.area - over, abs=1e-2)
    assert _aligned_share(gs) < _aligned_share(shed)
    # a whole wall on the other's axes is more than a notch: still refused
    c = affinity.rotate(shapely.box(9.0, -9.0, 19.0, -1.0), 20.0)
    lab2 = np.zeros((20, 40), np.int32)
    lab2[:, :20], lab2[:, 20:] = 1, 2
    _, gc = give_overlaps([house, c], lab2, [1, 2], cell=0.5, min_aligned=0.99, max_notch=3.0)
    assert gc.equals(c)


def test_outlines_from_labels_insets_only_the_edges_facing_the_background():
    from lidar2city.tools.dsm import outlines_from_labels

    lab = np.zeros((40, 60), np.int32)
    lab[10:30, 10:30] = 1
    lab[10:30, 30:50] = 2  # two row houses: 10 x 10 m each at 0.5 m, sharing x = 15 m
    ndsm = np.where(lab > 0, 6.0, 0.0)
    out = {}
    for inset in (0.0, 0.25):
        res = outlines_from_labels(lab, ndsm, cell=0.5,
                                   fit_config=PolygonFitConfig(outline_inset=inset))
        out[inset] = [r.footprint for r in res]
    u0 = shapely.union_all(out[0.0])
    u1 = shapely.union_all(out[0.25])
    assert u0.area == pytest.approx(200.0, abs=0.5)
    # the block's outer ring moves in by 0.25 m all round; no gap opens at the shared wall
    assert u1.area == pytest.approx((20.0 - 0.5) * (10.0 - 0.5), abs=0.5)
    assert len(shapely.get_parts(u1)) == 1 and len(u1.interiors) == 0
    wall = shapely.LineString([(15.0, -5.5), (15.0, -14.5)])
    assert wall.within(u1.buffer(-0.01))
    with pytest.raises(InputError, match="outline_inset"):
        outlines_from_labels(lab, ndsm, cell=0.5, fit_config=PolygonFitConfig(outline_inset=-0.1))
