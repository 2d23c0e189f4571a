"""Return cues read per survey, and building detection on the synthetic survey variants."""

from __future__ import annotations

import numpy as np
import pytest

from lidar2city.classify import classify_points, survey_cues
from lidar2city.classify.core import _classify
from lidar2city.errors import InputError
from lidar2city.metrics.classification import ASPRS_MAPPING, classification_scores
from lidar2city.synthetic import make_town
from lidar2city.synthetic_surveys import SURVEY_KINDS, add_canopy, make_survey, survey_variant


def _building_f1(cloud, cls):
    s = classification_scores(cloud.attributes["classification"], cls, mapping=ASPRS_MAPPING,
                              predicted_mapping=ASPRS_MAPPING, ignore=(7,))
    return s.f1["building"]


def _classify_cloud(cloud):
    a = cloud.attributes
    return classify_points(cloud.xyz, a["classification"] == 2, return_number=a.get("return_number"),
                           number_of_returns=a.get("number_of_returns"))


@pytest.fixture(scope="module")
def town():
    return make_town(size=(120, 90), density=6, seed=2)


# --- the survey variants themselves --------------------------------------------


def test_pairs_variant_is_first_then_last_pulse(town):
    pairs = survey_variant(town, "pairs")
    a = pairs.attributes
    m = len(pairs) // 2
    assert len(pairs) == 2 * m == 2 * int((town.cloud.attributes["return_number"] == 1).sum())
    assert (a["number_of_returns"] == 2).all()
    assert (a["return_number"][:m] == 1).all() and (a["return_number"][m:] == 2).all()
    # one-echo pulses repeat their point up to range noise; two-echo ones do not
    dz = pairs.xyz[:m, 2] - pairs.xyz[m:, 2]
    assert np.array_equal(pairs.xyz[:m, :2], pairs.xyz[m:, :2])
    assert (np.abs(dz) < 0.15).mean() > 0.9 and (dz > 1.0).sum() > 50


def test_single_and_no_return_variants(town):
    single = survey_variant(town, "single")
    assert (single.attributes["number_of_returns"] == 1).all()
    assert len(single) == int((town.cloud.attributes["return_number"] == 1).sum())
    bare = survey_variant(town, "no_returns")
    assert set(bare.attributes) == {"classification"}


def test_feet_variant_has_feet_units_and_same_metric_scene(town):
    feet = survey_variant(town, "feet")
    assert feet.xy_unit == pytest.approx(0.3048006, rel=1e-6)
    assert feet.z_unit == pytest.approx(0.3048006, rel=1e-6)
    assert np.array_equal(feet.xyz, town.cloud.xyz)


def test_unknown_kind_and_determinism(town):
    with pytest.raises(InputError, match="kind must be one of"):
        survey_variant(town, "waveform")
    a = survey_variant(town, "pairs", seed=4, shuffle=True)
    b = survey_variant(town, "pairs", seed=4, shuffle=True)
    assert np.array_equal(a.xyz, b.xyz)
    assert set(SURVEY_KINDS) == {"multi", "pairs", "single", "no_returns", "feet"}


# --- reading the cues ------------------------------------------------------------


def test_cues_per_survey(town):
    multi = town.cloud.attributes
    c = survey_cues(town.cloud.xyz, return_number=multi["return_number"],
                    number_of_returns=multi["number_of_returns"])
    assert c.returns == "multi" and c.has_returns and not c.duplicate.any()
    assert np.array_equal(c.multi, multi["number_of_returns"] > 1)
    single = survey_variant(town, "single")
    c = survey_cues(single.xyz, return_number=single.attributes["return_number"],
                    number_of_returns=single.attributes["number_of_returns"])
    assert c.returns == "single" and not c.has_returns
    assert survey_cues(single.xyz).returns == "absent"
    zeros = np.zeros(len(single), np.uint8)
    c = survey_cues(single.xyz, return_number=zeros, number_of_returns=zeros)
    assert c.returns == "inconsistent" and not c.multi.any()


def test_pairs_recognised_in_file_order_and_shuffled(town):
    for shuffle in (False, True):
        pairs = survey_variant(town, "pairs", shuffle=shuffle)
        a = pairs.attributes
        c = survey_cues(pairs.xyz, return_number=a["return_number"],
                        number_of_returns=a["number_of_returns"])
        assert c.returns == "pairs"
        # duplicates are first pulses whose partner is the last pulse at the same place
        d = np.flatnonzero(c.duplicate)
        assert (a["return_number"][d] == 1).all()
        assert (a["return_number"][c.partner[d]] == 2).all()
        assert np.allclose(pairs.xyz[d, :2], pairs.xyz[c.partner[d], :2], atol=0.2)
        # every roof pulse is one echo; tree pulses with a distinct last echo stay multi
        roof = a["classification"] == 6
        assert not c.multi[roof].any()
        assert c.multi.sum() > 100
        assert (c.not_last <= c.multi).all()


def test_intensity_inspected():
    xyz = np.random.default_rng(0).random((50, 3))
    assert survey_cues(xyz).intensity == "absent"
    assert survey_cues(xyz, intensity=np.full(50, 7)).intensity == "constant"
    assert survey_cues(xyz, intensity=np.arange(50)).intensity == "informative"


def test_pair_duplicates_take_their_partner_class(town):
    pairs = survey_variant(town, "pairs")
    a = pairs.attributes
    out = _classify(pairs.xyz, a["classification"] == 2, return_number=a["return_number"],
                    number_of_returns=a["number_of_returns"])
    cues = out["cues"]
    d = np.flatnonzero(cues.duplicate)
    assert len(d) and np.array_equal(out["classes"][d], out["classes"][cues.partner[d]])
    assert len(out["kept"]) == len(pairs) - len(d)


def test_pairs_read_literally_would_lose_the_roofs(town):
    """Regression: every point '2 of 2' made every roof a multi-return target."""
    pairs = survey_variant(town, "pairs")
    a = pairs.attributes
    cls = _classify_cloud(pairs)
    roof = a["classification"] == 6
    assert (cls[roof] == 6).mean() > 0.95


# --- building F1 on every survey variant ------------------------------------------


@pytest.mark.parametrize("kind", ["multi", "pairs", "single", "no_returns"])
def test_variant_building_f1(town, kind):
    cloud = survey_variant(town, kind, shuffle=kind == "pairs")
    assert _building_f1(cloud, _classify_cloud(cloud)) >= 0.95


def test_feet_file_round_trip_building_f1(town, tmp_path):
    from lidar2city.io.las import read_points, write_points

    feet = survey_variant(town, "feet")
    write_points(tmp_path / "feet.laz", feet)
    back = read_points(tmp_path / "feet.laz")
    assert back.xy_unit == pytest.approx(feet.xy_unit)
    assert np.allclose(back.xyz + back.origin * back.unit_scale,
                       feet.xyz + feet.origin * feet.unit_scale, atol=0.01)
    assert _building_f1(back, _classify_cloud(back)) >= 0.95


@pytest.mark.parametrize("density", [1.5, 25.0])
def test_density_building_f1(density):
    cloud = make_survey("multi", density=density, size=(120, 90) if density > 2 else (200, 150),
                        seed=1)
    assert _building_f1(cloud, _classify_cloud(cloud)) >= 0.95


# --- dense multi-echo canopy (IGN LiDAR HD style) -------------------------------


@pytest.fixture(scope="module")
def canopy_town():
    return add_canopy(make_town(size=(120, 90), density=6, seed=2), seed=2)


def test_canopy_echoes_are_consistent_pulses(canopy_town):
    a = canopy_town.cloud.attributes
    rn, nr = a["return_number"].astype(int), a["number_of_returns"].astype(int)
    assert nr.max() == 5 and (rn >= 1).all() and (rn <= nr).all()
    # every canopy pulse of n echoes stores echoes 1..n at one x, y (make_town's
    # own trees give at most 2; where two of its crowns overlap they are not
    # consistent, so only the pulses of 3 or more echoes are checked)
    xy = canopy_town.cloud.xyz[:, :2]
    _, inv = np.unique(xy, axis=0, return_inverse=True)
    inv = inv.ravel()
    count = np.bincount(inv)
    deep = nr >= 3
    assert deep.sum() > 1000
    assert (count[inv[deep]] == nr[deep]).all()
    pulses = np.unique(inv[deep])
    assert (np.bincount(inv, rn)[pulses] == count[pulses] * (count[pulses] + 1) / 2).all()
    # crowns over roofs: some roof points are later echoes under vegetation
    cls = a["classification"]
    assert ((cls == 6) & (rn > 1)).any()
    veg = np.isin(cls, (3, 4, 5))
    assert veg.mean() > 0.2


def test_canopy_is_deterministic_and_checked(canopy_town):
    again = add_canopy(make_town(size=(120, 90), density=6, seed=2), seed=2)
    assert np.array_equal(again.cloud.xyz, canopy_town.cloud.xyz)
    town = make_town(size=(60, 50), density=2, seed=1)
    with pytest.raises(InputError):
        add_canopy(town, max_returns=1)
    with pytest.raises(InputError):
        add_canopy(town, cover=1.5)


@pytest.mark.parametrize("kind", ["multi", "pairs", "single", "no_returns"])
def test_canopy_variant_building_f1(canopy_town, kind):
    cloud = survey_variant(canopy_town, kind)
    if kind == "pairs":
        assert (cloud.attributes["number_of_returns"] == 2).all()
    assert _building_f1(cloud, _classify_cloud(cloud)) >= 0.95


def test_smooth_crowns_need_the_region_roughness_cue(canopy_town):
    """Without returns, smooth crowns grow large planar regions; their points
    barely pass the planarity threshold while a roof's lie well inside it.
    Measured at 6 pts/m2: building F1 0.99 with the cue, 0.54 without."""
    cloud = survey_variant(canopy_town, "single")
    a = cloud.attributes
    off = classify_points(cloud.xyz, a["classification"] == 2, max_region_roughness=1.0)
    assert _building_f1(cloud, off) < 0.8
    assert _building_f1(cloud, _classify_cloud(cloud)) >= 0.95


# --- real first/last-pulse data ---------------------------------------------------


@pytest.mark.slow
def test_isprs_first_last_pulse_site_finds_buildings(data):
    """ISPRS CSite1 (Stuttgart, first and last pulse as separate points, all "n of 2"):
    read literally, every roof was a multi-return target and no point was building.

    Measured (ground from ground_mask): 42 % of the first-pulse points building;
    vegetation: 40 % of the two-echo first pulses, 3 % of the one-echo ones.
    """
    from lidar2city.ground import ground_mask
    from lidar2city.io.las import read_points

    cloud = read_points(data / "isprs" / "sites" / "CSite1_red2-utm.laz")
    a = cloud.attributes
    assert (a["number_of_returns"] == 2).all()
    out = _classify(cloud.xyz, ground_mask(cloud.xyz), return_number=a["return_number"],
                    number_of_returns=a["number_of_returns"], intensity=a["intensity"])
    assert out["cues"].returns == "pairs"
    assert out["cues"].intensity == "informative"
    first = a["return_number"] == 1
    assert (out["classes"][first] == 6).mean() > 0.3
    # a pulse with first and last far apart is a vegetation cue (roof edges
    # give such pulses too): its first pulse is far more often vegetation
    two = first & out["cues"].multi
    veg = np.isin(out["classes"], (3, 4, 5))
    assert veg[two].mean() > 3 * veg[first & ~two].mean()


def test_constant_or_unpaired_returns_are_no_cue(town):
    """All "2 of 2" (e.g. last pulses only) or all multi-echo without pairs: no cue."""
    single = survey_variant(town, "single")
    twos = np.full(len(single), 2, np.uint8)
    c = survey_cues(single.xyz, return_number=twos, number_of_returns=twos)
    assert c.returns == "constant" and not c.multi.any()
    # every point "1 of 2" or "2 of 2" but first and last never coincide
    rn = np.where(np.arange(len(single)) % 2 == 0, 1, 2).astype(np.uint8)
    shifted = single.xyz + np.where(rn[:, None] == 2, [0.0, 0.0, 5.0], 0.0)
    c = survey_cues(shifted, return_number=rn, number_of_returns=twos)
    assert c.returns == "constant" and not c.has_returns
    cls = classify_points(single.xyz, single.attributes["classification"] == 2,
                          return_number=twos, number_of_returns=twos)
    assert _building_f1(single, cls) >= 0.95


def test_scan_lines_survey_has_its_density_and_anisotropy():
    from scipy.spatial import cKDTree

    from lidar2city.synthetic_surveys import scan_lines

    town = make_town(size=(60, 50), density=96, seed=1)
    lines = scan_lines(town.cloud, 8.0, 8.0)
    first = lines.attributes["return_number"] == 1
    assert len(lines.xyz[first]) / (60 * 50) == pytest.approx(8.0, rel=0.1)
    d, i = cKDTree(lines.xyz[first, :2]).query(lines.xyz[first, :2], k=2)
    off = np.abs(lines.xyz[first][i[:, 1], :2] - lines.xyz[first, :2])
    assert np.median(off[:, 0]) > 2 * np.median(off[:, 1])  # neighbours along the line (x)


def test_buildings_found_in_a_survey_of_scan_lines_8_to_1():
    """Points 8 x closer along the scan lines than across (8 pts/m2): every k-neighbourhood
    lay on one line, so no point had a plane and no building was found (F1 0.000 on the
    200 m x 150 m town; 0.2 m along, 1 m across)."""
    cloud = make_survey("multi", density=8.0, size=(120, 90), seed=2, anisotropy=8.0)
    assert _building_f1(cloud, _classify_cloud(cloud)) > 0.9
