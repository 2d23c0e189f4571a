import json


def test_info_delft(runner, data):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["info", str(data / "delft" / "ahn3_cropped_1.laz"),
                              "--crs", "EPSG:7415", "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    assert info["points"] == 640510
    assert info["classes"][str(6)] == 246753 or info["classes"][6] == 246753
    assert 8 < info["density_pts_m2"] < 30


def test_info_missing_file_one_line_error(runner, tmp_path):
    from lidar2city.cli.main import cli

    res = runner.invoke(cli, ["info", str(tmp_path / "none.laz")])
    assert res.exit_code == 1
    assert res.output.strip().startswith("Error:")
    assert len(res.output.strip().splitlines()) == 1
