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
    """``--workers auto``, the default, on an input too small to gain from workers
    starts no cluster (no Dask executor is made where the system does not fork or
    ``LIDAR2CITY_LOCAL_EXECUTOR=dask``) and forks none, and writes the bytes of
    ``--workers 1``; a word other than a whole number >= 1 or ``auto`` is a usage error
    naming the option."""
    from lidar2city.tools import engine, forked

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(engine.DaskExecutor, "__init__", no_cluster)
    monkeypatch.setattr(forked.ForkExecutor, "__init__", no_cluster)
    one, auto, dask = (tmp_path / f"{n}.city.json" for n in ("w1", "auto", "dask"))
    for out, opts in ((one, ["--workers", "1"]), (auto, ["--workers", "auto"]), (dask, [])):
        if out == dask:
            monkeypatch.setenv(engine.LOCAL_EXECUTOR_ENV, "dask")
        r = runner.invoke(cli, ["reconstruct", str(tile), "--block-size", "60", *opts,
                                "-o", str(out)])
        assert r.exit_code == 0, r.output
    assert auto.read_bytes() == one.read_bytes() == dask.read_bytes()
    for bad in ("many", "0", "-2", "1.5"):
        r = runner.invoke(cli, ["reconstruct", str(tile), "--workers", bad, "-o",
                                str(tmp_path / "x.city.json")])
        assert r.exit_code == 2 and "--workers" in r.output, (bad, r.output)


def test_workers_defaults_to_auto_and_the_help_says_so(runner):
    r = runner.invoke(cli, ["reconstruct", "--help"])
    assert r.exit_code == 0
    text = " ".join(r.output.split())
    assert "--workers N|AUTO" in text and "[default: auto]" in text
    assert "1 runs the tasks in this process" in text


def test_in_another_program_the_default_runs_here_and_explicit_auto_forks_when_safe(
        runner, tile, tmp_path, monkeypatch, caplog):
    """The command run inside another program (click's runner inside pytest, a script
    calling ``cli()`` around its own timers): its default (``--workers auto``) runs in
    this process even for an input worth 2 workers; an explicit ``--workers auto``
    forks them when no other Python thread is alive, else runs here and says why; the
    bytes are those of ``--workers 1`` every time."""
    import logging
    import threading

    from lidar2city.tools import engine
    from lidar2city.tools import reconstruct as R

    if engine.local_executor() != "fork":
        pytest.skip("this platform does not fork")
    made, make = [], engine.make_executor

    def recorded(workers, *a, **k):
        made.append(workers)
        return make(workers, *a, **k)

    monkeypatch.setattr(engine, "make_executor", recorded)

    def run(name, *opts):
        out = tmp_path / name
        r = runner.invoke(cli, ["reconstruct", str(tile), "--block-size", "60", *opts,
                                "-o", str(out)])
        assert r.exit_code == 0, r.output
        return out.read_bytes()

    one = run("w1.city.json", "--workers", "1")
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS", {"fork": 1e-6, "dask": 1e-6})
    monkeypatch.setattr(R, "usable_cores", lambda: 2)
    caplog.set_level(logging.INFO, logger="lidar2city")
    assert run("default.city.json") == one and made == [1, 1]
    assert "inside another program" in caplog.text
    hazard = R.fork_hazard()  # threads earlier tests may have left in this process
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="a-test-runners", daemon=True)
    if hazard is None and R.observer() is None:
        assert run("auto.city.json", "--workers", "auto") == one and made[-1] == 2
        other.start()  # now one: no fork
    try:
        assert run("thread.city.json", "--workers", "auto") == one and made[-1] == 1
    finally:
        stop.set()
        if other.is_alive():
            other.join()
    assert "no fork" in caplog.text or R.observer() is not None


def _lowered(*args):
    """A ``lidar2city`` command line in a process of its own whose ``auto`` takes 2
    workers for any input (the threshold lowered, 2 usable cores)."""
    code = ("import sys; import lidar2city.tools.reconstruct as R; "
            "R.AUTO_LEAST_SECONDS.update(fork=1e-6, dask=1e-6); R.usable_cores = lambda: 2; "
            "from lidar2city.cli.main import main; sys.exit(main())")
    return [sys.executable, "-c", code, *map(str, args)]


@pytest.mark.slow
def test_default_run_forking_in_its_own_process_prints_each_line_once(runner, tile, tmp_path):
    """The command as a user types it, its output piped: the forked worker writes
    nothing of the parent's again, the run logs its choice once, and the bytes are
    those of ``--workers 1``."""
    from lidar2city.tools import engine

    if engine.local_executor() != "fork":
        pytest.skip("this platform does not fork")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    one, out = tmp_path / "one.city.json", tmp_path / "default.city.json"
    r = runner.invoke(cli, ["reconstruct", str(tile), "--block-size", "60", "--workers", "1",
                            "-o", str(one)])
    assert r.exit_code == 0, r.output
    r = subprocess.run(_lowered("-v", "reconstruct", tile, "--block-size", "60", "-o", out),
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr and r.stdout == "", (r.stdout, r.stderr)
    assert out.read_bytes() == one.read_bytes()
    err = r.stderr
    assert "forked process(es)" in err  # it did fork
    # what the process wrote before and after the fork, once
    assert err.count("--workers auto: 2 ") == 1, err
    assert err.count("no footprints given") == 1, err
    assert err.count("buildings reconstructed") == 1, err
