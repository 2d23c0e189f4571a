"""Roof-region segmentation of a DSM and the half-height edge trimming."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from lidar2city.errors import InputError
from lidar2city.segment.dsm import roof_regions, trim_to_edges


def _iou(a, b):
    return (a & b).sum() / (a | b).sum()


def blurred_scene(sigma=1.0):
    """Two flat houses of different heights side by side and a lone box, blurred."""
    nd = np.zeros((60, 80))
    truth = np.zeros((3, 60, 80), bool)
    truth[0, 10:24, 8:30] = True       # 9 m house
    truth[1, 10:24, 30:46] = True      # 5 m house sharing a wall
    truth[2, 36:52, 50:72] = True      # 7 m box
    for t, h in zip(truth, (9.0, 5.0, 7.0), strict=True):
        nd[t] = h
    return ndimage.gaussian_filter(nd, sigma), truth


def test_roof_regions_separates_heights_and_finds_edges():
    nd, truth = blurred_scene()
    # a blurred DSM (like the 2 m Alexandria one): regions cut back at half height
    labels, n = roof_regions(nd + 20.0, nd, cell=1.0, min_area=20.0, expand=3.0, edge_fraction=0.5,
                             edge_inset=0.0)
    found = set()
    for t in truth:
        ids, counts = np.unique(labels[t], return_counts=True)
        best = ids[np.argmax(counts)]
        assert best > 0 and best not in found  # the two houses sharing a wall stay apart
        found.add(best)
        # the blurred ramps are cut at half height: outlines within about a pixel
        assert _iou(labels == best, t) > 0.85
    # what else survives are iso-height strips along the steepest ramps (a known
    # weakness of step-based growing on blurred DSMs): thin, never a roof
    for i in set(range(1, n + 1)) - found:
        m = labels == i
        assert not ndimage.binary_erosion(m, structure=np.ones((3, 3), bool)).any()
        assert not (m & ndimage.binary_erosion(truth.any(axis=0), iterations=2)).any()


def test_trim_to_edges_cuts_ramp_and_low_appendage():
    nd, truth = blurred_scene(sigma=1.5)
    box = truth[2]
    grown = (ndimage.binary_dilation(box, iterations=4) & (nd > 0.5)).astype(int)
    # a 3 m shed attached to the 7 m box by a neck: not part of the building
    nd = nd.copy()
    nd[42:46, 72:78] = 3.0
    grown[42:46, 72:78] = 1
    trimmed = trim_to_edges(grown, nd, fraction=0.5)
    assert _iou(trimmed == 1, box) > 0.85
    assert _iou(trimmed == 1, box) > _iou(grown == 1, box) + 0.2
    assert not trimmed[42:46, 74:78].any()
    # fraction 0 keeps everything valid; nodata pixels are never kept
    nd[40, 60] = np.nan
    assert (trim_to_edges(grown, nd, fraction=0.0) > 0).sum() == (grown > 0).sum() - 1


def test_trim_to_edges_keeps_ids_and_validates():
    nd = np.zeros((10, 20))
    nd[2:8, 2:8] = 6.0
    nd[2:8, 12:18] = 3.0
    lab = np.zeros((10, 20), int)
    lab[1:9, 1:9] = 4
    lab[1:9, 11:19] = 7
    out = trim_to_edges(lab, nd)
    assert set(np.unique(out)) == {0, 4, 7}
    assert (out == 4).sum() == 36 and (out == 7).sum() == 36
    with pytest.raises(InputError):
        trim_to_edges(lab, nd, fraction=1.0)
    with pytest.raises(InputError):
        trim_to_edges(lab[:5], nd)
    with pytest.raises(InputError):
        roof_regions(nd, nd, cell=1.0, edge_fraction=-0.1)


def test_split_at_saddles_separates_house_and_crown_keeps_gable():
    from lidar2city.segment.dsm import split_at_saddles

    yy, xx = np.mgrid[0:40, 0:60].astype(float)
    nd = np.zeros((40, 60))
    house = np.zeros((40, 60), bool)
    house[10:30, 5:25] = True
    # a gable roof: eaves 5 m, ridge 8 m, one summit line
    nd[house] = 8.0 - 3.0 * np.abs(yy[house] - 19.5) / 10.0
    # a dome-shaped crown 9 m high touching the house through a 6 m saddle
    crown = (yy - 20) ** 2 + (xx - 36) ** 2 <= 11**2
    nd = np.where(crown, np.maximum(nd, 9.0 - 3.0 * ((yy - 20) ** 2 + (xx - 36) ** 2) / 121.0), nd)
    region = (nd > 2.0).astype(int)
    assert ndimage.label(region)[1] == 1
    out, n = split_at_saddles(region, nd, depth=1.0, min_pixels=30)
    assert n == 2
    ids, counts = np.unique(out[house], return_counts=True)
    h_id = ids[np.argmax(counts)]
    assert (out[house] == h_id).mean() > 0.95  # the gable is not split at its ridge
    assert (out[crown & ~house] != h_id).mean() > 0.9
    # a saddle shallower than the depth, or summits below min_pixels, keep one region
    assert split_at_saddles(region, nd, depth=4.0)[1] == 1
    assert split_at_saddles(region, nd, depth=1.0, min_pixels=500)[1] == 1
    with pytest.raises(InputError):
        split_at_saddles(region, nd, depth=0.0)


def test_split_at_saddles_keeps_flat_shapes_whole():
    from lidar2city.segment.dsm import split_at_saddles

    nd = np.zeros((60, 60))
    nd[5:45, 5:20] = 6.0
    nd[30:45, 20:50] = 6.0 + 1e-12 * np.arange(30)  # an L, flat up to rounding
    nd[50:56, 5:50] = 1.0  # a low wall: its plateau's height equals nothing special
    lab, _ = ndimage.label(nd > 0.5)
    for depth in (0.5, 1.0, 6.0, 20.0):
        out, n = split_at_saddles(lab, nd, depth=depth)
        assert n == 2 and np.array_equal(out > 0, lab > 0)


def test_inset_regions_moves_outer_edges_only_and_in_metres():
    from lidar2city.segment.dsm import inset_regions

    lab = np.zeros((12, 16), np.int32)
    lab[2:10, 2:8] = 1
    lab[2:10, 8:14] = 2  # a touching neighbour: the shared edge stays
    half = inset_regions(lab, cell=0.5, inset=0.25)
    assert (half[3:9, 3:8] == 1).all() and (half[3:9, 8:13] == 2).all()
    assert not half[2].any() and not half[:, 2].any() and not half[:, 13].any()
    assert (half > 0).sum() == 6 * 10
    # at 1 m a pixel centre is 0.5 m inside the edge: a 0.25 m inset changes nothing
    assert (inset_regions(lab, cell=1.0, inset=0.25) == lab).all()
    assert (inset_regions(lab, cell=0.5, inset=0.0) == lab).all()
    with pytest.raises(InputError):
        roof_regions(np.zeros((5, 5)), np.zeros((5, 5)), cell=1.0, edge_inset=-1)


def test_row_houses_one_region_per_block_split_at_a_step():
    """0.5 m DSM of two row-house blocks: 4 gabled houses of one height (no step between
    them) and 3 houses whose middle one is 1.5 m higher (a height step)."""
    cell = 0.5
    nd = np.zeros((80, 120))
    rows = np.arange(80)[:, None] * cell

    def gable(r0, r1, eaves, ridge):
        mid, half = (r0 + r1) / 2 * cell, (r1 - r0) / 2 * cell
        return eaves + (ridge - eaves) * (1 - np.abs(rows - mid) / half)

    block = gable(8, 32, 6.0, 10.0)
    nd[8:32, 8:88] = np.broadcast_to(block[8:32], (24, 80))      # 4 houses of 10 m, one roof
    low = gable(48, 72, 6.0, 10.0)
    nd[48:72, 8:98] = np.broadcast_to(low[48:72], (24, 90))
    nd[48:72, 38:68] += 1.5                                       # the middle house is higher
    labels, n = roof_regions(nd + 1.0, nd, cell=cell)
    top = np.unique(labels[10:30, 10:86])
    assert len(top[top > 0]) == 1                                  # one outline per block
    bottom = {int(np.bincount(labels[50:70, c0:c1].ravel()).argmax())
              for c0, c1 in ((12, 34), (42, 64), (72, 94))}
    assert len(bottom) == 3 and 0 not in bottom                    # split at the steps


def test_inset_default_drops_one_ring_at_half_and_one_metre_none_at_two():
    from lidar2city.segment.dsm import inset_regions

    lab = np.zeros((12, 12), np.int32)
    lab[2:10, 2:10] = 1
    for cell, kept in ((0.5, 36), (1.0, 36), (2.0, 64)):
        assert (inset_regions(lab, cell=cell, inset=0.5) > 0).sum() == kept


def test_expand_roughness_keeps_touching_tree_crown_out_but_joins_eaves():
    # 0.5 m grid: a flat 6 m roof, a rough tree crown touching its east side and
    # a thin rough eave strip on its west side (walls and gutters are rough too)
    rng = np.random.default_rng(3)
    nd = np.zeros((60, 80))
    house = np.zeros(nd.shape, bool)
    house[10:50, 10:40] = True
    nd[house] = 6.0
    tree = np.zeros(nd.shape, bool)
    tree[15:45, 40:65] = True
    nd[tree] = 6.0 + rng.normal(0.0, 1.5, tree.sum())
    eave = np.zeros(nd.shape, bool)
    eave[10:50, 9] = True
    nd[eave] = 6.0 + rng.normal(0.0, 1.5, eave.sum())
    kw = dict(cell=0.5, min_area=10.0, expand=2.0, edge_inset=0.0, saddle_depth=0.0)
    on, _ = roof_regions(nd + 1.0, nd, **kw)
    off, _ = roof_regions(nd + 1.0, nd, expand_roughness=0.0, **kw)
    best = np.bincount(on[house]).argmax()
    assert best > 0 and _iou(on == best, house | eave) > 0.9
    assert (on[tree] > 0).mean() < 0.05                # the crown stays out
    assert (on[eave] == best).mean() > 0.8             # the thin strip is joined
    assert (off[tree] > 0).mean() > 0.1                # without the cue it is grown into


def test_small_fragments_touching_a_roof_are_merged_lone_ones_dropped():
    nd = np.zeros((60, 70))
    nd[10:40, 10:40] = 6.0            # the house, 15 m x 15 m at 0.5 m
    nd[16:22, 40:46] = 3.0            # a 9 m2 annex behind a 3 m step
    nd[30:33, 40:43] = 4.5            # a 2.25 m2 fragment, below merge_area
    nd[45:51, 50:56] = 3.0            # a lone 9 m2 shed
    kw = dict(cell=0.5, min_area=10.0, expand=0.0, edge_inset=0.0, saddle_depth=0.0,
              expand_roughness=0.0)
    on, n_on = roof_regions(nd + 1.0, nd, merge_area=5.0, **kw)
    off, n_off = roof_regions(nd + 1.0, nd, merge_area=0.0, **kw)
    assert n_on == n_off == 1
    house = on[20, 20]
    assert house > 0 and (on[16:22, 40:46] == house).all()   # the annex joins the house
    assert (off[16:22, 40:46] == 0).all()
    assert (on[30:33, 40:43] == 0).all() and (on[45:51, 50:56] == 0).all()
    # at 2 m the same areas are a few pixels: below min_pixels nothing is merged
    coarse, _ = roof_regions(nd[::4, ::4] + 1.0, nd[::4, ::4], **{**kw, "cell": 2.0})
    assert coarse[6, 6] > 0 and (coarse[4:6, 10:12] == 0).all()
    with pytest.raises(InputError):
        roof_regions(nd + 1.0, nd, merge_area=-1.0, **kw)


def _gable_and_crown(seed=0):
    """0.5 m grid: a steep (45 degree) gable with highest-point-like noise and a bumpy crown."""
    rng = np.random.default_rng(seed)
    y = np.mgrid[0:60, 0:80][0] * 0.5
    nd = np.zeros((60, 80))
    house = np.zeros(nd.shape, bool)
    house[8:32, 6:30] = True
    nd[house] = (8.0 - np.abs(y - 10.0))[house] + rng.uniform(0.0, 0.25, house.sum())
    crown = np.zeros(nd.shape, bool)
    crown[36:56, 44:70] = True
    nd[crown] = (6.0 + 4.0 * ndimage.gaussian_filter(rng.normal(0.0, 1.0, nd.shape), 1.0))[crown]
    return nd, house, crown


def test_slope_spread_is_low_on_noisy_steep_faces_high_on_crowns():
    from lidar2city.segment.dsm import slope_spread

    nd, house, crown = _gable_and_crown()
    s = slope_spread(nd, cell=0.5)
    assert np.median(s[house]) < 0.15 and np.percentile(s[house], 90) < 0.5
    assert np.median(s[crown]) > max(0.4, 4 * np.median(s[house]))
    # heights moved up and down do not change it; NaN cells stay NaN
    assert np.allclose(slope_spread(nd + 30.0, cell=0.5), s, atol=1e-6)
    holed = nd.copy()
    holed[20, 20] = np.nan
    assert np.isnan(slope_spread(holed, cell=0.5)[20, 20])
    with pytest.raises(InputError):
        slope_spread(nd, cell=0.5, window=0.0)


def test_regions_without_planar_faces_are_dropped_at_fine_resolution():
    nd, house, crown = _gable_and_crown()
    kw = dict(cell=0.5, edge_inset=0.0, saddle_depth=0.0)
    on, n_on = roof_regions(nd + 1.0, nd, **kw)
    off, n_off = roof_regions(nd + 1.0, nd, min_planar_share=0.0, **kw)
    assert (on[house] > 0).all() and (off[house] > 0).all()     # the steep noisy gable stays
    assert (on[crown] > 0).mean() == 0.0                         # the crown is dropped
    assert (off[crown] > 0).mean() > 0.5 and n_off > n_on
    # coarser than 1 m the test is off (3 x 3 windows span whole roofs)
    c_on, _ = roof_regions(nd[::4, ::4] + 1.0, nd[::4, ::4], **{**kw, "cell": 2.0})
    c_off, _ = roof_regions(nd[::4, ::4] + 1.0, nd[::4, ::4],
                            **{**kw, "cell": 2.0, "min_planar_share": 0.0})
    assert np.array_equal(c_on, c_off)
    with pytest.raises(InputError):
        roof_regions(nd + 1.0, nd, min_planar_share=1.5, **kw)


def _low_strip_between_roofs(seed=0):
    """0.5 m grid: a 2 m wide flat roof 3 m below its two neighbours, and a bumpy crown."""
    rng = np.random.default_rng(seed)
    nd = np.zeros((40, 60))
    nd[6:34, 6:22] = 9.0
    nd[6:34, 26:42] = 9.0
    strip = np.zeros(nd.shape, bool)
    strip[6:34, 22:26] = True
    nd[strip] = 6.0
    nd[nd > 0] += rng.uniform(0.0, 0.1, (nd > 0).sum())
    crown = np.zeros(nd.shape, bool)
    crown[10:30, 45:58] = True
    nd[crown] = (6.0 + 4.0 * ndimage.gaussian_filter(rng.normal(0.0, 1.0, nd.shape), 1.0))[crown]
    return nd, strip, crown


def test_plane_share_counts_pixels_on_one_plane():
    from lidar2city.segment.dsm import plane_share

    r, c = np.mgrid[0:10, 0:12]
    z = 3.0 + 0.6 * c * 0.5 - 0.2 * r * 0.5
    z[:2, :3] += 4.0  # a chimney does not tilt the plane
    share = plane_share(z.ravel(), r.ravel(), c.ravel(), cell=0.5)
    assert share == pytest.approx(1.0 - 6 / 120)
    rng = np.random.default_rng(0)
    bumpy = ndimage.gaussian_filter(rng.normal(0.0, 3.0, (10, 12)), 1.0)
    assert plane_share(bumpy.ravel(), r.ravel(), c.ravel(), cell=0.5) < 0.5
    assert plane_share(np.array([1.0, 2.0]), np.array([0, 1]), np.array([0, 0]), cell=0.5) == 0.0


def test_narrow_flat_roof_between_steps_is_kept_the_crown_is_not():
    # every 1.5 m slope window on the strip reaches over a 3 m step: the slope test drops
    # it, but its pixels lie on one plane, which a crown's do not
    nd, strip, crown = _low_strip_between_roofs()
    kw = dict(cell=0.5, edge_inset=0.0, saddle_depth=0.0, expand=0.0, edge_fraction=0.0,
              merge_area=0.0)
    slope_only, _ = roof_regions(nd + 1.0, nd, min_plane_share=0.0, **kw)
    both, _ = roof_regions(nd + 1.0, nd, **kw)
    assert (slope_only[strip] > 0).mean() == 0.0
    assert (both[strip] > 0).all() and len(np.unique(both[strip])) == 1
    assert (both[crown] > 0).mean() == 0.0
    with pytest.raises(InputError):
        roof_regions(nd + 1.0, nd, plane_tolerance=0.0, **kw)


def test_split_at_necks_cuts_narrow_joints_keeps_wide_ones_and_every_pixel():
    from lidar2city.segment.dsm import split_at_necks

    lab = np.zeros((24, 46), np.int32)
    lab[2:22, 2:20] = 1                  # two 9 m x 10 m sheds (0.5 m cells) ...
    lab[2:22, 26:44] = 1
    lab[10:13, 20:26] = 1                # ... joined by a 1.5 m wide, 3 m long fence
    out, n = split_at_necks(lab, cell=0.5, width=2.0, min_pixels=40)
    assert n == 2
    assert np.array_equal(out > 0, lab > 0)                        # no pixel lost or added
    assert len(np.unique(out[2:22, 2:20])) == 1 and len(np.unique(out[2:22, 26:44])) == 1
    assert out[5, 5] != out[5, 30]
    for a in (1, 2):                                               # each part is connected
        assert ndimage.label(out == a)[1] == 1
    wide = lab.copy()
    wide[7:16, 20:26] = 1                                          # a 4.5 m wide joint holds
    assert split_at_necks(wide, cell=0.5, width=2.0, min_pixels=40)[1] == 1
    # a part smaller than min_pixels is not a part; width 0 or below two cells: no split
    assert split_at_necks(lab, cell=0.5, width=2.0, min_pixels=400)[1] == 1
    assert split_at_necks(lab, cell=0.5, width=0.0)[1] == 1
    assert split_at_necks(lab, cell=2.0, width=2.0)[1] == 1
    with pytest.raises(InputError):
        split_at_necks(lab, cell=0.5, width=-1.0)


def test_roof_regions_two_sheds_joined_by_a_wall_are_two_regions():
    # 0.5 m grid: two flat 2.5 m sheds joined by a garden wall as high as they are
    nd = np.zeros((30, 50))
    nd[4:26, 4:22] = 2.5
    nd[4:26, 28:46] = 2.5
    nd[14:16, 22:28] = 2.5
    kw = dict(cell=0.5, edge_inset=0.0, saddle_depth=0.0)
    labels, n = roof_regions(nd + 1.0, nd, **kw)
    assert n == 2 and labels[10, 10] != labels[10, 40] and labels[10, 10] > 0
    assert roof_regions(nd + 1.0, nd, neck_width=0.0, **kw)[1] == 1


def test_plane_test_keeps_roofs_between_steps_not_free_standing_strips():
    # a 1 m wide flat garden wall on open ground: every 1.5 m slope window straddles its
    # sides, so the slope test fails; its top lies on one plane, but it touches no other
    # region, so the plane test does not keep it (the strip between two roofs is kept)
    nd, strip, _ = _low_strip_between_roofs()
    wall = np.zeros(nd.shape, bool)
    wall[36:38, 4:40] = True
    nd = nd.copy()
    nd[36:, :] = 0.0
    nd[wall] = 2.5
    kw = dict(cell=0.5, edge_inset=0.0, saddle_depth=0.0, expand=0.0, edge_fraction=0.0,
              merge_area=0.0)
    on, _ = roof_regions(nd + 1.0, nd, **kw)
    off, _ = roof_regions(nd + 1.0, nd, plane_contact=0.0, **kw)
    assert (off[wall] > 0).all() and (on[wall] > 0).mean() == 0.0
    assert (on[strip] > 0).all() and len(np.unique(on[strip])) == 1
    with pytest.raises(InputError):
        roof_regions(nd + 1.0, nd, plane_contact=1.5, **kw)


def _gable_row(ridges, *, width=16, depth=30, cell=0.5):
    """Row houses along x on a 0.5 m grid: eaves level, each gable rising to its own ridge."""
    y = np.abs(np.arange(depth) - (depth - 1) / 2.0) * cell    # distance from the ridge line
    nd = np.zeros((depth + 8, width * len(ridges) + 8))
    for k, top in enumerate(ridges):
        eave = 3.0
        rise = (top - eave) / (y.max())
        face = top - rise * y
        nd[4:4 + depth, 4 + k * width:4 + (k + 1) * width] = face[:, None]
    return nd


def test_split_at_ridge_steps_splits_a_row_at_a_ridge_break_only():
    from lidar2city.segment.dsm import split_at_ridge_steps

    nd = _gable_row([8.0, 9.0, 9.0])      # eaves level: the growing joins the three houses
    lab = (nd > 2.0).astype(np.int32)
    out, n = split_at_ridge_steps(lab, nd + 1.0, cell=0.5, step=0.5)
    assert n == 2 and ((out > 0) == (lab > 0)).all()
    first = out[4:34, 4:20]
    rest = out[4:34, 20:52]
    assert len(np.unique(first)) == 1 and len(np.unique(rest)) == 1
    assert first[0, 0] != rest[0, 0]
    level, n_level = split_at_ridge_steps((_gable_row([8.0, 8.1, 8.0]) > 2).astype(int),
                                          _gable_row([8.0, 8.1, 8.0]), cell=0.5, step=0.5)
    assert n_level == 1
    assert split_at_ridge_steps(lab, nd, cell=0.5, step=0.0)[1] == 1
    with pytest.raises(InputError):
        split_at_ridge_steps(lab, nd, cell=0.5, step=-1.0)
    # in roof_regions: the growing joins the row at its level eaves, the ridge step splits it
    kw = dict(cell=0.5, edge_inset=0.0, saddle_depth=0.0, expand=0.0, edge_fraction=0.0,
              merge_area=0.0)
    assert roof_regions(nd + 1.0, nd, ridge_step=0.0, **kw)[1] == 1
    assert roof_regions(nd + 1.0, nd, **kw)[1] == 2
