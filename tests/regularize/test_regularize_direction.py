"""Dominant direction (length-weighted histogram, projection profiles) and frame rotation."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.errors import EmptyInputError, InputError
from lidar2city.regularize.direction import (
    aligned_fraction,
    dominant_direction,
    from_frame,
    segments_of,
    to_frame,
)


def angle_diff_deg(a, b):
    d = np.degrees(a - b) % 90
    return min(d, 90 - d)


@pytest.mark.parametrize("method", ["histogram", "profile"])
@pytest.mark.parametrize("deg", [0.0, 12.5, 30.0, 44.0, 46.0, 89.0])
def test_rotated_l_shape(method, deg):
    l_shape = shapely.Polygon([(0, 0), (20, 0), (20, 6), (8, 6), (8, 14), (0, 14)])
    g = shapely.affinity.rotate(l_shape, deg, origin=(3, 4))
    got = dominant_direction(g, method=method)
    assert 0 <= got < np.pi / 2
    assert angle_diff_deg(got, np.radians(deg)) < 0.1


@pytest.mark.parametrize("method", ["histogram", "profile"])
def test_noisy_outline_direction(method):
    rng = np.random.default_rng(4)
    rect = shapely.affinity.rotate(shapely.box(0, 0, 24, 10), 37, origin=(0, 0))
    pts = shapely.get_coordinates(shapely.segmentize(rect, 1.0).exterior)[:-1]
    noisy = shapely.Polygon(pts + rng.normal(0, 0.1, pts.shape))
    got = dominant_direction(noisy.simplify(0.3) if method == "histogram" else noisy, method=method)
    assert angle_diff_deg(got, np.radians(37)) < 2.0


def test_oblique_minority_does_not_win():
    # A long rectangle with one short 45-degree chamfer.
    g = shapely.Polygon([(0, 0), (30, 0), (30, 8), (3, 8), (0, 5)])
    assert angle_diff_deg(dominant_direction(g), 0.0) < 0.5


def test_rings_and_segments_inputs_agree():
    ring = np.array([[0, 0], [10, 1], [9, 11], [-1, 10]], dtype=float)
    a = dominant_direction([ring])
    b = dominant_direction(segments_of(shapely.Polygon(ring)))
    assert a == pytest.approx(b)


def test_errors():
    with pytest.raises(EmptyInputError):
        dominant_direction(shapely.Polygon())
    with pytest.raises(InputError, match="method"):
        dominant_direction(shapely.box(0, 0, 1, 1), method="hough")
    with pytest.raises(InputError, match="bin_deg"):
        dominant_direction(shapely.box(0, 0, 1, 1), bin_deg=7)


@settings(max_examples=50, deadline=None)
@given(
    st.floats(0, 2 * np.pi),
    st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)),
    st.lists(st.tuples(st.floats(-100, 100), st.floats(-100, 100)), min_size=1, max_size=20),
)
def test_frame_round_trip(angle, origin, pts):
    xy = np.array(pts)
    back = from_frame(to_frame(xy, angle, origin), angle, origin)
    np.testing.assert_allclose(back, xy, atol=1e-9)


def test_to_frame_aligns_direction():
    v = np.array([[0.0, 0.0], [np.cos(0.3), np.sin(0.3)]])
    f = to_frame(v, 0.3)
    np.testing.assert_allclose(f[1], [1.0, 0.0], atol=1e-12)


def test_aligned_fraction():
    g = shapely.Polygon([(0, 0), (30, 0), (30, 8), (3, 8), (0, 5)])
    chamfer = np.hypot(3, 3)
    expected = (g.length - chamfer) / g.length
    assert aligned_fraction(g, 0.0) == pytest.approx(expected)
    assert aligned_fraction(shapely.Polygon()) == 0.0


def _profile_score_points_major(pts, w, angles, binw):
    """The profile score as first written (one histogram row per angle built from a
    points x angles array): the angle-major form must give the same bits."""
    from scipy import ndimage

    fine = binw / 4
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros(len(angles))
    for proj in (pts[:, :1] * c + pts[:, 1:] * s, pts[:, 1:] * c - pts[:, :1] * s):
        b = np.floor(proj / fine).astype(np.int64)
        b -= b.min(axis=0) - 8
        nb = int(b.max()) + 9
        flat = (b + np.arange(len(angles)) * nb).ravel()
        h = np.bincount(flat, weights=np.repeat(w, len(angles)), minlength=nb * len(angles))
        h = ndimage.gaussian_filter1d(h.reshape(len(angles), nb), 2.0, axis=1, mode="constant")
        out += (h**2).sum(axis=1)
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_profile_score_matches_points_major_form(seed):
    from lidar2city.regularize.direction import _profile_score

    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 3000))
    pts = rng.normal(0.0, rng.uniform(1.0, 40.0), size=(n, 2))
    pts -= pts.mean(axis=0)
    w = rng.uniform(0.01, 0.2, size=n)
    angles = np.radians(np.arange(0.0, 90.0, 0.5))
    binw = float(rng.uniform(0.1, 0.5))
    got = _profile_score(pts, w, angles, binw)
    assert np.array_equal(got, _profile_score_points_major(pts, w, angles, binw))
