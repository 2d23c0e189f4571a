import tomllib

import pytest

from lidar2city.config import build_stage
from lidar2city.contour.outlines import ActiveContourConfig
from lidar2city.errors import ConfigError, FileFormatError
from lidar2city.io.weights import read_weights, write_weights


def test_round_trip_and_valid_run_config(tmp_path):
    w = {"alpha": 0.125, "beta": 2.0, "gamma": 1.5, "mu": 0.0, "epsilon": 3.0}
    p = tmp_path / "w.toml"
    write_weights(p, w, metadata={"cost": 0.1, "seed": 4, "dsm": 'a "quoted" path'})
    assert read_weights(p) == w
    data = tomllib.loads(p.read_text())
    assert data["tune"]["seed"] == 4 and data["tune"]["dsm"] == 'a "quoted" path'
    # the [active_contour] table is a valid stage config
    cfg = build_stage("active_contour", data["active_contour"], cls=ActiveContourConfig)
    assert cfg.beta == 2.0
    assert not list(tmp_path.glob(".*tmp*"))


def test_top_level_weights_accepted(tmp_path):
    p = tmp_path / "w.toml"
    p.write_text("alpha = 1\nmu = 0.5\n")
    assert read_weights(p) == {"alpha": 1.0, "mu": 0.5}


@pytest.mark.parametrize("text", ["alpha = -1\n", "alpha = 'x'\n", "[active_contour]\nalpha = [\n",
                                  "other = 1\n"])
def test_bad_weights_files(tmp_path, text):
    p = tmp_path / "w.toml"
    p.write_text(text)
    with pytest.raises(ConfigError):
        read_weights(p)


def test_missing_file(tmp_path):
    with pytest.raises(FileFormatError):
        read_weights(tmp_path / "none.toml")
    with pytest.raises(ConfigError):
        write_weights(tmp_path / "w.toml", {"delta": 1.0})
