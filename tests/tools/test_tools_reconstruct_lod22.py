"""reconstruct --lod 2.2 with both methods on a synthetic town written to files."""

import pytest

from lidar2city.io.cityjson import read_cityjson
from lidar2city.tools.reconstruct import reconstruct


@pytest.fixture(scope="module")
def town_files(tmp_path_factory, raw_town):
    d = tmp_path_factory.mktemp("town")
    town, _ = raw_town(d, size=(120.0, 90.0), density=6.0, seed=5)
    return town, d


@pytest.mark.parametrize("method", ["roof", "primitives"])
def test_lod22_from_a_raw_tile(town_files, tmp_path, method):
    town, d = town_files
    out = tmp_path / "m.city.json"
    s = reconstruct([d / "whole.laz"], out, footprints=d / "fp.gpkg", lods=("2.2",), method=method)
    assert s.done == s.total == len(town.buildings) and s.failed == 0 and s.invalid == 0
    model = read_cityjson(out)
    assert len(model.objects) == len(town.buildings)
    assert all(g["lod"] == "2.2" for o in model.objects.values() for g in o["geometry"])


def test_unknown_method(town_files, tmp_path):
    from lidar2city.errors import InputError

    _, d = town_files
    with pytest.raises(InputError, match="method"):
        reconstruct([d / "whole.laz"], tmp_path / "m.city.json", footprints=d / "fp.gpkg",
                     lods=("2.2",), method="magic")


def test_cli_primitives_with_check_images(town_files, tmp_path):
    from click.testing import CliRunner

    from lidar2city.cli.main import cli

    town, d = town_files
    out, imgs = tmp_path / "p.city.json", tmp_path / "imgs"
    res = CliRunner().invoke(cli, ["reconstruct", str(d / "whole.laz"), "--footprints", str(d / "fp.gpkg"),
                                   "--lod", "2.2", "--method", "primitives", "--check-images", str(imgs),
                                   "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    assert len(list(imgs.glob("*.png"))) == len(town.buildings)
    res = CliRunner().invoke(cli, ["reconstruct", str(d / "whole.laz"), "--footprints", str(d / "fp.gpkg"),
                                   "--check-images", str(imgs), "-o", str(out), "-q"])
    assert res.exit_code == 1 and "--method primitives" in res.output


def test_without_footprints_they_come_from_the_points(town_files, tmp_path):
    town, d = town_files
    out = tmp_path / "nofp.city.json"
    s = reconstruct([d / "whole.laz"], out, lods=("1.2", "2.2"))
    assert s.failed == 0 and s.invalid == 0
    # one model per building (the synthetic buildings stand apart)
    assert s.total == len(town.buildings)
