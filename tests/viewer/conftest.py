"""A viewer on a copy of the synthetic town's model, on a free loopback port."""

import shutil
import socket

import pytest

pytest.importorskip("viser", reason="the viewer needs viser (pip install lidar2city[view])")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def port():
    """A free loopback port."""
    return free_port()


@pytest.fixture
def viewer(edit_town, tmp_path):
    from lidar2city.viewer.app import Viewer

    model = tmp_path / "m.city.json"
    shutil.copy(edit_town.model, model)
    v = Viewer(model, points=[edit_town.laz], footprints=edit_town.footprints,
               port=free_port(), max_points=20_000)
    v.start(compute_rmse=False)
    v._compute_all_rmse()
    yield v
    v.stop()
