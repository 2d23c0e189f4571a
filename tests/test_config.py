import pytest

from lidar2city.config import load_config, read_config, stage_config
from lidar2city.errors import ConfigError, FileFormatError


def test_tune_record_is_not_a_stage(tmp_path):
    p = tmp_path / "w.toml"
    p.write_text("[active_contour]\nalpha = 0.5\n\n[tune]\nseed = 3\n")
    assert "tune" not in read_config(p)
    assert stage_config("active_contour", p).alpha == 0.5


def test_errors_name_stage_and_field(tmp_path):
    with pytest.raises(ConfigError, match="lod22.dist_tol"):
        load_config({"lod22": {"dist_tol": -1.0}})
    with pytest.raises(ConfigError, match="unknown config section"):
        stage_config("ground", {"grund": {}})
    with pytest.raises(FileFormatError, match="no such config file"):
        read_config(tmp_path / "missing.toml")


def test_a_scalar_where_a_list_is_expected_names_the_field():
    """``building_classes = 6`` (for ``[6]``) said `lod1: 'int' object is not iterable`."""
    with pytest.raises(ConfigError, match=r"lod1\.building_classes: expected a list, got 6"):
        load_config({"lod1": {"building_classes": 6}})
    assert stage_config("lod1", {"lod1": {"building_classes": [6, 26]}}).building_classes == (6, 26)
