"""ground / classify a tile with a strip of its neighbours: the same classes as the whole area."""

import laspy
import numpy as np
import pytest

from lidar2city.errors import CRSError, InputError
from lidar2city.io.las import read_las, with_neighbours, write_points


@pytest.fixture(scope="module")
def halves(tmp_path_factory, raw_town):
    d = tmp_path_factory.mktemp("halves")
    _, raw = raw_town(d, size=(140.0, 80.0), density=5.0, seed=21)
    world_x = raw.to_world(raw.xyz)[:, 0]
    cut = raw.origin[0] + 70.0
    write_points(d / "west.laz", raw.subset(world_x < cut))
    write_points(d / "east.laz", raw.subset(world_x >= cut))
    return d


def _classes(path):
    las = laspy.read(path)
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    return xyz, np.asarray(las.classification)


def test_with_neighbours_adds_only_the_strip(halves):
    west = read_las(halves / "west.laz").point_cloud()
    wide = with_neighbours(west, [halves / "east.laz", halves / "west.laz"], buffer=20.0)
    assert np.array_equal(wide.xyz[:len(west)], west.xyz)
    extra = wide.to_world(wide.xyz[len(west):])
    own_max = west.to_world(west.xyz).max(axis=0)
    # only the neighbour's points within 20 m, none of the tile's own taken twice
    assert len(extra) > 0
    assert (extra[:, 0] > own_max[0]).all() and (extra[:, 0] <= own_max[0] + 20.0).all()
    assert set(wide.attributes) == set(west.attributes)
    assert with_neighbours(west, []) is west
    with pytest.raises(InputError, match="buffer"):
        with_neighbours(west, [halves / "east.laz"], buffer=-1.0)
    # a strip that reaches no neighbour point, or an empty neighbour: the tile as it is
    far = west.subset(west.xyz[:, 0] < 20.0)
    assert with_neighbours(far, [halves / "east.laz"], buffer=5.0) is far
    empty = halves / "empty.laz"
    write_points(empty, west.subset(np.zeros(len(west), bool)))
    assert with_neighbours(west, [empty]) is west


def test_with_neighbours_checks_the_crs(halves, tmp_path):
    west = read_las(halves / "west.laz").point_cloud()
    east = read_las(halves / "east.laz", crs="EPSG:3857").point_cloud()
    write_points(tmp_path / "other.laz", east)
    with pytest.raises(CRSError, match="different CRSs"):
        with_neighbours(west, [tmp_path / "other.laz"])
    # a tile without CRS cannot take neighbours with one (their units are unknown to it)
    bare = west.__class__(west.xyz, west.origin, None, 1.0, 1.0, west.attributes)
    with pytest.raises(CRSError, match="pass --crs"):
        with_neighbours(bare, [halves / "east.laz"])


@pytest.mark.parametrize("command", ["ground", "classify"])
def test_tile_with_neighbour_matches_the_whole_area(halves, tmp_path, runner, command):
    from lidar2city.cli.main import cli

    whole = tmp_path / "whole.laz"
    res = runner.invoke(cli, [command, str(halves / "whole.laz"), "-o", str(whole)])
    assert res.exit_code == 0, res.output
    wxyz, wc = _classes(whole)
    for tile, other in (("west", "east"), ("east", "west")):
        out = tmp_path / f"{tile}.laz"
        res = runner.invoke(cli, [command, str(halves / f"{tile}.laz"), "--neighbour",
                                  str(halves / f"{other}.laz"), "-o", str(out)])
        assert res.exit_code == 0, res.output
        xyz, c = _classes(out)
        # the same points, in the input's order, with the whole run's classes
        key = {tuple(p): k for p, k in zip(np.round(wxyz, 3).tolist(), wc, strict=True)}
        ref = np.array([key[tuple(p)] for p in np.round(xyz, 3).tolist()])
        assert len(xyz) == len(_classes(halves / f"{tile}.laz")[0])
        if command == "ground":
            assert (c == ref).all()
        else:
            # thresholds follow the point spacing measured on the cloud at hand,
            # so a handful of points away from the seam may differ
            assert (c == ref).mean() > 0.999


def test_neighbour_option_errors(halves, tmp_path, runner):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["ground", str(halves / "west.laz"), "--neighbour",
                              str(tmp_path / "missing.laz"), "-o", str(tmp_path / "o.laz")])
    assert res.exit_code != 0 and "missing.laz" in res.output
    assert not (tmp_path / "o.laz").exists()
