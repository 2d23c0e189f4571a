"""The writability probe of an output folder is never left behind by an interrupt."""

import os
import signal

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

