"""LoD2.2 of real single-building clouds (City3D, AHN3-derived): no footprint, no ground."""

import numpy as np
import pytest
import shapely

from lidar2city.footprints import extract_footprints
from lidar2city.io.ply import read_ply
from lidar2city.metrics.model import model_rmse
from lidar2city.roof.building import reconstruct_lod22
from lidar2city.validate.solid import check_solid


@pytest.mark.slow
@pytest.mark.parametrize("name", ["0", "1", "5", "12", "23", "37", pytest.param("48", marks=pytest.mark.xfail(
    strict=True, reason="known regression of the line-arrangement roof partition (issue 12): a 1 m2 "
    "facet beside clutter is lost, RMSE 0.67 m (label-grid partition: 0.55 m; with [lod22] "
    "raised_parts the clutter comes in as a level rectangle: 0.56 m)")), "59"])
def test_city3d_building_valid_and_close(data, name):
    pc = read_ply(data / "city3d" / "building_instances" / f"{name}.ply")
    # the footprint is derived from the points themselves (all are building points)
    fps = extract_footprints(pc.xyz, np.full(len(pc), 6), regularize="snake")
    fp = shapely.union_all([f.polygon for f in fps])
    # no ground points: the floor is put at the lowest point of the cloud
    floor = float(pc.xyz[:, 2].min())
    res = reconstruct_lod22(fp, pc.xyz, floor)
    assert all(not check_solid(s) for s in res.solids)
    inside = shapely.contains_xy(fp, pc.xyz[:, 0], pc.xyz[:, 1])
    # measured: median 0.23 m over the 60 instances (most have walls and clutter)
    assert model_rmse(pc.xyz[inside], res.solids) < 0.6
