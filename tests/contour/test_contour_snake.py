import dataclasses

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.contour import (
    ActiveContourConfig,
    PixelFrame,
    active_contour_outlines,
    evaluation_domain,
    evolve_contours,
    gradient_vector_flow,
    linked_edges,
    prepare_scene,
    rasterize_polygons,
    resample_contour,
)
from lidar2city.contour.snake import _labels
from lidar2city.errors import ConfigError, InputError

# a 28 x 30 px building, 8 m high, on flat ground with noise; its outline in
# (row, col) pixel-centre coordinates runs half a pixel outside the pixels
ROWS, COLS = slice(15, 45), slice(12, 40)
TRUTH = shapely.box(11.5, 14.5, 39.5, 44.5)  # (x = col, y = row)


def _scene(seed=0):
    rng = np.random.default_rng(seed)
    dsm = np.zeros((60, 60))
    dsm[ROWS, COLS] = 8.0
    dsm += rng.normal(0.0, 0.2, dsm.shape)
    return dsm, prepare_scene(dsm, dsm, cell=1.0)


def _iou(contour):
    p = shapely.make_valid(shapely.Polygon(contour[:, ::-1]))
    return p.intersection(TRUTH).area / p.union(TRUTH).area


@pytest.mark.parametrize("corners", [
    [[18, 15], [18, 36], [41, 36], [41, 15]],   # inside, 3 px short of every edge
    [[12, 9], [12, 43], [48, 43], [48, 9]],     # outside, 3 px beyond
    [[17, 14], [17, 42], [47, 42], [47, 14]],   # shifted by 2-3 px
])
@pytest.mark.parametrize("weights", [
    (0.2, 0.2, 1.0, 0.0, 0.0),   # GVF alone
    (0.2, 0.2, 0.0, 1.0, 0.0),   # regional variance alone
    (0.2, 0.2, 1.0, 1.0, 1.0),   # all terms
])
@pytest.mark.parametrize("local_sigma", [0.0, 3.0])
def test_snake_converges_onto_rectangle(corners, weights, local_sigma):
    _, sc = _scene()
    rng = np.random.default_rng(1)
    init = resample_contour(np.array(corners, float), 1.0)
    init = init + rng.normal(0.0, 0.5, init.shape)
    assert _iou(init) < 0.8
    a, b, g, m, e = weights
    out = evolve_contours([init], sc.gvf, sc.image, sc.ndsm, alpha=a, beta=b, gamma=g, mu=m,
                          epsilon=e, max_iter=300, local_sigma=local_sigma)[0]
    assert _iou(out) > 0.9


def test_local_statistics_keep_a_low_annex_of_a_tall_building():
    # a 15 m block with a 4 m annex: one mean inside (about 11 m) puts the
    # mid-height above the annex, local means give each part its own
    nd = np.zeros((60, 70))
    nd[15:45, 10:35] = 15.0
    nd[20:40, 35:55] = 4.0
    truth = shapely.box(9.5, 14.5, 34.5, 44.5).union(shapely.box(34.5, 19.5, 54.5, 39.5))
    init = resample_contour(np.array([[13, 8], [13, 57], [47, 57], [47, 8]], float), 1.0)
    gvf = np.zeros((2,) + nd.shape)

    def iou(c):
        p = shapely.make_valid(shapely.Polygon(c[:, ::-1]))
        return p.intersection(truth).area / p.union(truth).area

    kw = dict(alpha=0.1, beta=0.1, gamma=0.0, max_iter=300)
    # regional term (DSM means): one mean per contour loses the annex
    local = evolve_contours([init], gvf, nd, nd, mu=1.0, epsilon=0.0, local_sigma=3.0, **kw)[0]
    whole = evolve_contours([init], gvf, nd, nd, mu=1.0, epsilon=0.0, local_sigma=0.0, **kw)[0]
    assert iou(local) > 0.95
    assert iou(whole) < 0.8
    # altitudinal term: pulled off the flat ground (small variance) onto both parts
    local = evolve_contours([init], gvf, nd, nd, mu=0.0, epsilon=1.0, local_sigma=3.0, **kw)[0]
    assert iou(local) > 0.95


def test_gvf_points_toward_a_known_edge():
    # edge map: a vertical line at column 20
    f = np.zeros((41, 41))
    f[:, 20] = 1.0
    g = gradient_vector_flow(f, mu=0.2, max_iter=2000)
    rows = slice(5, 36)
    left, right = g[1][rows, 5:18], g[1][rows, 23:36]
    assert (left > 0).all()      # columns increase toward the edge
    assert (right < 0).all()
    assert np.abs(g[0][rows, 5:36]).max() < 1e-6 + 0.05 * np.abs(g[1][rows, 5:36]).max()
    # the flow reaches far from the edge (plain gradients are zero there)
    assert abs(g[1][20, 8]) > 0


def test_gvf_of_a_square_points_to_its_outline():
    f = np.zeros((50, 50))
    f[15, 15:35] = f[34, 15:35] = f[15:35, 15] = f[15:35, 34] = 1.0
    g = gradient_vector_flow(f, mu=0.2, max_iter=3000)
    # just outside the right side the flow points left, inside it points right
    assert g[1][25, 40] < 0 and g[1][25, 30] > 0
    assert g[0][8, 25] > 0 and g[0][19, 25] < 0


def test_outlines_of_a_synthetic_building_in_metres():
    dsm, _ = _scene()
    polys = active_contour_outlines(dsm, dsm, cell=0.5, transform=(0.5, 0, 100.0, 0, -0.5, 200.0),
                                    origin=(100.0, 200.0))
    assert len(polys) == 1
    # the building spans cols 12..40, rows 15..45 of 0.5 m pixels; the outline is
    # drawn 0.5 m inside the DSM's roof edge (edge_inset, force_offset: the walls of
    # a highest-point DSM with eaves)
    truth = shapely.box(6.5, -22.0, 19.5, -8.0)
    p = polys[0]
    assert p.intersection(truth).area / p.union(truth).area > 0.9
    # without the offsets, on the DSM's edge
    cfg = ActiveContourConfig(force_offset=0.0, anchor=0.0)
    polys = active_contour_outlines(dsm, dsm, cell=0.5, transform=(0.5, 0, 100.0, 0, -0.5, 200.0),
                                    origin=(100.0, 200.0), config=cfg)
    edge = shapely.box(6.0, -22.5, 20.0, -7.5)
    assert polys[0].intersection(edge).area / polys[0].union(edge).area > 0.9


def test_outlines_do_not_mutate_inputs_and_ortho_is_used():
    dsm, _ = _scene()
    before = dsm.copy()
    ortho = np.where(dsm > 4, 200.0, 50.0)
    polys = active_contour_outlines(dsm, dsm, ortho=ortho, cell=1.0)
    assert np.array_equal(dsm, before)
    assert len(polys) == 1
    with pytest.raises(InputError):
        active_contour_outlines(dsm, dsm, ortho=ortho[:10], cell=1.0)


def test_flat_dsm_has_no_building():
    z = np.full((30, 30), 5.0)
    assert active_contour_outlines(z, np.zeros_like(z)) == []


def test_trees_removed_by_roughness():
    rng = np.random.default_rng(4)
    dsm = np.zeros((60, 60))
    dsm[10:30, 10:30] = 8.0                       # flat roof
    dsm[35:55, 35:55] = 8.0 + rng.uniform(-3, 3, (20, 20))  # rough canopy
    cfg = ActiveContourConfig(max_roughness=0.5)
    sc = prepare_scene(dsm, dsm, cell=1.0, config=cfg)
    assert len(sc.contours) == 1
    assert sc.contours[0][:, 0].max() < 31


def test_linked_edges_close_small_gaps_and_drop_short_chains():
    z = np.zeros((40, 40))
    z[10:30, 10:30] = 6.0
    e = linked_edges(z, min_length=4)
    assert e.any()
    z2 = z.copy()
    z2[2, 2] = 6.0   # a one-pixel spike gives a short chain
    e2 = linked_edges(z2, min_length=12)
    assert not e2[:6, :6].any()


def test_weights_validated():
    with pytest.raises(ConfigError):
        ActiveContourConfig(alpha=-1.0)
    with pytest.raises(ConfigError):
        ActiveContourConfig().with_weights([1, 2, 3])
    with pytest.raises(ConfigError):
        ActiveContourConfig().with_weights({"delta": 1.0})
    assert ActiveContourConfig().with_weights([0, 1, 2, 3, 0, 1]).mu == 3
    with pytest.raises(ConfigError):  # the anchor is the sixth weight
        ActiveContourConfig().with_weights([0, 1, 2, 3, 0])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-5, 35), st.floats(-5, 35)), min_size=3, max_size=10))
def test_scanline_labels_match_even_odd_polygon_fill(pts):
    from skimage.draw import polygon

    c = np.array(pts, dtype=np.float64)
    lab = _labels([c], (30, 30))
    rr, cc = polygon(c[:, 0], c[:, 1], (30, 30))
    ref = np.zeros((30, 30), dtype=np.int32)
    ref[rr, cc] = 1
    # pixel centres on the outline itself are a matter of convention: skip them
    ring = shapely.LinearRing(np.vstack([c[:, ::-1], c[:1, ::-1]])) if len(np.unique(c, axis=0)) > 2 else None
    for r, col in zip(*np.nonzero(lab != ref), strict=True):
        assert ring is None or ring.distance(shapely.Point(col, r)) < 1e-6


@settings(max_examples=25, deadline=None)
@given(st.floats(-50, 50), st.floats(-50, 50), st.integers(8, 60))
def test_resample_keeps_ring_closed_and_spacing(dx, dy, n):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.column_stack([10 * np.sin(t) + dy, 10 * np.cos(t) + dx])
    out = resample_contour(ring, 1.0)
    seg = np.hypot(*np.diff(np.vstack([out, out[:1]]), axis=0).T)
    assert len(out) >= 8
    assert seg.max() < 1.2 and seg.min() > 0.5


def test_pixel_frame_round_trip_and_rasterize():
    fr = PixelFrame((2.0, 0, 1000.0, 0, -2.0, 5000.0), origin=(1000.0, 5000.0))
    rc = np.array([[0.0, 0.0], [3.5, 7.25]])
    assert np.allclose(fr.to_pixel(fr.to_local(rc)), rc)
    assert np.allclose(fr.to_local([0, 0]), [1.0, -1.0])
    mask = rasterize_polygons([shapely.box(2.0, -8.0, 6.0, -4.0)], (10, 10), fr)
    assert mask.sum() == 4 and mask[2:4, 1:3].all()


def test_evaluation_domain_excludes_border_and_cut_objects():
    ref = np.zeros((40, 40), bool)
    ref[10:15, 10:15] = True
    ref[20:25, 20:28] = True
    objects = ref.copy()
    objects[30:40, 0:8] = True       # a building cut by the raster edge
    dom = evaluation_domain(ref, objects, buffer=20, edge_margin=2)
    assert dom[12, 12] and dom[22, 22]
    assert not dom[0].any() and not dom[:, -1].any()
    assert not dom[30:38, 2:8].any()
    with pytest.raises(InputError):
        evaluation_domain(np.zeros((5, 5), bool))


def test_anchor_keeps_a_good_start_and_offset_moves_the_edge_inward():
    from lidar2city.contour.outlines import start_signed_distance

    _, sc = _scene()
    start = resample_contour(np.array([[14.5, 11.5], [14.5, 39.5], [44.5, 39.5], [44.5, 11.5]]), 1.0)
    region = np.zeros((60, 60), int)
    region[ROWS, COLS] = 1
    sd = start_signed_distance(region)
    assert sd[ROWS, COLS].max() < 0 < sd[0, 0]
    assert sd[15, 20] == pytest.approx(-0.5) and sd[14, 20] == pytest.approx(0.5)
    # a stiff snake without image forces shrinks; the anchor holds it on its start
    kw = dict(alpha=2.0, beta=2.0, gamma=0.0, mu=0.0, epsilon=0.0, max_iter=100)
    free = evolve_contours([start], sc.gvf, sc.image, sc.ndsm, **kw)[0]
    held = evolve_contours([start], sc.gvf, sc.image, sc.ndsm, anchor=3.0, start_distance=sd, **kw)[0]
    assert _iou(free) < 0.9 < 0.97 < _iou(held)
    # image forces felt 2 px outside each vertex: the contour settles 2 px inside the edge
    kw = dict(alpha=0.2, beta=0.2, gamma=1.0, mu=1.0, epsilon=1.0, max_iter=300)
    at_edge = evolve_contours([start], sc.gvf, sc.image, sc.ndsm, **kw)[0]
    inside = evolve_contours([start], sc.gvf, sc.image, sc.ndsm, offset=2.0, **kw)[0]
    assert _iou(at_edge) > 0.93
    shrunk = shapely.box(13.5, 16.5, 37.5, 42.5)
    p = shapely.make_valid(shapely.Polygon(inside[:, ::-1]))
    assert p.intersection(shrunk).area / p.union(shrunk).area > 0.9
    with pytest.raises(InputError):
        evolve_contours([start], sc.gvf, sc.image, sc.ndsm, offset=-1.0)


def test_a_snake_that_does_not_move_gives_back_its_start_pixels():
    # an L-shaped block, a building rotated by 30 degrees (staircase edges) and one
    # cut by the raster's edge, 0.5 m pixels
    from lidar2city.contour import WEIGHT_NAMES, contours_to_polygons, run_scene

    rng = np.random.default_rng(3)
    dsm = rng.normal(0.0, 0.05, (90, 100))
    dsm[10:40, 10:30] = 9.0
    dsm[30:40, 30:55] = 9.0
    rr, cc = np.mgrid[:90, :100]
    u = (cc - 70) * np.cos(np.pi / 6) + (rr - 60) * np.sin(np.pi / 6)
    v = -(cc - 70) * np.sin(np.pi / 6) + (rr - 60) * np.cos(np.pi / 6)
    dsm[(np.abs(u) < 14) & (np.abs(v) < 8)] = 7.0
    dsm[78:90, 82:100] = 6.0
    cfg = ActiveContourConfig()
    scene = prepare_scene(dsm, dsm, cell=0.5, config=cfg)
    assert len(scene.contours) == 3
    frame = PixelFrame(cell=0.5)
    start = rasterize_polygons(contours_to_polygons(scene.contours, frame, simplify=0), dsm.shape, frame)
    assert start[89, 95] and start[20:30, 15:25].all() and start[60, 70]
    zero = dict.fromkeys(WEIGHT_NAMES, 0.0)
    for it in (1, 20):
        moved = run_scene(scene, zero, config=dataclasses.replace(cfg, max_iter=it))
        polys = contours_to_polygons(moved, frame, simplify=cfg.simplify)
        assert all(p is not None for p in polys)
        # neither the resampling, the clipping to the raster nor the simplification
        # loses or adds a pixel
        np.testing.assert_array_equal(rasterize_polygons(polys, dsm.shape, frame), start)
