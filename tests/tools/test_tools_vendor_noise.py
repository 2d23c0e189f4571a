"""A raw tile's vendor noise labels (7, 18) are kept when the tile is classified."""

import numpy as np
import pytest

from lidar2city.errors import EmptyInputError
from lidar2city.synthetic import make_town
from lidar2city.tools.classify import classify_cloud


@pytest.fixture(scope="module")
def raw():
    town = make_town(size=(80, 60), density=4, seed=1)
    cloud = town.cloud
    cloud.attributes["classification"] = np.ones(len(cloud), dtype=np.uint8)  # raw: unclassified
    return cloud


def test_vendor_noise_is_kept_and_the_rest_classified(raw):
    cls_in = np.array(raw.attributes["classification"], copy=True)
    cls_in[:50], cls_in[50:80] = 7, 18  # the vendor's low and high noise
    cloud = raw.subset(np.ones(len(raw), dtype=bool))
    cloud.attributes["classification"] = cls_in
    out = classify_cloud(cloud)
    assert np.array_equal(out[:50], np.full(50, 7)) and np.array_equal(out[50:80], np.full(30, 18))
    # the others are classified as if the noise were not there
    alone = classify_cloud(raw.subset(np.arange(len(raw)) >= 80))
    assert np.array_equal(out[80:], alone)


def test_a_tile_of_noise_only_is_a_one_line_error(raw):
    cloud = raw.subset(np.ones(len(raw), dtype=bool))
    cloud.attributes["classification"] = np.full(len(cloud), 7, dtype=np.uint8)
    with pytest.raises(EmptyInputError, match="every point is classified noise"):
        classify_cloud(cloud)
