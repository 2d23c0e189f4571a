import numpy as np
import pytest

from lidar2city.errors import FileFormatError
from lidar2city.io.ply import read_ply


def test_ascii_and_binary_agree(tmp_path):
    pts = np.array([[1.5, 2.0, 3.0], [4.0, 5.5, 6.25], [7.0, 8.0, 9.5]])
    header = "ply\nformat {}\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    (tmp_path / "a.ply").write_text(header.format("ascii 1.0") + "\n".join(" ".join(map(str, p)) for p in pts))
    with open(tmp_path / "b.ply", "wb") as f:
        f.write(header.format("binary_little_endian 1.0").encode())
        f.write(pts.astype("<f4").tobytes())
    a, b = read_ply(tmp_path / "a.ply"), read_ply(tmp_path / "b.ply")
    assert np.allclose(a.to_world(a.xyz), pts) and np.allclose(b.to_world(b.xyz), pts)


def test_not_a_ply(tmp_path):
    (tmp_path / "x.ply").write_text("hello")
    with pytest.raises(FileFormatError, match="not a PLY"):
        read_ply(tmp_path / "x.ply")


def test_city3d_instance(data):
    pc = read_ply(data / "city3d" / "building_instances" / "1.ply")
    assert len(pc) == 584 and "red" in pc.attributes
