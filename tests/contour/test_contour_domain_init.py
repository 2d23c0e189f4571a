"""Reference-neighbourhood scoring domain, object pieces and the height cut of initial regions."""

import numpy as np
import pytest

from lidar2city.contour import (
    ActiveContourConfig,
    aspect_coherence,
    building_regions,
    object_segments,
    reference_neighbourhood_domain,
)
from lidar2city.errors import ConfigError, InputError


def _two_blocks_with_neck():
    m = np.zeros((40, 60), bool)
    m[5:25, 5:25] = True
    m[5:25, 33:53] = True
    m[13:17, 25:33] = True  # a 4-pixel neck joins them
    return m


def test_object_segments_cuts_a_neck_into_two_pieces():
    seg = object_segments(_two_blocks_with_neck())
    assert seg.max() == 2
    assert seg[15, 10] != seg[15, 45]
    assert (seg > 0).sum() == _two_blocks_with_neck().sum()


def test_object_segments_keeps_tiny_blobs_and_empty_mask():
    m = np.zeros((10, 10), bool)
    m[2, 2] = True
    assert object_segments(m).max() == 1
    assert object_segments(np.zeros((5, 5), bool)).max() == 0


def test_reference_neighbourhood_domain_skips_unreferenced_objects():
    obj = _two_blocks_with_neck()
    obj[30:36, 5:11] = True  # a lone object far from the reference
    ref = np.zeros_like(obj)
    ref[6:24, 6:24] = True  # only the left block is referenced
    dom = reference_neighbourhood_domain(ref, obj, buffer=5, edge_margin=0)
    assert dom[ref].all()
    assert dom[15, 27]  # the neck belongs to the referenced piece: scored
    assert not dom[15, 35]  # the unreferenced right block: not scored
    assert not dom[32, 8]  # the lone object (within 6-8 px of nothing): not scored
    assert dom[3, 10] and not dom[3, 45]  # ground ring around the reference only
    assert not dom[15, 31 + 10]
    with pytest.raises(InputError):
        reference_neighbourhood_domain(np.zeros((5, 5), bool), np.zeros((5, 5), bool))
    with pytest.raises(InputError):
        reference_neighbourhood_domain(ref, obj[:-1])


def test_relative_height_drops_a_low_annex_of_a_building():
    nd = np.zeros((50, 50))
    nd[10:30, 10:30] = 10.0  # the building
    nd[10:30, 30:40] = 4.0  # a low annex / crown leaning on it, above min_height
    none = np.zeros(nd.shape, bool)  # no Canny cut: the height cut alone must separate them
    lab_cut = building_regions(nd, nd, cell=1.0, relative_height=0.5, max_roughness=99, edges=none)
    lab_all = building_regions(nd, nd, cell=1.0, relative_height=0.0, max_roughness=99, edges=none)
    assert (lab_cut > 0)[15:25, 33:40].sum() == 0
    assert (lab_cut > 0)[12:28, 12:28].all()
    assert (lab_all > 0)[15:25, 33:40].any()
    with pytest.raises(InputError):
        building_regions(nd, nd, relative_height=1.0)


def test_config_checks_the_new_fields():
    with pytest.raises(ConfigError):
        ActiveContourConfig(relative_height=1.5)
    with pytest.raises(ConfigError):
        ActiveContourConfig(split_distance=-1)


def _gable_and_crown():
    """A 16 x 30 px gable-roofed house and a round 8 m crown of radius 8 px, 2-m pixels."""
    z = np.zeros((60, 80))
    r, c = np.mgrid[0:60, 0:80]
    house = (r >= 10) & (r < 26) & (c >= 10) & (c < 40)
    z[house] = 6.0 + 2.0 * (1.0 - np.abs(r[house] - 17.5) / 8.0)  # ridge along the columns
    d = np.hypot(r - 40, c - 60)
    crown = d < 8
    z[crown] = 8.0 * np.sqrt(1.0 - (d[crown] / 8.0) ** 2) + 2.0
    return z, house, crown


def test_aspect_coherence_separates_a_gable_roof_from_a_round_crown():
    z, house, crown = _gable_and_crown()
    lab = house.astype(int) + 2 * crown
    coh = aspect_coherence(z, lab, cell=2.0)
    assert coh.shape == (2,)
    assert coh[0] > 0.5
    assert coh[1] < 0.1
    # rotating the scene by 90 degrees does not change it (four-fold)
    assert np.allclose(aspect_coherence(np.rot90(z), np.rot90(lab), cell=2.0), coh, atol=1e-9)
    assert aspect_coherence(z, np.zeros_like(lab)).shape == (0,)


def test_building_regions_drop_the_incoherent_crown():
    z, house, crown = _gable_and_crown()
    lab = building_regions(z, z, cell=2.0, max_roughness=99.0)
    assert (lab > 0)[house].mean() > 0.9 and not (lab > 0)[crown].any()
    kept = building_regions(z, z, cell=2.0, max_roughness=99.0, min_aspect_coherence=0.0)
    assert (kept > 0)[crown].mean() > 0.8


def test_initial_contours_from_roof_regions_or_edges():
    from lidar2city.contour import ActiveContourConfig, prepare_scene
    from lidar2city.errors import ConfigError

    dsm = np.zeros((60, 60))
    dsm[10:30, 10:40] = 8.0
    dsm[40:52, 20:50] = 5.0
    for init in ("roofs", "edges"):
        scene = prepare_scene(dsm, dsm, cell=1.0, config=ActiveContourConfig(init=init))
        assert len(scene.contours) == 2 and scene.cell == 1.0
    with pytest.raises(ConfigError, match="init"):
        ActiveContourConfig(init="blobs")
