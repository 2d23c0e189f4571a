"""`lidar2city reconstruct` in a terminal, --workers / --scheduler / --resume options."""

import os
import shlex
import shutil
import subprocess
import sys

import pytest

from lidar2city.cli.main import cli
from lidar2city.io.las import write_points
from lidar2city.synthetic import make_town


@pytest.fixture(scope="module")
def tile(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli_engine")
    town = make_town(size=(120.0, 90.0), density=3.0, seed=2, n_trees=3)
    write_points(d / "town.laz", town.cloud)
    return d / "town.laz"


@pytest.mark.skipif(shutil.which("script") is None, reason="needs util-linux `script` (a pty)")
def test_reconstruct_without_footprints_in_a_terminal_shows_a_bar_and_does_not_crash(tile,
                                                                                     tmp_path):
    # issue 17 item 1: the bar was given length=None (footprints traced) -> TypeError
    out = tmp_path / "t.city.json"
    cmd = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "lidar2city.cli.main",
                                            "reconstruct", str(tile), "--block-size", "60",
                                            "-o", str(out)])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path), "COLUMNS": "100"}
    r = subprocess.run(["script", "-qec", cmd, "/dev/null"], capture_output=True, text=True,
                       env=env, timeout=300)
    assert r.returncode == 0, r.stdout
    assert "Traceback" not in r.stdout and "buildings reconstructed" in r.stdout
    assert "blocks" in r.stdout  # the bar counts blocks when footprints are traced
    assert out.exists()


def test_workers_and_scheduler_together_and_with_dsm_are_one_line_errors(runner, tile, tmp_path):
    out = str(tmp_path / "x.city.json")
    r = runner.invoke(cli, ["reconstruct", str(tile), "--workers", "2", "--scheduler",
                            "tcp://127.0.0.1:1", "-o", out])
    assert r.exit_code == 1 and r.output.strip().count("\n") == 0 and "not both" in r.output
    r = runner.invoke(cli, ["reconstruct", "--dsm", str(tile), "--resume", "-o", out])
    assert r.exit_code == 1 and "apply to point clouds" in r.output
    r = runner.invoke(cli, ["reconstruct", str(tile), "--workers", "0", "-o", out])
    assert r.exit_code == 2 and "--workers" in r.output


@pytest.mark.slow
def test_two_workers_quiet_print_no_cluster_log_or_traceback(tile, tmp_path):
    # distributed logs at INFO on its own handlers (and a CommClosedError traceback when
    # the client closes): -q must leave only our summary
    out = tmp_path / "w.city.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    r = subprocess.run([sys.executable, "-m", "lidar2city.cli.main", "-q", "reconstruct",
                        str(tile), "--block-size", "60", "--workers", "2", "-o", str(out)],
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and "distributed" not in r.stderr, r.stderr
    assert out.exists()


def test_workers_auto_runs_a_small_input_in_this_process_with_the_same_bytes(runner, tile,
                                                                             tmp_path,
                                                                             monkeypatch):
    """``--workers auto`` on an input too small to gain from a cluster starts none (no
    Dask executor is made) and writes the bytes of ``--workers 1``; a word other than
    a whole number >= 1 or ``auto`` is a usage error naming the option."""
    from lidar2city.tools import engine

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(engine.DaskExecutor, "__init__", no_cluster)
    one, auto = tmp_path / "w1.city.json", tmp_path / "auto.city.json"
    for out, w in ((one, "1"), (auto, "auto")):
        r = runner.invoke(cli, ["reconstruct", str(tile), "--block-size", "60", "--workers", w,
                                "-o", str(out)])
        assert r.exit_code == 0, r.output
    assert auto.read_bytes() == one.read_bytes()
    for bad in ("many", "0", "-2", "1.5"):
        r = runner.invoke(cli, ["reconstruct", str(tile), "--workers", bad, "-o",
                                str(tmp_path / "x.city.json")])
        assert r.exit_code == 2 and "--workers" in r.output, (bad, r.output)
