"""Ground filters (SMRF, PMF), low outliers, grid kernels and DTMs on synthetic and real data."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lidar2city.errors import EmptyInputError, InputError
from lidar2city.ground import (
    GROUND_METHODS,
    GroundConfig,
    dtm_from_ground,
    ground_mask,
    height_above_ground,
    low_outliers,
    pmf,
    pmf_windows,
    smrf,
)
from lidar2city.ground._grid import (
    GridSpec,
    erode_square,
    grid_spec,
    inpaint,
    open_disk,
    open_disk_series,
    running_extreme,
    sample_bilinear,
)


def _jittered_grid(size, spacing, rng):
    g = np.stack(np.meshgrid(np.arange(0, size, spacing), np.arange(0, size, spacing)), -1)
    xy = g.reshape(-1, 2).astype(float)
    return xy + rng.uniform(-0.3, 0.3, xy.shape) * spacing


def _town(rng, terrain=lambda xy: np.zeros(len(xy))):
    """A 100 m x 100 m tile of terrain with four flat-roofed buildings; truth mask."""
    xy = _jittered_grid(100.0, 0.8, rng)
    z = terrain(xy) + rng.normal(0, 0.03, len(xy))
    ground = np.ones(len(xy), dtype=bool)
    for (x0, y0, x1, y1, h) in [(10, 10, 25, 30, 8.0), (40, 55, 70, 70, 12.0),
                                (75, 10, 85, 20, 4.0), (20, 70, 28, 90, 20.0)]:
        inside = (xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)
        z[inside] = terrain(np.array([[x0, y0]]))[0] + h + rng.normal(0, 0.03, inside.sum())
        ground[inside] = False
    return np.column_stack([xy, z]), ground


@pytest.mark.parametrize("method", sorted(GROUND_METHODS))
def test_boxes_on_flat_terrain_exact(method):
    xyz, truth = _town(np.random.default_rng(1))
    pred = ground_mask(xyz, method=method)
    assert pred.dtype == bool and pred.shape == truth.shape
    np.testing.assert_array_equal(pred, truth)


def test_boxes_on_gentle_slope():
    xyz, truth = _town(np.random.default_rng(2), terrain=lambda xy: 0.08 * xy[:, 0] + 0.05 * xy[:, 1])
    np.testing.assert_array_equal(smrf(xyz), truth)
    # PMF's thresholds reach dh_max = 3 m: on a slope the 4 m building (75..85, 10..20)
    # is within its tolerance (Zhang et al. 2003, a known limit); everything else is exact
    pred = pmf(xyz)
    low = (xyz[:, 0] > 75) & (xyz[:, 0] < 85) & (xyz[:, 1] > 10) & (xyz[:, 1] < 20)
    np.testing.assert_array_equal(pred[~low], truth[~low])


def test_hilly_terrain_not_eaten():
    """Rolling hills (up to ~25 % slope) without objects: nearly everything stays ground."""
    rng = np.random.default_rng(3)
    xy = _jittered_grid(150.0, 1.0, rng)
    z = 6.0 * np.sin(xy[:, 0] / 25.0) + 4.0 * np.cos(xy[:, 1] / 20.0)
    xyz = np.column_stack([xy, z])
    assert smrf(xyz).mean() > 0.97
    assert pmf(xyz).mean() > 0.97


def test_low_outliers_rejected():
    rng = np.random.default_rng(4)
    xyz, truth = _town(rng)
    far = np.array([[50.2, 40.1, -12.0], [5.3, 95.1, -3.0], [90.4, 45.6, -30.0]])
    xyz = np.vstack([xyz, far])
    truth = np.concatenate([truth, [False, False, False]])
    out = low_outliers(xyz)
    assert out[-3:].all() and not out[:-3].any()
    for method in GROUND_METHODS:
        np.testing.assert_array_equal(ground_mask(xyz, method=method), truth)


def test_low_outlier_cluster_rejected():
    """A line of multipath points 20 m below the ground (too many to be isolated)."""
    rng = np.random.default_rng(5)
    xyz, truth = _town(rng)
    t = np.linspace(0, 1, 25)
    line = np.column_stack([40 + 20 * t, 30 + 5 * t, -20 + rng.normal(0, 0.5, 25)])
    xyz = np.vstack([xyz, line])
    truth = np.concatenate([truth, np.zeros(25, bool)])
    out = low_outliers(xyz)
    assert out[-25:].all() and not out[:-25].any()
    np.testing.assert_array_equal(smrf(xyz), truth)


def test_low_outliers_keep_sunken_courtyard_and_steps():
    """A 3 m terrace step and a 2 m sunken square are terrain, not outliers."""
    rng = np.random.default_rng(6)
    xy = _jittered_grid(80.0, 1.0, rng)
    z = np.where(xy[:, 0] > 40, 3.0, 0.0)
    z[(abs(xy[:, 0] - 20) < 5) & (abs(xy[:, 1] - 40) < 5)] -= 2.0
    assert not low_outliers(np.column_stack([xy, z])).any()


def test_filters_do_not_mutate_and_are_translation_invariant():
    xyz, _ = _town(np.random.default_rng(7))
    before = xyz.copy()
    a = smrf(xyz)
    np.testing.assert_array_equal(xyz, before)
    shifted = xyz + np.array([1000.0, -500.0, 300.0])
    np.testing.assert_array_equal(smrf(shifted), a)
    np.testing.assert_array_equal(pmf(xyz + np.array([0.0, 0.0, 50.0])), pmf(xyz))


def test_bad_inputs():
    with pytest.raises(InputError):
        smrf(np.zeros((5, 2)))
    with pytest.raises(InputError):
        smrf(np.array([[0.0, 0.0, np.nan]] * 3))
    with pytest.raises(InputError, match="slope"):
        smrf(np.zeros((3, 3)), slope=0)
    with pytest.raises(InputError, match="method"):
        ground_mask(np.zeros((3, 3)), method="csf")
    with pytest.raises(InputError, match="window"):
        ground_mask(np.zeros((3, 3)), method="pmf", window=3.0)
    assert smrf(np.zeros((0, 3))).shape == (0,)
    assert pmf(np.zeros((1, 3))).tolist() == [True]


def test_pmf_windows_follow_zhang():
    w = pmf_windows(cell=1.0, max_window=33.0, slope=0.3, initial_distance=0.5,
                    max_distance=3.0, exponential=True, base=2.0)
    assert [s for s, _ in w] == [5, 9, 17, 33]
    assert w[0][1] == 0.5
    assert w[1][1] == pytest.approx(0.3 * (9 - 5) + 0.5)
    assert w[-1][1] == 3.0
    lin = pmf_windows(max_window=20.0, exponential=False, base=2.0)
    assert [s for s, _ in lin] == [5, 9, 13, 17]


def test_config_defaults_and_params():
    cfg = GroundConfig()
    assert cfg.method == "smrf_vote"
    p = GroundConfig(method="smrf_refined").method_params()
    assert p["slope"] == 0.15 and "max_window" not in p and p["extend"] == 10.0
    p = GroundConfig(method="smrf").method_params()
    assert p["slope"] == 0.15 and "extend" not in p and "rounds" not in p
    p = GroundConfig(method="pmf").method_params()
    assert p["slope"] == 0.3 and "window" not in p
    from lidar2city.errors import ConfigError

    with pytest.raises(ConfigError, match="ground.cell"):
        GroundConfig(cell=0)


# ----------------------------------------------------------------- grid kernels

@settings(max_examples=30, deadline=None)
@given(st.integers(1, 12), st.integers(1, 12), st.integers(0, 3), st.integers(0, 1000))
def test_running_min_equals_brute_force(h, w, half, seed):
    a = np.random.default_rng(seed).normal(size=(h, w))
    size = 2 * half + 1
    got = running_extreme(a, size, 1)
    want = np.array([[a[i, max(j - half, 0):j + half + 1].min() for j in range(w)] for i in range(h)])
    np.testing.assert_array_equal(got, want)
    got = erode_square(a, size)
    want = np.array([[a[max(i - half, 0):i + half + 1, max(j - half, 0):j + half + 1].min()
                      for j in range(w)] for i in range(h)])
    np.testing.assert_array_equal(got, want)


def test_disk_opening_properties():
    rng = np.random.default_rng(8)
    a = rng.normal(size=(40, 50)).cumsum(axis=0)
    series = dict(open_disk_series(a, [1, 2, 4, 7]))
    prev = a
    for r in (1, 2, 4, 7):
        np.testing.assert_allclose(series[r], open_disk(a, r))
        assert (series[r] <= prev + 1e-12).all()  # openings decrease with the radius
        np.testing.assert_allclose(open_disk(series[r], r), series[r])  # idempotent
        prev = series[r]
    # a plane is unchanged in the interior, a narrow spike removed
    yy, xx = np.mgrid[0:41, 0:41]
    plane = 0.3 * xx + 0.1 * yy
    np.testing.assert_allclose(open_disk(plane, 5)[10:-10, 10:-10], plane[10:-10, 10:-10])
    spike = np.zeros((41, 41))
    spike[18:23, 18:23] = 10.0
    assert open_disk(spike, 3).max() == 0.0


@pytest.mark.parametrize("shape", [(1, 9), (2, 2), (5, 2), (300, 260)])
def test_threaded_passes_give_the_same_bytes(shape, monkeypatch):
    """The opening series, the dilation chains and a vote on threads equal them on one."""
    from lidar2city.ground import _grid, smrf_vote
    from lidar2city.synthetic_terrain import make_terrain

    rng = np.random.default_rng(3)
    a = rng.normal(size=shape).cumsum(axis=0).astype(np.float32)
    a[rng.random(shape) < 0.05] = np.inf
    one = {}
    for threads in (1, 2):
        monkeypatch.setattr(_grid, "_thread_count", lambda n=threads: n)
        series = [(r, o.copy()) for r, o in open_disk_series(a, range(1, 9))]
        chains = [_grid._disk_chain(a, r, m) for r in (0, 1, 5) for m in (False, True)]
        if threads == 1:
            one = {"series": series, "chains": chains}
            continue
        assert [r for r, _ in series] == [r for r, _ in one["series"]]
        for (_, got), (_, want) in zip(series, one["series"]):
            np.testing.assert_array_equal(got, want)
        for got, want in zip(chains, one["chains"]):
            np.testing.assert_array_equal(got, want)
    # a chain of unit steps by the buffered code equals the plain one step by step
    for r in (1, 2, 5):
        for m in (False, True):
            want = a
            for i in range(1, r + 1):
                want = _grid._unit_step(want, _grid._is_square_step(i), m)
            np.testing.assert_array_equal(_grid._disk_chain(a, r, m), want)
    if shape == (300, 260):  # a grid large enough for threads
        xyz = make_terrain("terraces", spacing=1.0, seed=2).xyz
        masks = []
        for threads in (1, 2):
            monkeypatch.setattr(_grid, "_thread_count", lambda n=threads: n)
            monkeypatch.setattr(_grid, "THREADED_CELLS", 100)
            masks.append(smrf_vote(xyz))
        np.testing.assert_array_equal(masks[0], masks[1])


def test_inpaint_keeps_known_and_interpolates():
    yy, xx = np.mgrid[0:60, 0:80].astype(float)
    plane = 2.0 + 0.5 * xx - 0.25 * yy
    holed = plane.copy()
    holed[10:40, 20:60] = np.nan
    filled = inpaint(holed)
    known = np.isfinite(holed)
    np.testing.assert_array_equal(filled[known], plane[known])
    assert np.isfinite(filled).all()
    # harmonic fill of a planar boundary is the plane
    np.testing.assert_allclose(filled, plane, atol=0.06)
    with pytest.raises(InputError):
        inpaint(np.full((3, 3), np.nan))


def test_sample_bilinear_exact_on_planes():
    spec = GridSpec(0.0, 10.0, 1.0, (10, 12))
    xs, ys = spec.centers()
    grid = 3.0 + 0.7 * xs[None, :] - 0.2 * ys[:, None]
    rng = np.random.default_rng(9)
    xy = rng.uniform([0.5, 0.5], [11.5, 9.5], (100, 2))
    np.testing.assert_allclose(sample_bilinear(grid, spec, xy), 3.0 + 0.7 * xy[:, 0] - 0.2 * xy[:, 1])


def test_grid_spec_aligned():
    spec = grid_spec(np.array([[0.3, 0.7], [10.2, 4.9]]), cell=2.0)
    assert spec.x0 == 0.0 and spec.shape == (3, 6) and spec.y_top == 6.0


# ----------------------------------------------------------------------- DTM

def test_dtm_fills_holes_and_heights():
    xyz, truth = _town(np.random.default_rng(10), terrain=lambda xy: 0.1 * xy[:, 0])
    dtm = dtm_from_ground(xyz, truth, cell=1.0)
    assert np.isfinite(dtm.array).all()
    assert not dtm.measured.all() and dtm.measured.mean() > 0.7
    # under the buildings the terrain is interpolated, not the roof
    hag = height_above_ground(xyz, dtm)
    assert np.abs(hag[truth]).max() < 0.25
    assert hag[~truth].min() > 2.5  # the 4 m building stands on the 0.1 slope
    xs, _ = dtm.spec.centers()
    np.testing.assert_allclose(dtm.array.mean(axis=0), 0.1 * xs, atol=0.3)


def test_dtm_bounds_and_errors():
    xyz = np.array([[0.5, 0.5, 1.0], [3.5, 2.5, 2.0]])
    dtm = dtm_from_ground(xyz, np.array([True, True]), cell=1.0, bounds=(0, 0, 9.9, 9.9))
    assert dtm.shape == (10, 10)
    with pytest.raises(EmptyInputError):
        dtm_from_ground(xyz, np.array([False, False]))
    with pytest.raises(InputError):
        dtm_from_ground(xyz, np.array([True]))


def test_dtm_raster_round_trip():
    xyz, truth = _town(np.random.default_rng(11), terrain=lambda xy: 0.05 * xy[:, 1])
    dtm = dtm_from_ground(xyz, truth, cell=2.0)
    origin = np.array([84800.0, 447400.0, -2.0])
    feet = 0.3048
    arr = dtm.world_heights(origin[2], feet)
    arr[3, 4] = np.nan  # a nodata cell gets filled
    back = type(dtm).from_raster(arr, dtm.world_transform(origin, feet), origin,
                                 xy_unit=feet, z_unit=feet)
    assert (back.x0, back.y_top, back.cell) == pytest.approx((dtm.x0, dtm.y_top, dtm.cell))
    np.testing.assert_allclose(back.array, dtm.array, atol=0.05)
    assert not back.measured[3, 4]
    np.testing.assert_allclose(height_above_ground(xyz, back), height_above_ground(xyz, dtm), atol=0.05)


def test_dtm_world_transform():
    xyz = np.array([[0.5, 0.5, 1.0], [10.5, 5.5, 2.0]])
    dtm = dtm_from_ground(xyz, np.array([True, True]), cell=1.0)
    t = dtm.world_transform(np.array([1000.0, 2000.0, 0.0]), xy_unit=0.3048)
    assert t.a == pytest.approx(1 / 0.3048) and t.e == pytest.approx(-1 / 0.3048)
    assert t.c == pytest.approx(1000.0) and t.f == pytest.approx(2000.0 + 6 / 0.3048)


# ------------------------------------------------------------------ real data

def test_samp11_smrf_total_error(data):
    """ISPRS samp11 (steep urban slopes): measured 9.2 % total error, kappa 81 % with the defaults; PMF 12.2 %."""
    import laspy

    from lidar2city.metrics.ground import ground_errors

    las = laspy.read(data / "isprs" / "reference" / "samp11-utm.laz")
    xyz = np.column_stack([las.x, las.y, las.z])
    xyz -= np.floor(xyz.min(axis=0))
    ref = np.asarray(las.classification) == 2
    e = ground_errors(smrf(xyz), ref)
    assert e["total"] < 0.105
    assert e["kappa"] > 0.78
    e = ground_errors(pmf(xyz), ref)
    assert e["total"] < 0.14


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 60), st.floats(0.1, 200.0), st.integers(0, 10_000),
       st.sampled_from(sorted(GROUND_METHODS)))
def test_any_small_cloud_gives_a_mask(n, extent, seed, method):
    """Degenerate shapes (one point, a line, a tiny patch) never crash; the lowest point is ground."""
    rng = np.random.default_rng(seed)
    xyz = rng.uniform(0, extent, (n, 3)) * np.array([1.0, rng.choice([0.0, 1.0]), 0.1])
    mask = ground_mask(xyz, method=method)
    assert mask.shape == (n,) and mask.dtype == bool
    if n < 4:
        assert mask[np.argmin(xyz[:, 2])]


@pytest.mark.slow
def test_isprs_mean_total_error_target(data):
    """Mean total error over the ISPRS samples, one parameter set (the defaults).

    Measured: smrf_vote 2.98 % (max 8.08 %, samp11; kappa 90.9 %; with session 16's fitted
    thresholds near 1.14, steep 0.92: 2.99 % and 7.99 %; 3.04 % and 8.01 % also without
    its wall anchor and ``above``, the defaults until session 16; 3.07 % and 7.87 %
    without those and its veto), smrf_segments 3.34 % (kappa 89.9 %, max 7.25 %),
    smrf_refined 3.54 % (kappa 89.4 %), SMRF 3.56 % (kappa 89.3 %), PMF 4.57 %.
    Leave-one-sample-out: smrf_vote 3.02 % (bench_ground_vote.py; 3.17 % with session 16's
    fitted thresholds; 3.31 % with its slopes chosen per fold too, --pairs, against 3.42 %),
    smrf_segments 3.57 %, smrf_refined 3.67 %, SMRF 3.88 % (bench_ground.py --loo).
    """
    import laspy

    from lidar2city.metrics.ground import ground_errors

    paths = sorted((data / "isprs" / "reference").glob("samp*-utm.laz"))
    assert len(paths) == 7
    totals = {"smrf": [], "smrf_refined": [], "smrf_segments": [], "smrf_vote": [], "pmf": []}
    for path in paths:
        las = laspy.read(path)
        xyz = np.column_stack([las.x, las.y, las.z])
        xyz -= np.floor(xyz.min(axis=0))
        ref = np.asarray(las.classification) == 2
        for method in totals:
            cfg = GroundConfig(method=method)
            totals[method].append(ground_errors(ground_mask(xyz, method=method, **cfg.method_params()),
                                                ref)["total"])
    assert np.mean(totals["smrf"]) <= 0.038
    assert np.mean(totals["smrf_refined"]) <= 0.037
    assert max(totals["smrf_refined"]) <= 0.095
    assert np.mean(totals["smrf_segments"]) <= 0.035
    assert max(totals["smrf_segments"]) <= 0.08
    assert np.mean(totals["smrf_vote"]) <= 0.031
    assert max(totals["smrf_vote"]) <= 0.081
    assert np.mean(totals["pmf"]) <= 0.048


def _relax_whole_grid(values, unknown, iterations, omega=1.6):
    """Red-black SOR written plainly: each colour computed on the whole padded grid."""
    p = np.pad(values, 1)
    v = p[1:-1, 1:-1]
    parity = np.add.outer(np.arange(values.shape[0]), np.arange(values.shape[1])) % 2 == 1
    quarter, keep = values.dtype.type(omega / 4.0), values.dtype.type(1.0 - omega)
    for _ in range(iterations):
        for colour in (unknown & ~parity, unknown & parity):
            p[0, 1:-1], p[-1, 1:-1], p[1:-1, 0], p[1:-1, -1] = v[0], v[-1], v[:, 0], v[:, -1]
            new = p[:-2, 1:-1] + p[2:, 1:-1]
            new += p[1:-1, :-2]
            new += p[1:-1, 2:]
            new *= quarter
            new += keep * v
            np.copyto(v, new, where=colour)
    return v.copy()


@pytest.mark.parametrize("seed", range(6))
def test_relax_sweeps_each_colour_like_the_whole_grid(seed):
    from lidar2city.ground._grid import _relax

    rng = np.random.default_rng(seed)
    for _ in range(30):
        h, w = (int(n) for n in rng.integers(1, 25, 2))
        values = rng.normal(size=(h, w)).astype(rng.choice([np.float32, np.float64]))
        unknown = rng.random((h, w)) < rng.random()
        expected = _relax_whole_grid(values.copy(), unknown, 4)
        np.testing.assert_array_equal(_relax(values.copy(), unknown, 4), expected)
