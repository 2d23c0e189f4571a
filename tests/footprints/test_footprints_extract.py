"""Footprint extraction: synthetic roofs with exact outlines, invariants, errors, Delft."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import affinity

from lidar2city.errors import ConfigError, EmptyInputError, InputError
from lidar2city.footprints import (
    REGULARIZERS,
    FootprintsConfig,
    extract_footprints,
    outline_direction,
    point_spacing,
    simplify_polygon,
)


def scan(buildings, *, extent=(0.0, 0.0, 60.0, 60.0), spacing=0.3, seed=0, shadow=None,
         line_gap=0.0):
    """Points on a jittered grid: class 6 (z 8 m) inside ``buildings``, class 2 outside.

    ``shadow`` (a polygon) holds no point at all (a laser shadow); ``line_gap``
    removes every fifth scan line over the width ``line_gap`` (m).
    """
    rng = np.random.default_rng(seed)
    xs = np.arange(extent[0], extent[2], spacing)
    ys = np.arange(extent[1], extent[3], spacing)
    xx, yy = np.meshgrid(xs, ys)
    xy = np.column_stack([xx.ravel(), yy.ravel()]) + rng.uniform(-0.4, 0.4, (xx.size, 2)) * spacing
    if line_gap:
        period = 5 * spacing
        xy = xy[np.mod(xy[:, 1], period) >= line_gap]
    union = shapely.union_all(buildings)
    if shadow is not None:
        xy = xy[~shapely.contains_xy(shadow, xy[:, 0], xy[:, 1]) |
                shapely.contains_xy(union, xy[:, 0], xy[:, 1])]
    inside = shapely.contains_xy(union, xy[:, 0], xy[:, 1])
    z = np.where(inside, 8.0, 0.0) + rng.normal(0, 0.02, len(xy))
    cls = np.where(inside, 6, 2).astype(np.uint8)
    return np.column_stack([xy, z]), cls


def iou(a, b):
    return a.intersection(b).area / a.union(b).area


L_SHAPE = shapely.Polygon([(10, 10), (40, 10), (40, 25), (25, 25), (25, 45), (10, 45)])
COURTYARD = shapely.Polygon([(15, 15), (45, 15), (45, 45), (15, 45)],
                            [[(23, 23), (37, 23), (37, 37), (23, 37)]])


def test_l_shaped_roof_iou_above_095():
    xyz, cls = scan([L_SHAPE])
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 1
    f = fps[0]
    assert f.status == "ok"
    assert iou(f.polygon, L_SHAPE) > 0.97
    assert f.attributes["area"] == pytest.approx(f.polygon.area)
    # 6 corners: Douglas-Peucker leaves a handful of vertices, not the staircase
    assert 6 <= f.attributes["n_vertices"] <= 20
    assert f.attributes["n_points"] == pytest.approx(np.count_nonzero(cls == 6), rel=0.02)
    assert min(f.attributes["direction"], 90 - f.attributes["direction"]) < 2.0


def test_courtyard_block_keeps_its_hole():
    xyz, cls = scan([COURTYARD], seed=1)
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 1
    poly = fps[0].polygon
    assert len(poly.interiors) == 1
    assert shapely.Polygon(poly.interiors[0]).area == pytest.approx(14 * 14, rel=0.05)
    assert iou(poly, COURTYARD) > 0.95


def test_small_holes_are_filled_and_small_regions_dropped():
    block = shapely.Polygon([(10, 10), (40, 10), (40, 40), (10, 40)],
                            [[(20, 20), (21.5, 20), (21.5, 21.5), (20, 21.5)]])  # 2.25 m2 skylight
    shed = shapely.box(50, 50, 51.2, 51.2)  # 1.4 m2: below min_area
    xyz, cls = scan([block, shed], seed=2)
    fps = extract_footprints(xyz, cls, min_area=4.0, min_hole_area=4.0)
    assert len(fps) == 1
    assert len(fps[0].polygon.interiors) == 0
    assert fps[0].polygon.area == pytest.approx(900, rel=0.02)


def test_outline_is_not_biased_by_the_grid():
    """Area error well under the half-cell bias of pixel-edge outlines (~ perimeter x cell / 2)."""
    truth = shapely.box(10.3, 12.1, 47.9, 41.7)
    errors = []
    for seed in range(3):
        xyz, cls = scan([truth], seed=seed)
        (f,) = extract_footprints(xyz, cls)
        errors.append((f.polygon.area - truth.area) / truth.length)  # mean outward offset (m)
    assert abs(np.mean(errors)) < 0.06


def test_laser_shadow_does_not_pull_the_outline_out():
    truth = shapely.box(15, 15, 40, 40)
    shadow = shapely.box(40, 15, 43, 40)  # 3 m without points east of the building
    xyz, cls = scan([truth], shadow=shadow, seed=3)
    (f,) = extract_footprints(xyz, cls)
    east = f.polygon.bounds[2]
    assert east == pytest.approx(40.0, abs=0.35)


def test_scan_line_gaps_are_bridged():
    xyz, cls = scan([L_SHAPE], line_gap=0.5, seed=4)
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 1
    assert len(fps[0].polygon.interiors) == 0
    assert iou(fps[0].polygon, L_SHAPE) > 0.95


def test_rotated_buildings_apart_are_separate():
    a = affinity.rotate(shapely.box(8, 8, 28, 20), 30, origin=(18, 14))
    b = affinity.rotate(shapely.box(33, 30, 50, 50), 30, origin=(41, 40))
    xyz, cls = scan([a, b], seed=5)
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 2
    polys = sorted((f.polygon for f in fps), key=lambda p: p.centroid.x)
    assert iou(polys[0], a) > 0.95 and iou(polys[1], b) > 0.95
    assert outline_direction(polys[0]) == pytest.approx(30.0, abs=2.0)


def test_translation_moves_the_outline_only():
    xyz, cls = scan([L_SHAPE], seed=6)
    (f0,) = extract_footprints(xyz, cls)
    (f1,) = extract_footprints(xyz + np.array([1000.37, -250.81, 3.0]), cls)
    moved = affinity.translate(f0.polygon, 1000.37, -250.81)
    assert iou(moved, f1.polygon) > 0.98


def test_inputs_are_not_mutated_and_results_deterministic():
    xyz, cls = scan([L_SHAPE], seed=7)
    xyz0, cls0 = xyz.copy(), cls.copy()
    a = extract_footprints(xyz, cls)
    b = extract_footprints(xyz, cls)
    assert np.array_equal(xyz, xyz0) and np.array_equal(cls, cls0)
    assert a[0].polygon.equals_exact(b[0].polygon, 0.0)


def test_edge_offset_shrinks_by_the_perimeter():
    xyz, cls = scan([L_SHAPE], seed=8)
    (f0,) = extract_footprints(xyz, cls, simplify=0)
    (f1,) = extract_footprints(xyz, cls, simplify=0, edge_offset=-0.3)
    assert f0.polygon.area - f1.polygon.area == pytest.approx(0.3 * f0.polygon.length, rel=0.1)


def test_only_building_points_still_work():
    xyz, cls = scan([L_SHAPE], seed=9)
    keep = cls == 6
    (f,) = extract_footprints(xyz[keep], cls[keep])
    assert iou(f.polygon, L_SHAPE) > 0.95


def test_errors():
    xyz, cls = scan([L_SHAPE])
    with pytest.raises(EmptyInputError, match="class 6"):
        extract_footprints(xyz, np.full(len(xyz), 2))
    with pytest.raises(InputError, match="shape"):
        extract_footprints(xyz[:, :1], cls)
    with pytest.raises(InputError, match="classification"):
        extract_footprints(xyz, cls[:-1])
    with pytest.raises(InputError, match="regularize"):
        extract_footprints(xyz, cls, regularize="magic")
    with pytest.raises(ConfigError, match="footprints.cell"):
        extract_footprints(xyz, cls, cell=-1.0)
    with pytest.raises(ConfigError, match="footprints.regularize"):
        FootprintsConfig(regularize="magic")


def test_config_fields_are_the_function_keywords():
    import dataclasses
    import inspect

    names = {f.name for f in dataclasses.fields(FootprintsConfig)}
    kw = {p.name for p in inspect.signature(extract_footprints).parameters.values()
          if p.kind is p.KEYWORD_ONLY} - {"callback", "within"}
    assert names == kw
    import typing

    assert set(REGULARIZERS) == {"none", "snake", "fit"}
    hints = typing.get_type_hints(FootprintsConfig)
    assert set(typing.get_args(hints["regularize"])) == set(REGULARIZERS)
    for f in dataclasses.fields(FootprintsConfig):
        assert f.metadata["doc"]


def test_point_spacing_of_a_regular_grid():
    xx, yy = np.meshgrid(np.arange(0, 40, 0.5), np.arange(0, 40, 0.5))
    assert point_spacing(np.column_stack([xx.ravel(), yy.ravel()])) == pytest.approx(0.5, rel=0.05)


def test_simplify_keeps_a_valid_polygon():
    ring = [(np.cos(t) * 10, np.sin(t) * 10) for t in np.linspace(0, 2 * np.pi, 200, endpoint=False)]
    poly = shapely.Polygon(ring)
    out = simplify_polygon(poly, 0.5)
    assert out.is_valid and len(out.exterior.coords) < 30
    assert shapely.hausdorff_distance(out, poly) <= 0.5 + 1e-9
    with pytest.raises(InputError):
        simplify_polygon(poly, -1)


def test_callback_reports_every_building():
    xyz, cls = scan([shapely.box(5, 5, 20, 20), shapely.box(30, 30, 50, 50)], seed=10)
    calls = []
    extract_footprints(xyz, cls, callback=lambda d, t: calls.append((d, t)))
    assert calls == [(1, 2), (2, 2)]


def test_fit_regularises_a_rotated_l_shape_and_a_rectangle():
    from lidar2city.metrics.footprints import axis_alignment

    truth = affinity.rotate(L_SHAPE, 23.0, origin=(25, 27))
    rect = affinity.rotate(shapely.box(44, 5, 56, 13), -10.0, origin=(50, 9))
    xyz, cls = scan([truth, rect], seed=11)
    fps = sorted(extract_footprints(xyz, cls, regularize="fit"), key=lambda f: -f.polygon.area)
    assert [f.status for f in fps] == ["ok", "ok"]
    ell, box = fps
    assert iou(ell.polygon, truth) > 0.93 and iou(box.polygon, rect) > 0.9
    assert ell.attributes["n_vertices"] == 6 and box.attributes["n_vertices"] == 4
    assert axis_alignment([ell.polygon, box.polygon])["aligned_share"] > 0.95
    assert ell.attributes["direction"] % 90 == pytest.approx(23.0, abs=2.0)


def test_snake_regularises_a_rotated_l_shape():
    from lidar2city.metrics.footprints import axis_alignment

    truth = affinity.rotate(L_SHAPE, 23.0, origin=(25, 27))
    xyz, cls = scan([truth], seed=11)
    (f,) = extract_footprints(xyz, cls, regularize="snake")
    assert f.status == "ok", f.reason
    assert iou(f.polygon, truth) > 0.93
    assert axis_alignment([f.polygon])["aligned_share"] > 0.9
    assert f.attributes["direction"] % 90 == pytest.approx(23.0, abs=3.0)




def test_delft_footprints_quality(data):
    """Per-area quality against BGT on the fair evaluation area (see benchmarks/bench_footprints.py)."""
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints
    from lidar2city.metrics.footprints import area_metrics
    from lidar2city.tools.evaluate import fair_subset

    cloud = read_points(data / "delft" / "ahn3_cropped_1.laz", crs="EPSG:7415")
    ref, _ = read_footprints(data / "delft" / "footprints_bgt.gpkg", origin=cloud.origin[:2])
    fps = extract_footprints(cloud.xyz, cloud.get("classification"))
    extent = shapely.box(*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    pred, refs, info = fair_subset([f.polygon for f in fps], ref.geometries, extent=extent,
                                   hull_margin=2.0)
    m = area_metrics(pred, refs)
    # measured 0.878 (completeness 0.953, correctness 0.917); 8 of 132 references in cut blocks
    assert m["quality"] > 0.86
    assert m["completeness"] > 0.93 and m["correctness"] > 0.89
    assert info["ref_cut"] <= 10
    assert all(f.polygon.is_valid for f in fps)


def test_snake_results_and_failures_are_recorded_per_building(monkeypatch):
    """With a stand-in for the snake: info keys mapped, a fallback and an error kept per building."""
    from lidar2city.errors import FitError
    from lidar2city.footprints import regularizers

    calls = []

    def fake(polygon, *, cell, window, simplify_tolerance=None, t_adjust=None, sample_step=None):
        calls.append((cell, window, simplify_tolerance, t_adjust, sample_step))
        if polygon.centroid.x < 20:
            raise FitError("degenerate outline")
        if polygon.centroid.y < 20:
            return polygon, {"status": "fallback", "reason": "no valid result",
                             "reductions": {"I": 3, "II": 1, "III": 1, "IV": 0}}
        box = shapely.box(*polygon.bounds)
        return box, {"status": "regularized", "direction_deg": 90.0 + 12.0, "mean_deviation_m": 0.2,
                     "reductions": {"I": 5, "II": 2, "III": 2, "IV": 1}}

    monkeypatch.setattr(regularizers, "_snake", lambda: fake)
    xyz, cls = scan([shapely.box(5, 5, 15, 15), shapely.box(30, 5, 45, 15), shapely.box(30, 30, 50, 50)],
                    seed=12)
    fps = extract_footprints(xyz, cls, regularize="snake", snake_window=3)
    assert len(fps) == 3 and len(calls) == 3
    cell = calls[0][0]
    assert calls[0][1] == 3 and calls[0][3] == pytest.approx(2 * 3 * cell)
    # the deviation's samples every other raster cell unless asked otherwise
    assert {c[4] for c in calls} == {2.0}
    calls.clear()
    extract_footprints(xyz, cls, regularize="snake", snake_window=3, snake_sample_step=1.0)
    assert len(calls) == 3 and {c[4] for c in calls} == {1.0}
    by_x = sorted(fps, key=lambda f: (f.polygon.centroid.x, f.polygon.centroid.y))
    failed, fallback, ok = by_x
    assert failed.status == "unregularised" and "degenerate" in failed.reason
    assert fallback.status == "unregularised" and fallback.reason == "no valid result"
    assert fallback.attributes["type_i"] == 3
    assert ok.status == "ok" and ok.attributes["direction"] == pytest.approx(12.0)
    assert ok.attributes["type_iv"] == 1 and ok.attributes["mean_deviation"] == pytest.approx(0.2)
    assert ok.attributes["n_vertices"] == 4


@settings(max_examples=12, deadline=None)
@given(w=st.floats(4.0, 25.0), h=st.floats(4.0, 25.0), angle=st.floats(0.0, 90.0),
       seed=st.integers(0, 1000))
def test_any_rotated_rectangle_gives_one_valid_closed_ring(w, h, angle, seed):
    truth = affinity.rotate(shapely.box(30 - w / 2, 30 - h / 2, 30 + w / 2, 30 + h / 2), angle)
    xyz, cls = scan([truth], seed=seed)
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 1
    poly = fps[0].polygon
    assert poly.is_valid and poly.exterior.is_closed and len(poly.interiors) == 0
    assert iou(poly, truth) > 0.9


@pytest.mark.slow
def test_delft_snake_footprints(data):
    from lidar2city.io.las import read_points
    from lidar2city.io.vector import read_footprints
    from lidar2city.metrics.footprints import area_metrics, axis_alignment
    from lidar2city.tools.evaluate import fair_subset

    cloud = read_points(data / "delft" / "ahn3_cropped_1.laz", crs="EPSG:7415")
    ref, _ = read_footprints(data / "delft" / "footprints_bgt.gpkg", origin=cloud.origin[:2])
    fps = extract_footprints(cloud.xyz, cloud.get("classification"), regularize="snake")
    extent = shapely.box(*cloud.xyz[:, :2].min(axis=0), *cloud.xyz[:, :2].max(axis=0))
    pred, refs, _ = fair_subset([f.polygon for f in fps], ref.geometries, extent=extent,
                                hull_margin=2.0)
    # measured with the snake branch at 2bca764: quality 0.869, alignment 0.809
    assert area_metrics(pred, refs)["quality"] > 0.85
    assert axis_alignment(pred)["aligned_share"] > 0.78
    assert sum(f.status == "ok" for f in fps) >= 0.9 * len(fps)


def _with_roof(xyz, cls, height):
    """``xyz`` with the building points' z set by ``height(x, y)``."""
    out = xyz.copy()
    b = cls == 6
    out[b, 2] = height(out[b, 0], out[b, 1])
    return out


def test_row_houses_of_different_heights_are_split_at_the_steps():
    row = shapely.box(10, 20, 49, 30)  # three 13 m houses: 8 m, 11 m, 8 m high
    xyz, cls = scan([row], seed=3)
    xyz = _with_roof(xyz, cls, lambda x, y: np.where((x >= 23) & (x < 36), 11.0, 8.0))
    fps = extract_footprints(xyz, cls)
    assert len(fps) == 3
    polys = sorted((f.polygon for f in fps), key=lambda p: p.centroid.x)
    for p, x0 in zip(polys, (10, 23, 36), strict=True):
        assert iou(p, shapely.box(x0, 20, x0 + 13, 30)) > 0.9
    # disjoint parts that still cover the block
    assert sum(p.area for p in polys) == pytest.approx(shapely.union_all(polys).area, rel=1e-9)
    assert shapely.union_all(polys).area == pytest.approx(row.area, rel=0.05)
    # split_step = 0 keeps the block whole
    assert len(extract_footprints(xyz, cls, split_step=0)) == 1
    assert len(extract_footprints(xyz[:, :2], cls)) == 1


def test_pitched_roof_and_chimney_are_not_split():
    house = shapely.box(15, 15, 40, 35)
    xyz, cls = scan([house], seed=4)

    def gable(x, y):  # 45-degree gable (ridge along x at y = 25) and a 1 m chimney 3 m high
        z = 14.0 - np.abs(y - 25.0)
        return np.where((np.abs(x - 20.0) < 0.5) & (np.abs(y - 28.0) < 0.5), z + 3.0, z)

    fps = extract_footprints(_with_roof(xyz, cls, gable), cls)
    assert len(fps) == 1
    assert iou(fps[0].polygon, house) > 0.95


def test_split_at_steps_on_a_grid():
    from lidar2city.footprints.grid import split_at_steps

    labels = np.zeros((6, 12), dtype=np.int32)
    labels[1:5, 1:11] = 1
    h = np.full(labels.shape, np.nan)
    h[1:5, 1:6] = 5.0
    h[1:5, 6:11] = 9.0
    h[2, 3] = np.nan  # no point in that cell: takes its neighbours' height
    h[3, 8] = 12.0    # a one-cell spike joins its part
    out = split_at_steps(labels, h, 1.0, step=2.0, min_area=4.0)
    assert set(np.unique(out)) == {0, 1, 2}
    assert (out[1:5, 1:6] == 1).all() and (out[1:5, 6:11] == 2).all()
    assert (out[labels == 0] == 0).all()
    # parts smaller than min_area leave the region whole
    assert set(np.unique(split_at_steps(labels, h, 1.0, step=2.0, min_area=30.0))) == {0, 1}
    with pytest.raises(InputError):
        split_at_steps(labels, h[:, :5], 1.0)


def _jittered(spacing, size=120.0, seed=0):
    rng = np.random.default_rng(seed)
    xx, yy = np.meshgrid(np.arange(0, size, spacing), np.arange(0, size, spacing))
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    return xy + rng.uniform(-0.4, 0.4, xy.shape) * spacing


@pytest.mark.parametrize("spacing", [1.5, 2.5, 4.0])
def test_point_spacing_of_a_sparse_survey(spacing):
    # a survey sparser than the 2 m squares: most squares hold one point, the spacing
    # measured on them saturated near 1.4 m (ISPRS CSite1, 4 m apart: 1.42 m)
    assert point_spacing(_jittered(spacing)) == pytest.approx(spacing, rel=0.12)


def test_point_spacing_of_first_last_pulse_pairs():
    # a first/last-pulse survey stores a one-echo pulse twice at the same x, y: the
    # spacing is that of the distinct positions (was 1/sqrt(2) of it)
    xy = _jittered(1.0)
    assert point_spacing(np.vstack([xy, xy])) == pytest.approx(point_spacing(xy), rel=1e-9)


def test_point_spacing_with_a_cell_given_is_unchanged():
    xy = _jittered(4.0)
    ij = np.floor((xy - xy.min(axis=0)) / 2.0).astype(np.int64)
    occupied = len(np.unique(ij, axis=0))
    assert point_spacing(xy, cell=2.0) == pytest.approx(np.sqrt(occupied * 4.0 / len(xy)))


def test_sparse_pairs_survey_traces_one_footprint_per_building():
    # 3.5 m between pulses, every pulse stored twice (first/last pairs): each 40 m x 30 m
    # building is one footprint of about its area (was dozens of fragments)
    rng = np.random.default_rng(1)
    xy = _jittered(3.5, size=200.0, seed=1)
    houses = [shapely.box(20, 20, 60, 50), shapely.box(110, 100, 150, 130)]
    inside = shapely.contains_xy(shapely.union_all(houses), xy[:, 0], xy[:, 1])
    z = np.where(inside, 12.0, 0.0) + rng.normal(0, 0.05, len(xy))
    xyz = np.column_stack([xy, z])
    cls = np.where(inside, 6, 2)
    fps = extract_footprints(np.vstack([xyz, xyz]), np.concatenate([cls, cls]))
    assert len(fps) == 2
    for f in fps:
        truth = max(houses, key=lambda h: h.intersection(f.polygon).area)
        assert f.polygon.intersection(truth).area / f.polygon.union(truth).area > 0.8


def test_scan_lines_8_to_1_trace_one_footprint_per_building():
    # points 0.125 m apart along scan lines 1 m apart: the footprint grid (1.5 x the
    # 0.35 m mean spacing) left every gap between lines void, and each scan line over a
    # roof became a footprint of its own (the synthetic town: 114 for 15 buildings)
    rng = np.random.default_rng(3)
    x, y = np.meshgrid(np.arange(0, 120, 0.125), np.arange(0.3, 90, 1.0))
    xy = np.column_stack([x.ravel(), y.ravel()]) + rng.normal(0, 0.02, (x.size, 2))
    houses = [shapely.box(20, 20, 50, 38), affinity.rotate(shapely.box(70, 40, 95, 70), 30)]
    inside = shapely.contains_xy(shapely.union_all(houses), xy[:, 0], xy[:, 1])
    xyz = np.column_stack([xy, np.where(inside, 9.0, 0.0)])
    fps = extract_footprints(xyz, np.where(inside, 6, 2))
    assert len(fps) == 2
    for f in fps:
        truth = max(houses, key=lambda h: h.intersection(f.polygon).area)
        assert f.polygon.intersection(truth).area / f.polygon.union(truth).area > 0.85


def test_within_a_box_gives_the_footprints_centred_there_unchanged():
    """A block keeps the footprints centred in its cell: those come out as without
    ``within`` (same polygons and attributes), regions far outside are not regularised."""
    houses = [shapely.box(x, y, x + 12, y + 9) for x in (5, 35, 65, 95) for y in (5, 40)]
    houses.append(shapely.Polygon([(50, 25), (75, 25), (75, 33), (58, 33), (58, 38), (50, 38)]))
    xyz, cls = scan(houses, extent=(0.0, 0.0, 120.0, 60.0), seed=3)
    every = extract_footprints(xyz, cls, regularize="snake")
    box = (40.0, 0.0, 70.0, 60.0)

    def centred(f):
        x0, y0, x1, y1 = f.polygon.bounds
        return box[0] <= (x0 + x1) / 2 < box[2] and box[1] <= (y0 + y1) / 2 < box[3]

    some = extract_footprints(xyz, cls, regularize="snake", within=box)
    want = [f for f in every if centred(f)]
    got = [f for f in some if centred(f)]
    assert len(want) == 3 and len(every) == 9
    assert len(some) < len(every)  # the houses far outside were left out
    assert [shapely.to_wkb(f.polygon) for f in got] == [shapely.to_wkb(f.polygon) for f in want]
    assert [f.attributes for f in got] == [f.attributes for f in want]


def test_regularised_outline_stays_within_its_reach():
    from lidar2city.footprints.extract import grid_lengths, regularised_reach

    xyz, cls = scan([affinity.rotate(L_SHAPE, 17, origin=(25, 25))], seed=5)
    traced = extract_footprints(xyz, cls, regularize="none", simplify=0.0)[0].polygon
    for f in extract_footprints(xyz, cls, regularize="snake"):
        reach = regularised_reach(grid_lengths(point_spacing(xyz[cls == 6, :2])), window=3)
        assert traced.buffer(reach / 4).contains(f.polygon)


def test_none_regulariser_simplifies_with_the_tolerance_only_when_asked():
    xyz, cls = scan([L_SHAPE], seed=7)
    traced = extract_footprints(xyz, cls, regularize="none", simplify=0.0)[0].polygon
    poly, _ = REGULARIZERS["none"](traced, tolerance=0.45)
    assert shapely.equals_exact(poly, simplify_polygon(traced, 0.45), 0.0)
    assert REGULARIZERS["none"](traced)[0] is traced


def test_point_spacing_with_the_distinct_count_given():
    xy = _jittered(1.0)
    pairs = np.vstack([xy, xy[:700]])
    assert point_spacing(pairs, distinct=len(xy)) == point_spacing(pairs)


def _same_footprints(a, b):
    """Whether two lists of footprints are the same to the bit (polygons, status,
    reasons, attributes)."""
    assert len(a) == len(b)
    for f, g in zip(a, b, strict=True):
        assert f.polygon.wkb == g.polygon.wkb
        assert (f.status, f.reason, f.attributes) == (g.status, g.reason, g.attributes)


def _staged(outlines, pieces, order):
    """The footprints of ``outlines`` regularised piece by piece (``pieces``: the piece
    of each part), the pieces in ``order``, each taken and sent as another process
    would get it (pickled), then put back in the parts' order and assembled."""
    import pickle

    from lidar2city.footprints.extract import assemble_footprints, regularise_outlines

    found = [None] * len(outlines)
    for p in order:
        idx = [k for k in range(len(outlines)) if pieces[k] == p]
        if not idx:
            continue
        piece = pickle.loads(pickle.dumps(outlines.take(idx)))
        assert [int(n) for n in piece.numbers] == idx
        for k, f in zip(idx, pickle.loads(pickle.dumps(regularise_outlines(piece))), strict=True):
            found[k] = f
    return assemble_footprints(outlines, found)


_STAGED_SCENE = {}


def _staged_scene():
    """Row houses of three heights (one region cut in three parts), an L shape and a
    courtyard: their outlines (snake) and their footprints in one pass."""
    if not _STAGED_SCENE:
        from lidar2city.footprints.extract import trace_outlines

        row = shapely.box(5, 5, 44, 15)
        xyz, cls = scan([row, affinity.translate(L_SHAPE, 0, 12), shapely.box(47, 20, 58, 55)],
                        seed=11)
        xyz = _with_roof(xyz, cls, lambda x, y: np.where(y < 16, np.where(
            (x >= 18) & (x < 31), 11.0, np.where(x >= 31, 14.5, 8.0)), 9.0))
        kw = {"regularize": "snake"}
        _STAGED_SCENE.update(outlines=trace_outlines(xyz, cls, **kw),
                             whole=extract_footprints(xyz, cls, **kw))
    return _STAGED_SCENE["outlines"], _STAGED_SCENE["whole"]


@settings(max_examples=12, deadline=None)
@given(st.lists(st.integers(0, 3), min_size=8, max_size=8), st.permutations(range(4)))
def test_outlines_regularised_in_any_pieces_give_the_footprints_of_one_pass(pieces, order):
    """The stages of extract_footprints run apart (the outlines cut into any pieces,
    regularised in any order, elsewhere) give its footprints to the bit, the parts
    of a region made disjoint as one pass makes them."""
    outlines, whole = _staged_scene()
    assert len(outlines) >= 5 and len(set(outlines.regions.tolist())) < len(outlines)
    assert len(whole) >= 5
    got = _staged(outlines, [pieces[k % len(pieces)] for k in range(len(outlines))], order)
    _same_footprints(got, whole)


def test_outline_stages_check_their_inputs():
    from lidar2city.footprints.extract import assemble_footprints, regularise_outlines

    outlines, _ = _staged_scene()
    with pytest.raises(InputError, match="footprints for"):
        assemble_footprints(outlines, regularise_outlines(outlines, [0]))
    assert outlines.work().shape == (len(outlines),) and (outlines.work() > 20).all()
    assert len(outlines.take([])) == 0


@pytest.mark.slow
def test_delft_outlines_regularised_in_pieces_give_the_footprints_of_one_pass(data):
    from lidar2city.footprints.extract import trace_outlines
    from lidar2city.io.las import read_points

    cloud = read_points(data / "delft" / "ahn3_cropped_1.laz")
    cls = cloud.get("classification")
    outlines = trace_outlines(cloud.xyz, cls, regularize="snake")
    whole = extract_footprints(cloud.xyz, cls, regularize="snake")
    assert len(outlines) >= 80
    rng = np.random.default_rng(3)
    _same_footprints(_staged(outlines, rng.integers(0, 3, len(outlines)), [2, 0, 1]), whole)
