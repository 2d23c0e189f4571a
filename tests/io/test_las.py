import numpy as np
import pytest

from lidar2city.errors import CRSError, FileFormatError
from lidar2city.io.las import read_las, read_points, write_las


def test_missing_file(tmp_path):
    with pytest.raises(FileFormatError, match="no such file"):
        read_las(tmp_path / "nope.laz")


def test_not_a_las(tmp_path):
    p = tmp_path / "x.las"
    p.write_text("hello")
    with pytest.raises(FileFormatError, match="not a readable LAS"):
        read_las(p)


def test_feet_crs_read_in_metres(data):
    pc = read_points(data / "misc" / "autzen_trim.laz")
    assert pc.crs is not None
    assert pc.xy_unit == pytest.approx(0.3048)
    # ~1177 ft wide tile -> ~359 m
    width = np.ptp(pc.xyz[:, 0])
    assert 350 < width < 370


def test_crs_override_and_required(data):
    f = data / "delft" / "ahn3_cropped_1.laz"
    with pytest.raises(CRSError, match="--crs"):
        read_points(f, require_crs=True)
    pc = read_points(f, crs="EPSG:7415")
    assert pc.crs.is_compound and pc.xy_unit == 1.0


def test_write_keeps_attributes_and_is_atomic(data, tmp_path):
    tile = read_las(data / "misc" / "simple.laz")
    n = len(tile.data.points)
    out = tmp_path / "out.laz"
    write_las(out, tile, classification=np.full(n, 2))
    back = read_las(out)
    assert len(back.data.points) == n
    assert np.all(np.asarray(back.data.classification) == 2)
    assert np.allclose(back.data.x, tile.data.x)
    assert [p.name for p in tmp_path.iterdir()] == ["out.laz"]


def test_unknown_crs():
    from lidar2city.crs import parse_crs

    with pytest.raises(CRSError, match="unknown CRS"):
        parse_crs("EPSG:999999999")
