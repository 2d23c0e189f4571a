"""`ground` and `classify` on a folder (or glob) of tiles: one task per tile, neighbours found."""

import hashlib

import numpy as np
import pytest

from lidar2city.cli.main import cli
from lidar2city.io.las import read_las, write_points
from lidar2city.synthetic import make_town


def _md5(p):
    return hashlib.md5(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def tiles(tmp_path_factory):
    """A raw synthetic town cut into 2 x 2 tiles in a folder."""
    d = tmp_path_factory.mktemp("tiles") / "in"
    d.mkdir()
    town = make_town(size=(80.0, 60.0), density=3.0, seed=4, n_trees=3)
    raw = town.cloud.with_attributes(classification=np.ones(len(town.cloud), np.uint8))
    x = raw.xyz[:, 0] < 40.0
    y = raw.xyz[:, 1] < 30.0
    for name, m in {"a": x & y, "b": ~x & y, "c": x & ~y, "d": ~x & ~y}.items():
        write_points(d / f"{name}.laz", raw.subset(m))
    return d


def test_ground_on_a_folder_equals_each_tile_with_its_neighbours(runner, tiles, tmp_path):
    out = tmp_path / "out"
    r = runner.invoke(cli, ["ground", str(tiles), "-o", str(out), "--dtm", str(tmp_path / "dtm")])
    assert r.exit_code == 0, r.output
    assert "4 of 4 tiles done, 0 failed" in r.output
    assert sorted(p.name for p in out.iterdir()) == ["a.laz", "b.laz", "c.laz", "d.laz"]
    assert sorted(p.name for p in (tmp_path / "dtm").iterdir()) == ["a.tif", "b.tif", "c.tif",
                                                                    "d.tif"]
    # the same as one tile given its three neighbours by hand
    one = tmp_path / "a.laz"
    r = runner.invoke(cli, ["ground", str(tiles / "a.laz"), "-o", str(one)]
                      + [a for n in "bcd" for a in ("--neighbour", str(tiles / f"{n}.laz"))])
    assert r.exit_code == 0, r.output
    assert np.array_equal(read_las(one).data.classification,
                          read_las(out / "a.laz").data.classification)


@pytest.mark.slow
def test_classify_on_a_glob_with_two_workers_gives_the_same_bytes(runner, tiles, tmp_path):
    pytest.importorskip("distributed")
    outs = []
    for w in ("1", "2"):
        out = tmp_path / f"w{w}"
        r = runner.invoke(cli, ["classify", str(tiles / "*.laz"), "-o", str(out), "--workers", w])
        assert r.exit_code == 0, r.output
        outs.append(out)
    assert {p.name: _md5(p) for p in outs[0].iterdir()} == \
        {p.name: _md5(p) for p in outs[1].iterdir()}
    assert (6 == read_las(outs[0] / "a.laz").data.classification).any()


def test_tiles_with_different_crss_and_neighbour_options_are_one_line_errors(runner, tiles,
                                                                            tmp_path):
    d = tmp_path / "mixed"
    d.mkdir()
    a = read_las(tiles / "a.laz").point_cloud()
    write_points(d / "a.laz", a)
    write_points(d / "z.laz", a.__class__(a.xyz, a.origin, None, a.xy_unit, a.z_unit,
                                          a.attributes))
    r = runner.invoke(cli, ["ground", str(d), "-o", str(tmp_path / "o")])
    assert r.exit_code == 1 and "different CRSs" in r.output and r.output.count("\n") == 1
    r = runner.invoke(cli, ["ground", str(tiles), "-o", str(tmp_path / "o"), "--neighbour",
                            str(tiles / "a.laz")])
    assert r.exit_code == 1 and "drop --neighbour" in r.output
    r = runner.invoke(cli, ["ground", str(tiles / "nothing*.laz"), "-o", str(tmp_path / "o")])
    assert r.exit_code == 1 and "no tile matches" in r.output


def test_footprints_on_a_folder_of_raw_tiles_trace_each_building_once(runner, tiles, tmp_path):
    """The folder is traced block by block (raw points classified in each block's box);
    a building across the tiles is one footprint, as from the whole area at once."""
    from lidar2city.io.vector import read_footprints

    out = tmp_path / "fp.gpkg"
    r = runner.invoke(cli, ["footprints", str(tiles), "-o", str(out), "--block-size", "50"])
    assert r.exit_code == 0, r.output
    fps, _ = read_footprints(out)
    assert len(fps) >= 1 and f"{len(fps)} footprints" in r.output
    whole = tmp_path / "whole.gpkg"
    r = runner.invoke(cli, ["footprints", *sorted(str(p) for p in tiles.iterdir()), "-o",
                            str(whole)])
    assert r.exit_code == 0, r.output
    assert len(read_footprints(whole)[0]) == len(fps)
    r = runner.invoke(cli, ["footprints", str(tiles / "a.laz"), "-o", str(tmp_path / "x.gpkg"),
                            "--workers", "2"])
    assert r.exit_code == 1 and "folder or glob of tiles" in r.output
    assert r.output.count("\n") == 1
