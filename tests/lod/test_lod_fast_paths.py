"""The LoD1.3 fast paths give what the plain computations they replace give."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city._components import component_labels
from lidar2city.lod import lod13
from lidar2city.lod.lod13 import _merge_by_height, _neighbour_pairs


def _merge_by_height_plain(labels, pairs, mask, hv, step, percentile=70.0):
    """Every region measured again and the closest pair of neighbours merged, one merge
    per pass (the definition :func:`_merge_by_height` keeps)."""
    lab = labels.copy()
    cells = np.flatnonzero(mask.ravel())
    height = np.zeros(lab.max() + 1)
    while True:
        la, lb = lab[pairs[:, 0]], lab[pairs[:, 1]]
        diff = la != lb
        if not diff.any():
            return lab
        k, z = lab[cells], hv[cells]
        order = np.lexsort((z, k))
        k, z = k[order], z[order]
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        pos = starts + (np.diff(np.r_[starts, len(k)]) - 1) * (percentile / 100.0)
        lo = np.floor(pos).astype(np.int64)
        hi = np.minimum(lo + 1, len(z) - 1)
        height[k[starts]] = z[lo] + (z[hi] - z[lo]) * (pos - lo)
        pair = {(min(a, b), max(a, b)) for a, b in zip(la[diff].tolist(), lb[diff].tolist())}
        gap, a, b = min((abs(height[a] - height[b]), a, b) for a, b in pair)
        if gap >= step:
            return lab
        lab[lab == b] = a


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 30), cols=st.integers(1, 30),
       decimals=st.sampled_from([0, 1, 3]), scale=st.sampled_from([3.0, 10.0, 20.0]),
       step=st.sampled_from([1.0, 2.0, 4.0]), few=st.sampled_from([0, 3, 200]))
def test_merge_by_height_is_the_plain_merge(seed, rows, cols, decimals, scale, step, few):
    # rounded heights: many equal gaps, so the tie order is exercised
    rng = np.random.default_rng(seed)
    mask = rng.random((rows, cols)) < 0.9
    hv = np.round(rng.random(rows * cols) * scale, decimals)
    pairs = _neighbour_pairs((rows, cols), mask)
    ok = np.abs(hv[pairs[:, 0]] - hv[pairs[:, 1]]) <= 1.0
    lab = component_labels(rows * cols, pairs[ok, 0], pairs[ok, 1])
    # ``few``: the most regions measured in Python lists (more go to the arrays' loop)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(lod13, "_LIST_REGIONS", few)
        got = _merge_by_height(lab, pairs, mask, hv, step)
    np.testing.assert_array_equal(got, _merge_by_height_plain(lab, pairs, mask, hv, step))


def _prisms_of(rng, parts, hole):
    """Random star-shaped prisms side by side (some with a hole), as LoD1.3 parts."""
    from shapely.geometry import Polygon

    from lidar2city.lod.prism import clean_polygon, prism_solid

    solids = []
    for j in range(parts):
        n = int(rng.integers(3, 11))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        rad = rng.uniform(3, 20, n)
        shell = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)]) + [25.0 * j, 0.0]
        holes = [shell.mean(axis=0) + np.array([[1, 0], [0, 1], [-1, 0], [0, -1.0]])[::-1]] \
            if hole else []
        for p in clean_polygon(Polygon(shell, holes), grid=0.001):
            g = float(rng.uniform(-1, 1))
            solids.append((p, prism_solid(p, g, g + float(rng.uniform(0.5, 12)), grid=0.001)))
    return solids


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), parts=st.integers(2, 4), hole=st.booleans())
def test_prism_distance_is_the_same_at_once_and_tile_by_tile(seed, parts, hole):
    # few points and edges are measured all against all (DIRECT_PAIRS), many tile by tile:
    # the same doubles either way
    import lidar2city.lod.prism as prism

    rng = np.random.default_rng(seed)
    solids = [s for _, s in _prisms_of(rng, parts, hole)]
    lo = np.min([s.vertices.min(axis=0) for s in solids], axis=0) - 3
    hi = np.max([s.vertices.max(axis=0) for s in solids], axis=0) + 3
    pts = rng.uniform(lo, hi, (300, 3))
    at_once = prism.prism_distance(pts, solids)
    saved = prism.DIRECT_PAIRS
    try:
        prism.DIRECT_PAIRS = 0
        tiled = prism.prism_distance(pts, solids)
    finally:
        prism.DIRECT_PAIRS = saved
    np.testing.assert_array_equal(at_once, tiled)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), hole=st.booleans())
def test_inside_distance_and_layout_checks_equal_the_prisms_own(seed, hole):
    # a prism's layout as built is the one found from its surfaces; the distance of the
    # points inside its footprint (GEOS) is prism_distance's; the validity is prism_is_valid's
    import shapely

    from lidar2city.lod.prism import (_layout_distance, _layout_inside_distance,
                                      _layout_is_valid, _prism_layout, _prism_solid,
                                      prism_distance, prism_is_valid)

    rng = np.random.default_rng(seed)
    for poly, _ in _prisms_of(rng, 1, hole):
        g = float(rng.uniform(-1, 1))
        solid, layout = _prism_solid(poly, g, g + float(rng.uniform(0.5, 12)), 0.001)
        found = _prism_layout(solid)
        assert all(np.array_equal(a, b) for a, b in zip(layout[:2], found[:2], strict=True))
        assert list(layout[2]) == list(found[2]) and list(layout[3]) == list(found[3])
        assert all(np.array_equal(a, b) for a, b in zip(layout[4], found[4], strict=True))
        assert _layout_is_valid(layout) == prism_is_valid(solid)
        x0, y0, x1, y1 = poly.bounds
        pts = np.column_stack([rng.uniform(x0, x1, 500), rng.uniform(y0, y1, 500),
                               rng.uniform(g - 3, g + 15, 500)])
        pts = pts[shapely.contains_xy(poly, pts[:, 0], pts[:, 1])]
        want = prism_distance(pts, [solid])
        np.testing.assert_array_equal(_layout_distance(pts, [layout]), want)
        np.testing.assert_array_equal(_layout_inside_distance(pts, layout, chunk_pairs=97),
                                      want)


def test_lod1_does_not_import_the_footprint_extraction():
    # a run with given footprints measures the point spacing (LoD1's coverage) without
    # importing lidar2city.footprints and through it the classification and ground filters
    import subprocess
    import sys

    code = ("import sys, lidar2city.lod.lod1, lidar2city.tools.reconstruct; "
            "print(sorted(m for m in sys.modules if m.startswith(('lidar2city.footprints', "
            "'lidar2city.classify', 'lidar2city.ground'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
