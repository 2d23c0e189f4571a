"""Scratch files of a run killed outright (kill -9) are removed by a later run, never
those of a live run."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile

from lidar2city.io._atomic import new_scratch_file, remove_stale_scratch


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_dead_runs_scratch_file_is_removed_and_a_live_ones_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    host = socket.gethostname()
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        names = {
            "dead": f"lidar2city-tile-{host}-{_dead_pid()}-abc123.npz",
            "live": f"lidar2city-tile-{host}-{live.pid}-def456.npz",
            "other host": f"lidar2city-tile-{host}x-{_dead_pid()}-ghi789.npz",
            "unnamed run": "lidar2city-tile-_lghl9b4.npz",  # older runs: no pid to test
            "not ours": f"other-{host}-{_dead_pid()}-x.npz",
        }
        for n in names.values():
            (tmp_path / n).write_bytes(b"x")
        removed = remove_stale_scratch("lidar2city-tile-", ".npz")
        assert [os.path.basename(p) for p in removed] == [names["dead"]]
        left = {p.name for p in tmp_path.iterdir()}
        assert left == set(names.values()) - {names["dead"]}
        # a new scratch file is named by this host and process, and cleans first
        (tmp_path / names["dead"]).write_bytes(b"x")
        path = new_scratch_file("lidar2city-tile-", ".npz")
        assert os.path.basename(path).startswith(f"lidar2city-tile-{host}-{os.getpid()}-")
        assert not (tmp_path / names["dead"]).exists() and os.path.exists(path)
        assert remove_stale_scratch("lidar2city-tile-", ".npz") == []  # ours: alive
    finally:
        live.kill()
        live.wait()
