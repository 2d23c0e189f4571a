"""The writability probe of an output folder is never left behind by an interrupt."""

import os
import signal

import pytest

from lidar2city.errors import FileFormatError
from lidar2city.io import _atomic
from lidar2city.io._atomic import check_output_path


def test_interrupt_during_the_probe_leaves_nothing(tmp_path, monkeypatch):
    # SIGINT arrives while the probe exists (sent from inside its creation); the
    # handler does what the CLI's does (remove what is being written; it then exits)
    seen = []

    def handler(signum, frame):
        _atomic.remove_run_outputs()
        seen.append(sorted(p.name for p in tmp_path.iterdir()))

    real_close = os.close

    def close_and_interrupt(fd):
        os.kill(os.getpid(), signal.SIGINT)
        real_close(fd)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        monkeypatch.setattr(_atomic.os, "close", close_and_interrupt)
        check_output_path(tmp_path / "x.laz")
        monkeypatch.undo()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert seen == [[]]
    assert list(tmp_path.iterdir()) == []
    assert not _atomic._PENDING


def test_probe_in_a_read_only_folder_is_a_one_line_error(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):  # root ignores the mode
            pytest.skip("this user can write to a read-only folder")
        with pytest.raises(FileFormatError, match="cannot write to"):
            check_output_path(ro / "x.laz")
    finally:
        ro.chmod(0o700)
    assert not _atomic._PENDING
