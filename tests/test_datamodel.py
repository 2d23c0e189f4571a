import numpy as np
import pytest

from lidar2city.datamodel import PointCloud
from lidar2city.errors import InputError


def test_local_world_round_trip_in_feet():
    world = np.array([[1000.5, 2000.25, 30.0], [1010.0, 2005.0, 40.0]])
    pc = PointCloud.from_world(world, xy_unit=0.3048, z_unit=0.3048)
    assert np.allclose(pc.origin, [1000.0, 2000.0, 0.0])
    # local coordinates are metres
    assert np.isclose(pc.xyz[1, 0] - pc.xyz[0, 0], 9.5 * 0.3048)
    assert np.allclose(pc.to_world(pc.xyz), world)


def test_nan_points_rejected():
    with pytest.raises(InputError, match="NaN"):
        PointCloud(np.array([[0.0, np.nan, 1.0]]))


def test_attribute_length_checked():
    with pytest.raises(InputError, match="classification"):
        PointCloud(np.zeros((3, 3)), attributes={"classification": np.zeros(2)})


def test_subset_keeps_frame():
    pc = PointCloud(np.arange(12.0).reshape(4, 3), origin=[5, 6, 0],
                    attributes={"classification": np.array([1, 2, 2, 1])})
    sub = pc.subset(pc.get("classification") == 2)
    assert len(sub) == 2 and np.allclose(sub.origin, [5, 6, 0])
