"""reconstruct on executors: same bytes on 1 / 2 workers and an external Dask cluster,
resume from the journal, failing blocks and dead workers."""

import inspect
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections import Counter

import numpy as np
import pytest

from lidar2city.errors import InputError
from lidar2city.io.journal import journal_path
from lidar2city.io.las import write_points
from lidar2city.io.vector import write_polygons
from lidar2city.synthetic import make_town
from lidar2city.tools import engine, task
from lidar2city.tools.engine import DaskExecutor
from lidar2city.tools.reconstruct import reconstruct

BLOCK = 50.0

# dask.distributed leaves sockets to the garbage collector when clients and clusters close
pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning",
                                        "ignore::pytest.PytestUnraisableExceptionWarning")


class Crash(BaseException):
    """A crash of the whole run (not a task failure the executor would retry)."""


@pytest.fixture(scope="module")
def area(tmp_path_factory):
    d = tmp_path_factory.mktemp("engine")
    town = make_town(size=(160.0, 120.0), density=3.0, seed=5, n_trees=5)
    write_points(d / "town.laz", town.cloud)
    write_polygons(d / "fp.gpkg", town.footprints.geometries, {"id": town.footprints.ids},
                   origin=town.cloud.origin, crs=town.cloud.crs)
    return d


def _run(area, out, **kw):
    kw.setdefault("block_size", BLOCK)
    return reconstruct([area / "town.laz"], out, footprints=area / "fp.gpkg", lods=("1.2", "1.3"),
                       **kw)


@pytest.fixture(scope="module")
def reference(area, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "ref.city.json"
    summary = _run(area, out)
    assert summary.blocks >= 3 and summary.done >= 5 and summary.failed == 0
    assert not journal_path(out).exists()  # removed once the output is written
    return out.read_bytes(), summary


def test_two_workers_give_the_same_bytes(area, reference, tmp_path):
    out = tmp_path / "w2.city.json"
    summary = _run(area, out, workers=2)
    assert out.read_bytes() == reference[0]
    assert summary.done == reference[1].done


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def dask_cluster():
    """A scheduler and one worker started with the standard `dask` commands (loopback)."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler",
                               "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              **quiet)]
    procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address,
                                   "--nworkers", "1", "--nthreads", "1", "--host", "127.0.0.1",
                                   "--no-dashboard"], **quiet))
    from distributed import Client

    with Client(address, timeout="60s", set_as_default=False) as c:
        c.wait_for_workers(1, timeout=60)
    yield address
    for p in procs[::-1]:
        p.terminate()
        p.wait(timeout=30)


def test_an_external_scheduler_gives_the_same_bytes(area, reference, dask_cluster, tmp_path):
    out = tmp_path / "ext.city.json"
    _run(area, out, scheduler=dask_cluster)
    assert out.read_bytes() == reference[0]


def _crash_on_third(real, ran):
    """``real`` (a block task) noting the blocks it ran in ``ran``; the third crashes the run."""
    def task_fn(spec, options):
        if len(ran) == 2:
            raise Crash
        ran.append(spec.index)
        return real(spec, options)

    return task_fn


def test_resume_after_a_crash_gives_the_same_bytes_and_reruns_only_what_is_missing(
        area, reference, tmp_path, monkeypatch):
    real, ran = task.run_block, []
    out = tmp_path / "r.city.json"
    monkeypatch.setattr(task, "run_block", _crash_on_third(real, ran))
    with pytest.raises(Crash):
        _run(area, out)
    assert not out.exists() and len(list(journal_path(out).glob("block-*"))) == 2

    def counting(spec, options):
        ran.append(spec.index)
        return real(spec, options)

    monkeypatch.setattr(task, "run_block", counting)
    first, ran[:] = list(ran), []
    summary = _run(area, out, resume=True)
    assert out.read_bytes() == reference[0]
    assert summary.resumed == 2 and sorted(ran + first) == list(range(summary.blocks))
    assert not journal_path(out).exists()


def test_a_run_on_auto_workers_resumes_on_the_workers_it_was_planned_for(
        area, reference, tmp_path, monkeypatch):
    """``workers="auto"`` forking workers, crashed half-way, is resumed by the same call:
    the count (hence the plan its journal is keyed on) does not depend on the machine's
    load, and the output is the bytes of one process."""
    import threading

    from lidar2city.tools import reconstruct as R

    if engine.local_executor() != "fork":
        pytest.skip("this platform does not fork")
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS", {"fork": 1e-6, "dask": 1e-6})
    monkeypatch.setattr(R, "usable_cores", lambda: 2)
    # the threads earlier tests may have left in this process set aside
    monkeypatch.setattr(threading, "enumerate", lambda: [threading.current_thread()])
    made, make = [], engine.make_executor

    def recorded(workers, *a, **k):
        made.append(workers)
        return make(workers, *a, **k)

    monkeypatch.setattr(engine, "make_executor", recorded)
    real, ran = task.run_block, []
    out = tmp_path / "a.city.json"
    monkeypatch.setattr(task, "run_block", _crash_on_third(real, ran))
    with pytest.raises(Crash):
        _run(area, out, workers="auto")
    assert not out.exists() and list(journal_path(out).glob("block-*"))
    monkeypatch.setattr(task, "run_block", real)
    summary = _run(area, out, workers="auto", resume=True)
    assert out.read_bytes() == reference[0]
    assert summary.resumed >= 2 and made == [2, 2]
    assert not journal_path(out).exists()


def test_a_journal_of_other_options_is_an_error_without_and_with_resume(
        area, tmp_path, monkeypatch, crash_after_first_block):
    out = tmp_path / "j.city.json"
    with pytest.raises(crash_after_first_block):
        _run(area, out)
    assert journal_path(out).exists()
    monkeypatch.undo()
    with pytest.raises(InputError, match="--resume"):
        _run(area, out, block_size=60.0)
    with pytest.raises(InputError, match="another run"):
        _run(area, out, block_size=60.0, resume=True)
    assert not out.exists()


def test_a_block_failing_once_is_retried_and_twice_gives_its_buildings_a_reason(
        area, reference, tmp_path, monkeypatch):
    real, calls, broken = task.run_block, Counter(), {"for good": False}

    def flaky(spec, options):
        calls[spec.index] += 1
        if spec.index == 1 and (broken["for good"] or calls[1] == 1):
            raise RuntimeError("disk on fire")
        return real(spec, options)

    monkeypatch.setattr(task, "run_block", flaky)
    out = tmp_path / "once.city.json"
    _run(area, out)  # fails once, retried: nothing lost
    assert calls[1] == 2 and out.read_bytes() == reference[0]
    calls.clear()
    broken["for good"] = True
    out = tmp_path / "twice.city.json"
    summary = _run(area, out)
    assert calls[1] == 2
    lost = json.loads(out.read_text())["CityObjects"]
    reasons = {a["attributes"].get("reason") for a in lost.values() if a["type"] == "Building"}
    assert "block failed twice: RuntimeError: disk on fire" in reasons
    assert 0 < summary.failed < summary.total and summary.done == summary.total - summary.failed
    assert not journal_path(out).exists()


def test_a_dead_workers_task_is_run_again_on_another_worker(tmp_path):
    marker = tmp_path / "died"

    def square_or_die(i):
        if i == 2 and not marker.exists():
            marker.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        return i * i

    with DaskExecutor(workers=2) as ex:
        got = dict(ex.map(square_or_die, range(5)))
    assert marker.exists() and got == {i: i * i for i in range(5)}


@pytest.mark.parametrize("balance", [False, True])
def test_the_client_computes_beside_its_worker_every_item_once(balance):
    """``client_computes``: one worker process for ``workers=2``, this process running
    its share of the items (and any the cluster has not got yet); every item's
    result comes back once, from one side or the other."""
    me = os.getpid()

    def square_where(i):
        time.sleep(0.02)
        return i * i, os.getpid()

    with DaskExecutor(workers=2, client_computes=True) as ex:
        ex.ready()  # the cluster up: both sides get items
        got = dict(ex.map(square_where, range(12), costs=[1.0] * 12, balance=balance))
        assert len(ex.process_cpu()) == 1  # one worker process
    assert sorted(got) == list(range(12))
    assert all(v[0] == i * i for i, v in got.items())
    assert len({pid for _, pid in got.values()}) == 2 and me in {pid for _, pid in got.values()}


def test_the_client_takes_the_clusters_runs_while_it_starts(monkeypatch):
    """A cluster slow to start: this process, its share done, runs the cluster's
    runs not handed out yet (the last first); nothing runs twice."""
    real = DaskExecutor._start

    def slow(self):
        time.sleep(1.5)
        return real(self)

    monkeypatch.setattr(DaskExecutor, "_start", slow)
    calls = Counter()

    def count(i):
        calls[i] += 1
        return i

    with DaskExecutor(workers=2, client_computes=True) as ex:
        got = dict(ex.map(count, range(8)))
    assert got == {i: i for i in range(8)} and set(calls.values()) == {1} and len(calls) == 8


def test_a_cluster_that_fails_to_start_leaves_every_item_to_the_computing_client(monkeypatch,
                                                                                   caplog):
    def broken(self):
        raise RuntimeError("no ports left")

    monkeypatch.setattr(DaskExecutor, "_start", broken)
    with DaskExecutor(workers=2, client_computes=True) as ex:
        got = dict(ex.map(lambda i: i * i, range(6)))
        again = dict(ex.map(lambda i: -i, range(3), balance=True))
        assert ex.process_cpu() == {}
    assert got == {i: i * i for i in range(6)} and again == {0: 0, 1: -1, 2: -2}
    assert "did not start (RuntimeError: no ports left)" in caplog.text


def test_a_dead_worker_beside_a_computing_client_has_its_task_run_again(tmp_path):
    marker, me = tmp_path / "died", os.getpid()

    def square_or_die(i):
        if os.getpid() != me and not marker.exists():
            marker.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        time.sleep(0.05)
        return i * i

    with DaskExecutor(workers=2, client_computes=True) as ex:
        ex.ready()
        got = dict(ex.map(square_or_die, range(8)))
    assert marker.exists() and got == {i: i * i for i in range(8)}


def test_a_scheduler_that_does_not_answer_is_an_input_error_in_time(monkeypatch):
    monkeypatch.setattr(engine, "CONNECT_TIMEOUT", 2)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="no Dask scheduler answers"):
        with DaskExecutor(scheduler=f"tcp://127.0.0.1:{_free_port()}"):
            pass
    assert time.perf_counter() - t0 < 15


@pytest.mark.slow
def test_resume_after_sigkill_gives_the_same_bytes(area, reference, tmp_path):
    out = tmp_path / "k.city.json"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    cmd = [sys.executable, "-m", "lidar2city.cli.main", "reconstruct", str(area / "town.laz"),
           "--footprints", str(area / "fp.gpkg"), "--lod", "1.2", "--lod", "1.3",
           "--block-size", str(BLOCK), "-o", str(out), "-q"]
    p = subprocess.Popen(cmd, env=env)
    deadline = time.time() + 120
    while time.time() < deadline and not list(journal_path(out).glob("block-*.pickle")):
        time.sleep(0.05)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert not out.exists()
    done = len(list(journal_path(out).glob("block-*.pickle")))
    assert done >= 1
    r = subprocess.run(cmd + ["--resume"], env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == reference[0]


def test_footprints_are_read_block_by_block_from_gpkg_and_flatgeobuf(area, reference, tmp_path,
                                                                     monkeypatch):
    """The planner scans the footprint file in chunks and keeps references; the blocks read
    their own features by id; the output is the same bytes from a GPKG or a FlatGeobuf."""
    from lidar2city.io import vector
    from lidar2city.tools import reconstruct as rec
    from lidar2city.tools.blocks import FootprintRef

    monkeypatch.setattr(rec, "FOOTPRINT_CHUNK", 4)
    plan = rec.plan_reconstruct([area / "town.laz"], tmp_path / "p.city.json",
                                footprints=area / "fp.gpkg", block_size=BLOCK)
    assert len(plan.specs) >= 3
    assert all(isinstance(s.footprints, FootprintRef) for s in plan.specs)
    positions = sorted(p for s in plan.specs for p in s.footprints.positions)
    assert positions == list(range(plan.total))
    reads = []
    real = vector.read_footprints

    def spy(*a, **kw):
        out = real(*a, **kw)
        reads.append((kw.get("fids"), len(out[0])))
        return out

    monkeypatch.setattr(vector, "read_footprints", spy)
    _run(area, tmp_path / "gpkg.city.json")
    assert (tmp_path / "gpkg.city.json").read_bytes() == reference[0]
    by_block = [n for fids, n in reads if fids is not None]
    assert len(by_block) == len(plan.specs) and sum(by_block) == plan.total
    assert max(n for fids, n in reads if fids is None) <= 4  # the planner's chunks
    fgb = tmp_path / "fp.fgb"
    town = make_town(size=(160.0, 120.0), density=3.0, seed=5, n_trees=5)
    write_polygons(fgb, town.footprints.geometries, {"id": town.footprints.ids},
                   origin=town.cloud.origin, crs=town.cloud.crs, layer="fp")
    # a FlatGeobuf is written in its spatial index's order: the same order in a GeoPackage
    order = [town.footprints.ids.index(i) for i in real(fgb)[0].ids]
    write_polygons(tmp_path / "same.gpkg", [town.footprints.geometries[i] for i in order],
                   {"id": [town.footprints.ids[i] for i in order]}, origin=town.cloud.origin,
                   crs=town.cloud.crs)
    outs = []
    for fp in (fgb, tmp_path / "same.gpkg"):
        outs.append(tmp_path / f"{fp.suffix[1:]}.city.json")
        reconstruct([area / "town.laz"], outs[-1], footprints=fp, lods=("1.2", "1.3"),
                    block_size=BLOCK, workers=2 if fp == fgb else 1)
    assert outs[0].read_bytes() == outs[1].read_bytes()


def test_ids_repeated_across_the_planners_chunks_are_made_unique_as_in_a_whole_read(tmp_path):
    import numpy as np
    import shapely
    from pyproj import CRS

    from lidar2city.io.vector import read_footprints
    from lidar2city.tools.blocks import Frame
    from lidar2city.tools.reconstruct import index_footprints

    boxes = [shapely.box(10 * i, 0, 10 * i + 5, 5) for i in range(5)]
    ids = ["a", "b", "a", "c", "a"]
    write_polygons(tmp_path / "fp.gpkg", boxes, {"id": ids}, origin=(0.0, 0.0, 0.0),
                   crs=CRS("EPSG:28992"))
    frame = Frame(np.zeros(3), CRS("EPSG:28992"), 1.0, 1.0)
    whole, _ = read_footprints(tmp_path / "fp.gpkg")
    for chunk in (1, 2, 5):
        fids, got, bounds = index_footprints(tmp_path / "fp.gpkg", frame, extent=(0, 0, 100, 10),
                                             chunk=chunk)
        assert got == whole.ids == ["a", "b", "a-2", "c", "a-3"]
        assert len(set(fids)) == 5 and bounds.shape == (5, 4)
    fids, got, _ = index_footprints(tmp_path / "fp.gpkg", frame, extent=(18, 0, 32, 10), chunk=2)
    assert got == ["a-2", "c"]  # unique over the whole file, then cut to the extent


@pytest.mark.parametrize("n,workers", [(1, 2), (7, 2), (48, 2), (48, 3), (3, 8)])
def test_a_cluster_takes_runs_of_consecutive_items_covering_all_once(n, workers):
    runs = engine.runs_of(n, workers)
    assert runs[0][0] == 0 and runs[-1][1] == n
    assert all(a < b for a, b in runs)
    assert all(b == c for (_, b), (c, _) in zip(runs[:-1], runs[1:]))
    assert len(runs) == min(n, engine.RUNS_PER_WORKER * workers)
    assert max(b - a for a, b in runs) - min(b - a for a, b in runs) <= 1


@pytest.mark.parametrize("costs", [[1] * 10 + [5] * 38, [0, 0, 0, 0, 100], [3, 1, 2]])
def test_runs_of_equal_cost_cover_every_item_once_in_order(costs, monkeypatch):
    monkeypatch.setattr(engine, "RUNS_PER_WORKER", 2)
    n = len(costs)
    runs = engine.runs_of(n, 2, costs)
    assert runs[0][0] == 0 and runs[-1][1] == n and all(a < b for a, b in runs)
    assert all(b == c for (_, b), (c, _) in zip(runs[:-1], runs[1:]))
    assert len(runs) == min(n, engine.RUNS_PER_WORKER * 2)
    if costs[0] == 1:  # 200 in four shares of 50: cut where each share is reached
        assert runs == [(0, 18), (18, 28), (28, 38), (38, 48)]


@pytest.mark.parametrize("costs,cap", [([20] * 500, 1000), ([1] * 5000, 1000), ([50] * 100, 120),
                                       ([3000, 1, 1, 1], 1000)])
def test_a_run_holds_at_most_max_cost_whatever_the_area(costs, cap):
    """A task returns its run's results together: runs are capped, so a worker holds a
    bounded share whatever the area (more runs than RUNS_PER_WORKER x workers)."""
    n = len(costs)
    runs = engine.runs_of(n, 2, costs, max_cost=cap)
    assert runs[0][0] == 0 and runs[-1][1] == n
    assert all(b == c for (_, b), (c, _) in zip(runs[:-1], runs[1:]))
    biggest = max(costs)
    assert all(sum(costs[a:b]) <= cap + biggest for a, b in runs)
    assert len(runs) >= min(n, -(-sum(costs) // cap))
    # without costs an item counts 1
    assert max(b - a for a, b in engine.runs_of(5000, 2)) <= engine.RUN_MAX_COST


def test_a_run_keeps_only_the_tile_points_its_next_blocks_read(area, tmp_path):
    """After each block of a run the shared cache holds, of each tile, only the points
    inside the boxes of the run's later blocks, in scratch files (none in memory);
    nothing once the run is over."""
    from lidar2city.io.las import SpilledTile
    from lidar2city.tools.reconstruct import plan_reconstruct, run_blocks

    plan = plan_reconstruct([area / "town.laz"], tmp_path / "x.city.json",
                            footprints=area / "fp.gpkg", lods=("1.2",), block_size=BLOCK)
    specs = plan.specs
    assert len(specs) >= 3
    seen = []
    real = task.run_block

    def watching(spec, options):
        out = real(spec, options)
        seen.append(spec.index)
        return out

    def check(k):
        later = [s.world_box for s in specs[k + 1:] if s.world_box is not None]
        for spilled in task._cache.tiles.values():
            assert isinstance(spilled, SpilledTile)  # nothing held in memory between blocks
            world = spilled.load().world()
            x, y = world[:, 0], world[:, 1]
            inside = np.zeros(len(world), dtype=bool)
            for x0, y0, x1, y1 in later:
                inside |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            assert inside.all()  # every kept point is read by a later block

    class Watched(engine.InProcess):
        def map(self, fn, items, *args, run_hook=None, costs=None):
            def hook(run, ahead=()):
                keep = run_hook(run, ahead)

                def after(k):
                    keep(k)
                    check(k)
                return after
            return super().map(fn, items, *args, run_hook=hook, costs=costs)

    task_run = task.run_block
    try:
        task.run_block = watching
        outs = list(run_blocks(Watched(), plan))
    finally:
        task.run_block = task_run
    assert len(outs) == len(specs) and seen == list(range(len(specs)))
    assert not task._cache.tiles and task._cache.later is None


def test_footprints_on_tiles_give_the_same_bytes_on_one_and_two_workers(area, tmp_path):
    from lidar2city.io.vector import read_footprints
    from lidar2city.tools.footprints import footprints_on_tiles

    one, two = tmp_path / "w1.gpkg", tmp_path / "w2.gpkg"
    s1 = footprints_on_tiles([area / "town.laz"], one, block_size=BLOCK)
    s2 = footprints_on_tiles([area / "town.laz"], two, block_size=BLOCK, workers=2)
    assert one.read_bytes() == two.read_bytes()
    assert s1["blocks"] >= 3 and s1["buildings"] == s2["buildings"] >= 5
    assert not s1["failed_blocks"] and not task._cache.tiles
    fps, _ = read_footprints(one)
    assert fps.ids == [f"b{i + 1:05d}" for i in range(s1["buildings"])]


@pytest.mark.parametrize("runs,workers", [(8, 2), (9, 2), (3, 4), (12, 5)])
def test_runs_are_dealt_in_contiguous_shares_first_runs_first(runs, workers):
    """Each worker's share is a stretch of consecutive runs (their inputs pass from
    run to run); every share's first run is handed out before any second run."""
    shares = engine.shares_of(runs, workers)
    assert [a for a, _ in shares] == sorted(a for a, _ in shares) and shares[0][0] == 0
    assert shares[-1][1] == runs and all(b == c for (_, b), (c, _) in zip(shares, shares[1:]))
    assert max(b - a for a, b in shares) - min(b - a for a, b in shares) <= 1
    dealt = engine._dealt(shares)
    assert sorted(r for _, r in dealt) == list(range(runs))
    depth = [r - shares[k][0] for k, r in dealt]
    assert depth == sorted(depth)
    assert all(shares[k][0] <= r < shares[k][1] for k, r in dealt)


def test_a_run_count_is_a_multiple_of_the_workers():
    """More runs than RUNS_PER_WORKER x workers (the cap) still give every worker
    as many runs."""
    runs = engine.runs_of(30, 2, [100] * 30, max_cost=280)  # 3000 / 280: 11 runs at least
    assert len(runs) % 2 == 0 and len(runs) >= 11


def test_a_run_told_of_other_blocks_than_it_gets_next_reads_the_same_points(area, tmp_path):
    """Tiles kept for the blocks a run was told come next hold only their points: a
    run that gets other blocks decodes the tiles again and reads exactly what a
    fresh read gives."""
    from lidar2city.tools.reconstruct import plan_reconstruct

    plan = plan_reconstruct([area / "town.laz"], tmp_path / "x.city.json",
                            footprints=area / "fp.gpkg", lods=("1.2",), block_size=BLOCK)
    specs = [s for s in plan.specs if s.world_box is not None]
    assert len(specs) >= 3
    fresh = []
    for s in specs:
        task._cache.stop()
        fresh.append(task._read_box(s))
    try:
        keep = task.tile_keeper(specs[:1], ahead=specs[-1:])  # told: the last block next
        got = [task._read_box(specs[0])]
        keep(0)
        keep = task.tile_keeper(specs[1:])  # but gets the others
        for k, s in enumerate(specs[1:]):
            got.append(task._read_box(s))
            keep(k)
    finally:
        task._cache.stop()
    for a, b in zip(got, fresh, strict=True):
        assert np.array_equal(a.xyz, b.xyz)
        assert np.array_equal(a.attributes["classification"], b.attributes["classification"])


def test_features_encoded_in_the_blocks_are_the_bytes_the_client_would_write(area, tmp_path,
                                                                              monkeypatch):
    real, encoded = task.encode_block, []

    def spy(out, options):
        out = real(out, options)
        if out.encoded is not None:  # text, and results without geometry
            assert len(out.encoded) == len(out.results)
            assert all(r.footprint is None and not r.parts for r in out.results)
            encoded.append(out.index)
        return out

    monkeypatch.setattr(task, "encode_block", spy)
    out1, out2 = tmp_path / "w1.city.jsonl", tmp_path / "w2.city.jsonl"
    s1 = _run(area, out1)
    assert encoded  # the blocks encoded their buildings
    s2 = _run(area, out2, workers=2)
    # the reference: every building encoded by the client's writer
    monkeypatch.setattr(task, "encode_block", lambda out, options: out)
    ref = tmp_path / "client.city.jsonl"
    s0 = _run(area, ref)
    assert out1.read_bytes() == ref.read_bytes() == out2.read_bytes()
    assert (s1.done, s1.failed, s1.invalid) == (s2.done, s2.failed, s2.invalid) == (
        s0.done, s0.failed, s0.invalid)
    assert s0.done >= 5


def test_no_building_anywhere_leaves_no_journal(tmp_path):
    """A run that finds no building in any block fails with one line; a --resume could
    only fail the same way, so no journal is left beside the missing output."""
    from pyproj import CRS

    from lidar2city.datamodel import PointCloud
    from lidar2city.errors import EmptyInputError

    rng = np.random.default_rng(3)
    xy = rng.uniform(0, [150.0, 60.0], (12000, 2))
    world = np.column_stack([xy + [85000.0, 447000.0], rng.normal(0, 0.03, len(xy))])
    ground = {"classification": np.full(len(xy), 2, np.uint8)}
    write_points(tmp_path / "flat.laz",
                 PointCloud.from_world(world, crs=CRS.from_epsg(28992), attributes=ground))
    out = tmp_path / "o.city.json"
    with pytest.raises(EmptyInputError, match="no building footprint"):
        reconstruct([tmp_path / "flat.laz"], out, block_size=BLOCK)
    assert not out.exists() and not journal_path(out).exists()


@pytest.mark.parametrize("lods", [("1.2", "1.3"), ("1.2", "2.2")])
def test_buildings_built_group_by_group_equal_those_of_the_whole_blocks_cloud(tmp_path, lods,
                                                                             monkeypatch):
    """A block builds its buildings in groups, each with the full-width cloud of its
    footprints' surroundings only: the same results as from the block's whole
    cloud, with groups of a few buildings, a building across groups' cells and
    a building without ground around it (its ground level from the area's
    ground points within 50 m, outside its group's cloud)."""
    import dataclasses

    from lidar2city.datamodel import PointCloud
    from lidar2city.tools.reconstruct import _without_run_attributes, plan_reconstruct

    town = make_town(size=(160.0, 120.0), density=3.0, seed=5, n_trees=5)
    c, g = town.cloud, town.footprints.geometries[0]
    x0, y0, x1, y1 = g.bounds
    xy = c.xyz[:, :2]
    near = (xy[:, 0] > x0 - 15) & (xy[:, 0] < x1 + 15) & (xy[:, 1] > y0 - 15) & (xy[:, 1] < y1 + 15)
    keep = ~(near & (c.attributes["classification"] == 2))  # no ground within 15 m
    cloud = PointCloud(c.xyz[keep], c.origin, c.crs, c.xy_unit, c.z_unit,
                       {k: v[keep] for k, v in c.attributes.items()})
    write_points(tmp_path / "town.laz", cloud)
    write_polygons(tmp_path / "fp.gpkg", town.footprints.geometries, {"id": town.footprints.ids},
                   origin=c.origin, crs=c.crs)
    plan = plan_reconstruct([tmp_path / "town.laz"], tmp_path / "x.city.jsonl",
                            footprints=tmp_path / "fp.gpkg", lods=lods, block_size=200.0)
    assert task._by_groups(plan.specs[0], plan.options)

    def built(grouped):
        monkeypatch.setattr(task, "_by_groups", lambda spec, options: grouped)
        out = []
        for spec in plan.specs:
            task._cache.stop()
            b = task._run_block(spec, plan.options)
            out += [dataclasses.asdict(_without_run_attributes(r)) for r in b.results]
        task._cache.stop()
        return out

    whole = built(False)
    monkeypatch.setattr(task, "GROUP_POINTS", 500)  # groups of a few buildings each
    groups = task.footprint_groups
    seen = []
    monkeypatch.setattr(task, "footprint_groups",
                        lambda *a, **k: seen.append(groups(*a, **k)) or seen[-1])
    from lidar2city.tools import reconstruct as R

    real, area_ground = R.reconstruct_buildings, []

    def spy(*a, **k):
        area_ground.append(k["area_ground"])
        return real(*a, **k)

    monkeypatch.setattr(R, "reconstruct_buildings", spy)
    grouped = built(True)
    assert sum(len(g) for g in seen) >= 2  # several groups
    assert {r["attributes"].get("ground_source") for r in whole} > {"ring"}
    assert len(grouped) == len(whole) >= 5
    for a, b in zip(grouped, whole, strict=True):
        assert repr(a) == repr(b)
    # the area's ground level of a building without any ground near it (a rare
    # last resort): the ground points of the whole block's cloud within 50 m
    cloud = task._read_box(plan.specs[0])
    task._cache.stop()
    gz = cloud.xyz[np.isin(cloud.attributes["classification"], plan.options.config.ground_classes)]
    for x0, y0, x1, y1 in [(x0 - 50, y0 - 50, x1 + 50, y1 + 50), (-1e3, -1e3, 1e3, 1e3),
                           (10.0, 20.0, 60.5, 70.25)]:
        box = (gz[:, 0] >= x0) & (gz[:, 0] <= x1) & (gz[:, 1] >= y0) & (gz[:, 1] <= y1)
        assert box.sum() > 0
        assert np.array_equal(np.sort(area_ground[0](x0, y0, x1, y1)), np.sort(gz[box, 2]))


@pytest.mark.slow
def test_delft_built_group_by_group_is_the_same_bytes_as_from_whole_blocks(data, tmp_path,
                                                                          monkeypatch):
    """Real AHN3 points and BGT footprints (132 row houses), blocks of 100 m, groups
    of a few houses each: the same output as every block's whole cloud."""
    tile = data / "delft" / "ahn3_cropped_1.laz"
    fp = data / "delft" / "footprints_bgt.gpkg"
    monkeypatch.setattr(task, "GROUP_POINTS", 20_000)
    seen = []
    real = task._run_groups
    monkeypatch.setattr(task, "_run_groups", lambda *a: seen.append(1) or real(*a))
    out = {}
    for mode in ("groups", "whole"):
        if mode == "whole":
            monkeypatch.setattr(task, "_by_groups", lambda spec, options: False)
        out[mode] = tmp_path / f"{mode}.city.jsonl"
        s = reconstruct([tile], out[mode], footprints=fp, lods=("1.2", "1.3"), crs="EPSG:7415",
                        block_size=100.0)
        assert s.done >= 100
    assert len(seen) >= 4  # the blocks went group by group
    assert out["groups"].read_bytes() == out["whole"].read_bytes()


def test_local_worker_exits_without_interpreter_teardown(tmp_path):
    """A worker of our own cluster, once closed, ends at its first exit handler: the
    handlers registered before (and the interpreter's teardown) are skipped, what it
    printed is flushed, and it exits with status 0."""
    import subprocess
    import sys

    code = ("import atexit, sys\n"
            "atexit.register(lambda: open(sys.argv[1], 'w').write('torn down'))\n"
            "from lidar2city.tools.engine import _warm\n"
            "_warm(True)\n"
            "print('worked', end='')\n")
    marker = tmp_path / "marker"
    r = subprocess.run([sys.executable, "-c", code, str(marker)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout == "worked"
    assert not marker.exists()
    # an external cluster's worker is left to end as it does
    code = code.replace("_warm(True)", "_warm(False)")
    r = subprocess.run([sys.executable, "-c", code, str(marker)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0 and marker.read_text() == "torn down"


def test_local_cluster_leaves_no_process():
    """A local cluster's worker processes, and the server they were forked from, are
    gone (reaped, not zombies) once the last executor of the process has closed; a
    cluster closed while another is open leaves the other's workers running."""
    from multiprocessing import forkserver

    def square(i):
        return i * i

    with DaskExecutor(workers=1) as outer:
        outer.ready()
        pids = list(outer._client.run(os.getpid).values())
        with DaskExecutor(workers=1) as inner:
            inner.ready()
            pids += list(inner._client.run(os.getpid).values())
            if engine.START_METHOD == "forkserver":
                pids.append(forkserver._forkserver._forkserver_pid)
        assert dict(outer.map(square, range(3))) == {0: 0, 1: 1, 2: 4}
        assert list(outer._client.run(os.getpid).values()) == pids[:1]
    assert len(set(pids)) == len(pids) and all(pids)
    if engine.START_METHOD == "forkserver":
        assert forkserver._forkserver._forkserver_pid is None
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_one_block_cut_into_parts_for_two_workers_gives_the_same_bytes(area, tmp_path,
                                                                       monkeypatch):
    """A block of many buildings (here the whole area) is one spec for one process
    and cut into parts of its footprints for two workers, which share it: the
    same bytes."""
    from lidar2city.tools import blocks

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)  # parts of 2 buildings at least
    one, two = tmp_path / "w1.city.json", tmp_path / "w2.city.json"
    s1 = _run(area, one, block_size=1000.0)
    s2 = _run(area, two, block_size=1000.0, workers=2)
    assert s1.blocks == 1 and s2.blocks > 1
    assert s2.done == s1.done >= 8
    assert two.read_bytes() == one.read_bytes()


@pytest.mark.parametrize("n,split", [(5, 8), (9, 8), (17, 8), (132, 17)])
@pytest.mark.parametrize("weighted", [False, True])
def test_a_split_block_gives_parts_covering_its_footprints_once(n, split, weighted):
    """Strips of decreasing work, the first about RAMP times the last: handed out in
    order, the small last ones even out the workers' ends."""
    from lidar2city.tools.blocks import RAMP, _split_parts, footprint_work

    rng = np.random.default_rng(n)
    centre = rng.uniform(0, 200, (n, 2))
    empty = np.zeros(n, dtype=bool)
    empty[::7] = True
    size = rng.uniform(5, 40, (n, 2))
    bounds = np.column_stack([centre - size / 2, centre + size / 2])
    bounds[empty] = np.nan
    work = footprint_work(bounds) if weighted else None
    assert weighted or np.allclose(footprint_work(np.ones((3, 4))), 1.0)
    if weighted:
        assert np.isclose(work.mean(), 1.0) and np.all(work[empty] == 0.5)
    block = np.arange(n)  # in footprint order, as footprint_blocks gives it
    parts = _split_parts(block, centre, empty, split, work)
    assert sorted(i for p in parts for i in p) == list(range(n))
    assert all(len(p) > 0 and p == sorted(p) for p in parts)
    want = 1 if n <= split else -(-n // split)
    assert want - 1 <= len(parts) <= want
    w = np.ones(n) if work is None else work
    totals = [float(w[p].sum()) for p in parts]
    if len(parts) > 2:
        # decreasing, up to one footprint's work at each cut
        assert all(a >= b - 2 * w.max() for a, b in zip(totals, totals[1:], strict=False))
        assert totals[0] > totals[-1] and totals[0] / totals[-1] <= 2 * RAMP
    assert _split_parts(block, centre, empty, split, work) == parts  # deterministic


def test_blocks_where_the_workers_shares_meet_are_found_by_their_footprints():
    from lidar2city.tools.blocks import MEET_SHARE, meet_blocks, meet_size

    sizes = [10, 10, 10, 10, 10, 10, 10, 10, 10, 10]  # the middle at 50 +- 10
    assert MEET_SHARE == 0.1 and meet_blocks(sizes, 2) == {4, 5}
    assert meet_blocks(sizes, 1) == set() and meet_blocks([], 2) == set()
    assert meet_blocks([0, 0, 0], 2) == set()
    assert meet_blocks([200, 1, 1, 1], 2) == {0}  # one block holding the place
    assert meet_blocks(sizes, 3) == {2, 3, 4, 5, 6, 7}  # 33.3 +- 10 and 66.7 +- 10
    assert meet_size(2112, 2) == 66 and meet_size(10, 2) == 8


def test_whole_blocks_where_the_shares_meet_are_cut_into_equal_parts():
    """With several workers, whole blocks holding the place where two shares meet
    are cut into parts of at most meet_size footprints; the other blocks stay whole."""
    from lidar2city.tools.blocks import Frame, footprint_blocks, meet_size

    # a row of 10 blocks of 100 m, 10 footprints of 10 m each
    x = np.repeat(np.arange(10) * 100.0, 10) + np.tile(np.arange(10) * 9.0 + 2.0, 10)
    bounds = np.column_stack([x, np.full(100, 5.0), x + 5.0, np.full(100, 15.0)])
    frame = Frame(np.zeros(3), None, 1.0, 1.0)

    def plan(**kw):
        return footprint_blocks((), frame, bounds, 100.0, 10.0, lambda idx: list(idx), **kw)

    whole, cut = plan(split=20), plan(split=20, meet=2)
    assert len(whole) == 10 and all(len(s.footprints) == 10 for s in whole)
    assert meet_size(100, 2) == 8
    cells = Counter(s.cell for s in cut)
    assert {c for c, k in cells.items() if k > 1} == {whole[4].cell, whole[5].cell}
    assert all(k <= 2 for k in cells.values()) and len(cells) == 10
    assert sorted(i for s in cut for i in s.footprints) == list(range(100))
    parts = [s for s in cut if cells[s.cell] > 1]
    assert all(len(s.footprints) <= 8 and s.cost is not None for s in parts)
    assert [s.index for s in cut] == list(range(len(cut)))
    assert len(plan(split=20, meet=1)) == 10  # one process: no place where shares meet


def test_blocks_cut_where_the_shares_meet_give_the_same_bytes(area, tmp_path, monkeypatch):
    """Blocks no larger than a part, cut where the two workers' shares meet: the
    journal's key knows it, and the bytes are those of one process."""
    from lidar2city.tools import blocks
    from lidar2city.tools.reconstruct import plan_reconstruct

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 1)
    monkeypatch.setattr(blocks, "split_size", lambda total, runs: 5)  # blocks of 4 stay whole
    kw = dict(footprints=area / "fp.gpkg", lods=("1.2", "1.3"))
    one = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=100.0, **kw)
    two = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=100.0,
                           workers=2, **kw)
    assert one.split is None and two.split == (5, 2) and len(two.specs) > len(one.specs)
    out1, out2 = tmp_path / "w1.city.json", tmp_path / "w2.city.json"
    _run(area, out1, block_size=100.0)
    _run(area, out2, block_size=100.0, workers=2)
    assert out2.read_bytes() == out1.read_bytes()


def test_only_parts_of_blocks_cut_for_the_workers_are_dealt_one_by_one(area, tmp_path,
                                                                       monkeypatch):
    """Parts of a block cut for the workers (whose tiles every worker holds) go one by
    one, largest first, to the free worker; whole blocks go in runs of neighbours."""
    from lidar2city.tools import blocks
    from lidar2city.tools.reconstruct import dealt_one_by_one, plan_reconstruct

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)
    kw = dict(footprints=area / "fp.gpkg", lods=("1.2",))
    whole = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=BLOCK,
                             workers=2, **kw)
    cut = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=1000.0,
                           workers=2, **kw)
    assert not dealt_one_by_one(whole, whole.specs)
    assert cut.split is not None and len(cut.specs) > 2 and dealt_one_by_one(cut, cut.specs)
    assert isinstance(cut.split, int)  # no block cut only where shares meet: the key as before
    assert not dealt_one_by_one(cut, [])
    works = [s.work for s in cut.specs]
    assert works[0] > works[-1] and np.isclose(sum(works), sum(s.size for s in cut.specs))


def test_an_interrupted_run_releases_every_semaphore_it_registered():
    """A semaphore registered with the resource tracker but not yet given its finalizer
    (a nanny's queue being made in the cluster's thread when Ctrl-C came) is released
    too, so the tracker has nothing to warn of after the run's last line."""
    import multiprocessing
    import os
    from multiprocessing import resource_tracker

    from lidar2city.tools import engine

    if "forkserver" not in multiprocessing.get_all_start_methods():
        pytest.skip("named semaphores are a forkserver / spawn platform's")
    engine._track_semaphores()
    engine._track_semaphores()  # once per process
    lock = multiprocessing.get_context("forkserver").Lock()
    name = lock._semlock.name
    # one made as a nanny's queue is made, stopped between its registration and its finalizer
    from _multiprocessing import SemLock

    bare = SemLock(1, 1, 1, "/mp-l2c-test", False)
    resource_tracker.register(bare.name, "semaphore")
    assert {name, bare.name} <= engine._SEMAPHORES
    engine.release_semaphores()
    assert not {name, bare.name} & engine._SEMAPHORES
    assert not os.path.exists(f"/dev/shm/sem.{name.lstrip('/')}")
    assert not os.path.exists("/dev/shm/sem.mp-l2c-test")


def _traced(area, out, **kw):
    return reconstruct([area / "town.laz"], out, lods=("1.2", "1.3", "2.2"), block_size=1000.0,
                       **kw)


@pytest.fixture(scope="module")
def traced_reference(area, tmp_path_factory):
    out = tmp_path_factory.mktemp("traced") / "w1.city.json"
    summary = _traced(area, out)
    assert summary.blocks < 4 * 2 and summary.done >= 8 and summary.failed == 0
    return out.read_bytes(), summary


class _Three(engine.InProcess):
    """In-process, but planned as for three workers (the two passes of a traced run)."""

    workers = 3


def _traced_in_parts(area, out, resume=False):
    """The traced run of :func:`_traced`, planned for three workers, run in this process."""
    from lidar2city.tools.reconstruct import _reconstruct

    return _reconstruct(_Three(), 0.0, [area / "town.laz"], out, footprints=None,
                        lods=("1.2", "1.3", "2.2"), crs=None, config=None, fmt=None,
                        id_field=None, layer=None, progress=None, method="roof",
                        primitives=None, check_images=None, block_size=1000.0,
                        resume=resume, block_progress=None, edits=None)


@pytest.mark.parametrize("staged", [False, True])
def test_traced_blocks_built_in_parts_give_the_bytes_of_the_whole_block(area, traced_reference,
                                                                        tmp_path, monkeypatch,
                                                                        staged):
    """Without footprints, fewer blocks than the workers' runs: each block is traced
    first, then its buildings are built in parts (their boxes plus the margin, cut
    to the block's box, nothing claimed): the bytes of the block building them.
    A block of few outlines regularises them in its first pass (no second round of
    the executor); ``staged``: every block's outlines are regularised in pieces
    shared by the workers, then assembled: the same bytes."""
    from lidar2city.tools import blocks

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)
    if staged:
        monkeypatch.setattr(task, "STAGED_LEAST", 1)
    out = tmp_path / "parts.city.json"
    calls, pieces = [], []
    first, regularise = task.trace_outlines, task.regularise_parts
    monkeypatch.setattr(task, "trace_outlines", lambda *a: calls.append(1) or first(*a))
    monkeypatch.setattr(task, "regularise_parts",
                        lambda item: pieces.append(item.parts) or regularise(item))
    s = _traced_in_parts(area, out)
    # each block traced once, then built in parts
    assert len(calls) == traced_reference[1].blocks < s.blocks
    assert s.done == traced_reference[1].done
    assert out.read_bytes() == traced_reference[0]
    if staged:  # several pieces
        assert len(pieces) > 1
    else:  # the town's blocks hold fewer outlines than STAGED_LEAST: one pass
        assert not pieces


def test_staged_outlines_are_cut_into_pieces_covering_each_once_heaviest_first(area):
    """The outlines of several staged blocks: every one in one piece, the pieces of
    about equal work (a piece holds at most its share plus one outline), the
    heaviest outlines in the first pieces."""
    from lidar2city.tools.reconstruct import plan_reconstruct

    plan = plan_reconstruct([area / "town.laz"], area / "x.city.json", lods=("1.2",),
                            block_size=BLOCK, workers=3)
    staged = {}
    for spec in plan.specs:
        out = task.trace_outlines(spec, plan.options, least=1)
        if out.staged is not None:
            staged[spec.index] = out.staged
    assert len(staged) >= 2
    items = task.outline_parts(staged, 5)
    seen = sorted((it.block, k) for it in items for k in it.parts)
    assert seen == sorted((b, k) for b, st in staged.items() for k in range(len(st.outlines)))
    work = {b: st.outlines.work() for b, st in staged.items()}
    share = sum(float(w.sum()) for w in work.values()) / 5
    heaviest = max(float(w.max()) for w in work.values())
    # a piece's block parts, in the piece's order
    totals = {}
    for it in items:
        totals[id(it)] = float(work[it.block][list(it.parts)].sum())
        assert it.work == pytest.approx(totals[id(it)])
        assert list(it.parts) == sorted(it.parts)
        assert [int(n) for n in it.outlines.numbers] == list(it.parts)
    assert max(totals.values()) <= share + heaviest + 1e-9
    assert work[items[0].block][list(items[0].parts)].max() == heaviest


def test_a_staged_block_whose_piece_fails_twice_gets_no_footprint_and_says_why(area, caplog,
                                                                               monkeypatch):
    """A piece of a block's outlines that fails twice: that block traced nothing (its
    failure logged as a block whose tracing failed), the other blocks keep theirs,
    as one pass gives them."""
    import logging

    from lidar2city.tools.reconstruct import _regularise_staged, plan_reconstruct

    plan = plan_reconstruct([area / "town.laz"], area / "x.city.json", lods=("1.2",),
                            block_size=BLOCK, workers=3)
    staged, whole = {}, {}
    for spec in plan.specs:
        out = task.trace_outlines(spec, plan.options, least=1)
        if out.staged is not None:
            staged[spec.index] = out.staged
            whole[spec.index] = task.trace_footprints(spec, plan.options).footprints
    bad = sorted(staged)[0]
    real = task.regularise_parts

    def fails(item):
        if item.block == bad:
            raise RuntimeError("no outline here")
        return real(item)

    monkeypatch.setattr(task, "regularise_parts", fails)
    with caplog.at_level(logging.WARNING):
        got = dict(_regularise_staged(engine.InProcess(), plan, staged, lambda out: None))
    assert got[bad] is None
    assert any("block failed twice: RuntimeError: no outline here" in r.getMessage()
               and "no footprint traced there" in r.getMessage() for r in caplog.records)
    for b, fps in got.items():
        if b != bad:
            assert fps.ids == whole[b].ids
            assert [g.wkb for g in fps.geometries] == [g.wkb for g in whole[b].geometries]
            assert fps.attributes == whole[b].attributes


@pytest.mark.parametrize("staged", [False, True])
def test_traced_parts_resumed_after_a_crash_give_the_same_bytes(area, traced_reference, tmp_path,
                                                                monkeypatch, staged):
    """The journal of a traced run built in parts keeps the parts done; a resumed run
    traces again (the same parts) and builds only the others (``staged``: the
    outlines regularised in pieces shared by the workers, both times)."""
    from lidar2city.tools import blocks

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)
    if staged:
        monkeypatch.setattr(task, "STAGED_LEAST", 1)
    real, ran = task.run_block, []
    out = tmp_path / "r.city.json"
    monkeypatch.setattr(task, "run_block", _crash_on_third(real, ran))
    with pytest.raises(Crash):
        _traced_in_parts(area, out)
    assert len(list(journal_path(out).glob("block-*"))) == 2
    first = list(ran)
    monkeypatch.setattr(task, "run_block", lambda spec, options: ran.append(spec.index)
                        or real(spec, options))
    summary = _traced_in_parts(area, out, resume=True)
    assert summary.resumed == 2 and sorted(ran) == list(range(summary.blocks))
    assert not set(ran[2:]) & set(first)
    assert out.read_bytes() == traced_reference[0]


@pytest.mark.parametrize("staged,executor", [(False, None), (True, "fork"), (True, "dask")])
def test_traced_block_shared_by_two_workers_gives_the_same_bytes(area, traced_reference,
                                                                 tmp_path, monkeypatch, staged,
                                                                 executor):
    """A real 2-worker cluster on a one-block traced area: parts, the same bytes
    (``staged``: its outlines regularised by both workers too, forked or a Dask
    cluster's)."""
    from lidar2city.tools import blocks

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)
    if staged:
        monkeypatch.setattr(task, "STAGED_LEAST", 1)
    if executor is not None:
        monkeypatch.setenv(engine.LOCAL_EXECUTOR_ENV, executor)
    out = tmp_path / "w2.city.json"
    s = _traced(area, out, workers=2)
    assert s.blocks > traced_reference[1].blocks and s.done == traced_reference[1].done
    assert out.read_bytes() == traced_reference[0]


@pytest.mark.parametrize("n,k", [(1, 4), (5, 2), (30, 7), (80, 16)])
def test_weighted_parts_cover_every_footprint_once_in_strips_of_about_equal_work(n, k):
    from lidar2city.tools.blocks import _weighted_parts

    rng = np.random.default_rng(n)
    centre = rng.uniform(0, 100, (n, 2)) * [3.0, 1.0]  # wider than high: strips across x
    weights = rng.uniform(1.0, 3.0, n)
    empty = np.zeros(n, dtype=bool)
    parts = _weighted_parts(np.arange(n), centre, empty, weights, k)
    assert sorted(i for p in parts for i in p) == list(range(n))
    assert all(p == sorted(p) and p for p in parts) and len(parts) <= k
    assert len(parts) == min(n, k)  # no weight dominates: every strip holds one at least
    # strips along x, each about an equal share of the work (one footprint of slack)
    assert all(max(centre[a, 0] for a in p) <= min(centre[b, 0] for b in q)
               for p, q in zip(parts[:-1], parts[1:], strict=False))
    work = [weights[p].sum() for p in parts]
    assert max(work) <= weights.sum() / len(parts) + weights.max() + 1e-9
    assert _weighted_parts(np.arange(n), centre, empty, weights, k) == parts


def test_a_traced_part_reads_its_footprints_surroundings_inside_its_blocks_box():
    import shapely

    from lidar2city.datamodel import Footprints
    from lidar2city.tools.blocks import BlockSpec, Frame, traced_parts

    frame = Frame(np.array([1000.0, 2000.0, 0.0]), None, 1.0, 1.0)
    block = BlockSpec(0, (1, 2), (1000.0, 2000.0, 1200.0, 2200.0), (), frame)
    geoms = [shapely.box(10, 10, 20, 20), shapely.box(150, 150, 190, 195)]
    bounds = np.array([g.bounds for g in geoms])
    parts = traced_parts(block, bounds, 51.0, np.array([1.0, 1.0]), 1.0,
                         lambda idx: Footprints([geoms[i] for i in idx], [f"b{i + 1}" for i in idx]),
                         5)
    assert [p.index for p in parts] == [5, 6] and all(p.traced for p in parts)
    assert parts[0].world_box == (1000.0, 2000.0, 1071.0, 2071.0)  # cut to the block's box
    assert parts[1].world_box == (1099.0, 2099.0, 1200.0, 2200.0)
    assert [p.cost for p in parts] == [1.0, 1.0] and parts[1].footprints.ids == ["b2"]


def test_a_tile_decoded_by_the_client_is_loaded_by_the_workers_bit_for_bit(area, tmp_path,
                                                                           monkeypatch):
    """The tiles every worker would decode first are decoded once by the run's client
    (:func:`task.predecode`): a worker loads the saved file instead of decoding the
    LAZ (the same points, bit for bit), decodes the tile itself when the file has
    changed since, and the saved files are gone when the run ends."""
    import contextlib
    import tempfile

    from lidar2city.io.las import read_tile, scan_tiles

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    tile = scan_tiles([area / "town.laz"])[0]
    decoded = []

    def decode():
        decoded.append(1)
        return read_tile(tile.path)

    whole = read_tile(tile.path)
    with contextlib.ExitStack() as stack:
        saved = task.predecode([tile, tile], stack)
        assert len(saved) == 1 and saved[0][0][0] == tile.path
        assert [p.name.startswith("lidar2city-tile-") for p in tmp_path.iterdir()] == [True]
        cache = task._TileCache()
        cache.saved = dict(saved)
        got = cache.get(tile, decode)
        assert not decoded
        assert got.steps.dtype == whole.steps.dtype and np.array_equal(got.steps, whole.steps)
        assert np.array_equal(got.base, whole.base) and np.array_equal(got.scales, whole.scales)
        assert list(got.attrs) == list(whole.attrs)
        assert all(np.array_equal(got.attrs[k], whole.attrs[k]) for k in whole.attrs)
        # the tile rewritten since: its size and time no longer match, decoded here
        st = os.stat(tile.path)
        os.utime(tile.path, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
        try:
            task._TileCache.__init__(cache)
            cache.saved = dict(saved)
            cache.get(tile, decode)
            assert decoded == [1]
        finally:
            os.utime(tile.path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert not list(tmp_path.iterdir())  # removed with the run
    # over the budget: nothing decoded ahead
    monkeypatch.setattr(task, "PREDECODE_POINTS", tile.count - 1)
    with contextlib.ExitStack() as stack:
        assert task.predecode([tile], stack) == ()
    # a tile that cannot be decoded is left to the blocks (they state its reason)
    import dataclasses

    bad = tmp_path / "bad.laz"
    bad.write_bytes(b"LASF" + bytes(300))
    monkeypatch.setattr(task, "PREDECODE_POINTS", 10 ** 9)
    with contextlib.ExitStack() as stack:
        assert task.predecode([dataclasses.replace(tile, path=str(bad))], stack) == ()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("lidar2city-tile-")]


@pytest.mark.parametrize("executor", ["dask", "fork"])
def test_only_blocks_cut_for_the_workers_have_their_tiles_decoded_ahead(area, tmp_path,
                                                                        monkeypatch, executor):
    """A plan of whole blocks decodes nothing in the client; a block cut into parts
    for two workers has its tiles decoded ahead (saved for a Dask cluster's
    workers, held in memory for workers forked from the client); a 2-worker run
    of it gives the bytes of one process and leaves no saved or held tile behind."""
    import tempfile

    if executor == "fork" and not engine.local_executor() == "fork":
        pytest.skip("this platform does not fork")
    monkeypatch.setenv(engine.LOCAL_EXECUTOR_ENV, executor)

    from lidar2city.tools import blocks
    from lidar2city.tools.reconstruct import plan_reconstruct, shared_tiles

    monkeypatch.setattr(blocks, "SPLIT_LEAST", 2)
    kw = dict(footprints=area / "fp.gpkg", lods=("1.2", "1.3"))
    whole = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=BLOCK,
                             workers=2, **kw)
    assert whole.split is None and shared_tiles(whole) == []
    cut = plan_reconstruct([area / "town.laz"], tmp_path / "a.city.json", block_size=1000.0,
                           workers=2, **kw)
    assert cut.split is not None
    assert {t.path for t in shared_tiles(cut)} == {str(area / "town.laz")}
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    calls = []

    def predecode(tiles, stack):
        calls.append(saved := real(tiles, stack))
        return saved

    def hold_tiles(tiles, stack):
        calls.append([None] * (held := real_hold(tiles, stack)))
        return held

    real, real_hold = task.predecode, task.hold_tiles
    monkeypatch.setattr(task, "predecode" if executor == "dask" else "hold_tiles",
                        predecode if executor == "dask" else hold_tiles)
    one, two = tmp_path / "w1.city.json", tmp_path / "w2.city.json"
    _run(area, one, block_size=1000.0)
    assert not calls  # one process decodes each tile once anyway
    s2 = _run(area, two, block_size=1000.0, workers=2)
    assert len(calls) == 1 and len(calls[0]) == 1
    assert s2.blocks > 1 and two.read_bytes() == one.read_bytes()
    assert not [p for p in scratch.iterdir() if p.name.startswith("lidar2city-tile-")]
    assert not task._cache.held


def test_workers_auto_gives_each_worker_enough_work(area, monkeypatch):
    """``workers="auto"``: one worker per ``AUTO_LEAST_SECONDS`` of expected work (header
    points x the cost of what is built), at most the cores, at least 1; a Dask cluster
    (no fork) needs more work a worker than forked workers; the machine's load is not
    looked at (the same command, the same plan: ``--resume`` finds its journal)."""
    from lidar2city.io import las
    from lidar2city.tools import reconstruct as R

    laz = area / "town.laz"
    # the threads earlier tests may have left in this process set aside (their own test)
    monkeypatch.setattr(R, "fork_hazard", lambda: None)
    kw = dict(footprints=area / "fp.gpkg", lods=("1.2",))
    for executor in ("fork", "dask"):
        assert R.auto_workers([laz], cores=2, executor=executor, **kw) == 1  # a small town
        assert R.auto_workers([laz], cores=1, executor=executor, **kw) == 1
    n = las.count_points([laz])
    # LoD2.2 and traced footprints cost more per point than LoD1 alone
    rates = R.AUTO_SECONDS_PER_POINT
    assert rates["lod1"] < rates["lod22"] < rates["traced"]
    assert R.AUTO_LEAST_SECONDS["fork"] < R.AUTO_LEAST_SECONDS["dask"]
    # the town's LoD2.2 worth 2.5 workers on a fork, 1.25 on a cluster
    least = n * rates["lod22"] / 2.5
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS", {"fork": least, "dask": 2 * least})
    lod22 = dict(footprints=kw["footprints"], lods=("1.2", "2.2"))
    assert R.auto_workers([laz], cores=3, executor="fork", **kw) == 1  # LoD1: too little
    assert R.auto_workers([laz], cores=3, executor="fork", **lod22) == 2
    assert R.auto_workers([laz], cores=2, executor="fork", **lod22) == 2
    assert R.auto_workers([laz], cores=1, executor="fork", **lod22) == 1
    assert R.auto_workers([laz], cores=3, executor="dask", **lod22) == 1
    assert R.auto_workers([laz], cores=8, executor="fork") == 8  # traced: 8 x 2.5 x 5.5 / 18
    assert R.auto_workers([laz], cores=3, executor="dask") == 3
    assert "load" not in inspect.signature(R.auto_workers).parameters


def test_workers_auto_opens_headers_only_until_the_cores_are_covered(area, monkeypatch):
    from lidar2city.io import las
    from lidar2city.tools import reconstruct as R

    laz = area / "town.laz"
    n = las.count_points([laz])
    opened = []
    real = las.check_input_file

    def counted(p):
        opened.append(p)
        return real(p)

    monkeypatch.setattr(las, "check_input_file", counted)
    assert las.count_points([laz] * 5, at_least=n + 1) == 2 * n and len(opened) == 2
    assert R.usable_cores() >= 1
    # two workers need the points of half the tile: its header alone is read
    monkeypatch.setattr(R, "fork_hazard", lambda: None)
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS",
                        {"fork": n / 4 * R.AUTO_SECONDS_PER_POINT["lod22"], "dask": 1.0})
    opened.clear()
    assert R.auto_workers([laz] * 5, cores=2, executor="fork", footprints=area / "fp.gpkg",
                          lods=("2.2",)) == 2
    assert len(opened) == 1


def test_workers_auto_does_not_fork_beside_other_threads_or_off_the_main_thread(area,
                                                                               monkeypatch):
    """A fork copies only the forking thread: another thread's locks stay held in the
    child. ``auto`` forks no worker while another Python thread is alive (a test
    runner's, a Dask client's) or when called from a thread other than the main one;
    a Dask cluster (no fork) is not concerned."""
    import threading

    from lidar2city.io import las
    from lidar2city.tools import reconstruct as R

    laz = area / "town.laz"
    n = las.count_points([laz])
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS", {"fork": 1e-9, "dask": 1e-9})
    alive = threading.enumerate
    # the threads earlier tests may have left in this process (a cluster's) set aside
    monkeypatch.setattr(threading, "enumerate", lambda: [threading.current_thread()])
    assert R.fork_hazard() is None
    assert R.auto_workers([laz], cores=2, executor="fork") == 2
    monkeypatch.setattr(threading, "enumerate", lambda: [threading.current_thread(), *(
        t for t in alive() if t.name == "someone-elses")])
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, name="someone-elses", daemon=True)
    other.start()
    try:
        assert "someone-elses" in R.fork_hazard()
        assert R.auto_workers([laz], cores=2, executor="fork") == 1
        assert R.auto_workers([laz], cores=2, executor="dask") == 2
    finally:
        stop.set()
        other.join()
    got = []
    t = threading.Thread(target=lambda: got.append((R.fork_hazard(), R.auto_workers(
        [laz], cores=2, executor="fork"))))
    t.start()
    t.join()
    assert "not the main one" in got[0][0] and got[0][1] == 1
    assert n > 0


def test_workers_auto_runs_in_one_process_under_a_profiler_or_tracer(area, monkeypatch):
    """``python -m cProfile``, a debugger or coverage watch this process only: ``auto``
    then runs in it, whichever executor, so that their figures hold the run's work."""
    import sys

    from lidar2city.tools import reconstruct as R

    laz = area / "town.laz"
    monkeypatch.setattr(R, "AUTO_LEAST_SECONDS", {"fork": 1e-9, "dask": 1e-9})
    monkeypatch.setattr(R, "fork_hazard", lambda: None)
    before = (sys.getprofile(), sys.gettrace())
    if any(before):
        pytest.skip("this test process is already profiled or traced")
    assert R.observer() is None
    assert R.auto_workers([laz], cores=2, executor="fork") == 2
    for hook in (sys.setprofile, sys.settrace):
        hook(lambda *a: None)
        try:
            watched = R.observer()
            workers = [R.auto_workers([laz], cores=2, executor=e) for e in ("fork", "dask")]
        finally:
            hook(None)
        assert watched is not None and workers == [1, 1]


def test_semaphores_made_after_an_interrupt_closed_them_are_never_left_to_the_tracker():
    """An interrupted run closes the registrations before it kills its workers: a
    nanny then making new queues for the worker it starts in place of one killed (six
    semaphores) must not leave them to the resource tracker, which would warn of
    "leaked semaphore objects" after the run's last line. In a process of its own:
    the closing is not undone."""
    import multiprocessing
    import subprocess
    import sys

    if "forkserver" not in multiprocessing.get_all_start_methods():
        pytest.skip("named semaphores are a forkserver / spawn platform's")
    code = """
import multiprocessing, os, sys
from lidar2city.tools import engine
engine._track_semaphores()
ctx = multiprocessing.get_context("forkserver")
kept = ctx.Lock()
engine.close_semaphores()
queue = ctx.Queue()   # as a nanny makes them for a worker it restarts
made = [queue._rlock._semlock.name, queue._wlock._semlock.name, queue._sem._semlock.name]
assert kept._semlock.name in engine._SEMAPHORES
assert not set(made) & engine._SEMAPHORES, made
assert not [n for n in made if os.path.exists("/dev/shm/sem." + n.lstrip("/"))], made
engine.release_semaphores()
sys.stdout.flush()
os._exit(0)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert "leaked" not in done.stderr, done.stderr


_FINALIZER_RACE = """
import multiprocessing, os, sys, threading, time
from multiprocessing import resource_tracker, synchronize, util
from lidar2city.tools import engine
engine._track_semaphores()
lock = multiprocessing.get_context("forkserver").Lock()
name = lock._semlock.name
# its finalizer, run by a cluster's thread as the interrupt comes: taken out of the
# registry (as Finalize does first), the semaphore unlinked, the tracker not yet told
key = next(k for k, f in util._finalizer_registry.items() if f._args == (name,))
del util._finalizer_registry[key]
synchronize.sem_unlink(name)
if sys.argv[1] == "slow":  # the thread is telling the tracker, slowly, when it comes
    tracker = resource_tracker._resource_tracker
    send = tracker._send
    def slow(*args):
        time.sleep(0.5)
        return send(*args)
    tracker._send = slow
    threading.Thread(target=resource_tracker.unregister, args=(name, "semaphore")).start()
    time.sleep(0.1)
    engine.close_semaphores()
    engine.release_semaphores()
else:  # the thread tells the tracker just after the run released everything
    engine.close_semaphores()
    engine.release_semaphores()
    resource_tracker.unregister(name, "semaphore")
sys.stderr.flush()
os._exit(130)
"""


@pytest.mark.parametrize("when", ["slow", "late"])
def test_an_interrupt_racing_a_semaphore_finalizer_leaves_the_tracker_nothing(when):
    """A semaphore's finalizer running in a cluster's thread when Ctrl-C comes has
    unlinked it but not told the tracker: the interrupted run neither cuts it off
    between the two (the tracker then warned of a leaked semaphore it could not
    unlink: CI, session 14) nor tells the tracker twice (it then printed a KeyError's
    traceback)."""
    import multiprocessing
    import subprocess
    import sys

    if "forkserver" not in multiprocessing.get_all_start_methods():
        pytest.skip("named semaphores are a forkserver / spawn platform's")
    done = subprocess.run([sys.executable, "-c", _FINALIZER_RACE, when], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 130, done.stderr
    assert "leaked" not in done.stderr and "Traceback" not in done.stderr, done.stderr


_HELD_LOCK = """
import multiprocessing, os, sys, threading, time
from multiprocessing import resource_tracker, synchronize
from lidar2city.tools import engine
engine._track_semaphores()
lock = multiprocessing.get_context("forkserver").Lock()
name = lock._semlock.name
held = threading.Event()
def hold():  # a thread holding the registrations' lock while it waits on the tracker
    with engine._SEMAPHORE_LOCK:
        held.set()
        time.sleep(4.0)
threading.Thread(target=hold, daemon=True).start()
held.wait()
t0 = time.perf_counter()
resource_tracker.unregister(name, "semaphore")
waited = time.perf_counter() - t0
synchronize.sem_unlink(name)
print(f"{waited:.2f}")
sys.stdout.flush()
os._exit(0)
"""


def test_a_semaphore_finalizer_waits_for_the_registrations_lock_at_most_a_second():
    """A finalizer the collector runs inside the tracker's own lock must not wait for
    ever on a thread holding the registrations' lock (that thread may be waiting for
    the tracker's): it goes on after a second, as CPython's would without the lock."""
    import multiprocessing
    import subprocess
    import sys

    if "forkserver" not in multiprocessing.get_all_start_methods():
        pytest.skip("named semaphores are a forkserver / spawn platform's")
    done = subprocess.run([sys.executable, "-c", _HELD_LOCK], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert 0.9 <= float(done.stdout) < 3.0, done.stdout
    assert "leaked" not in done.stderr and "Traceback" not in done.stderr, done.stderr


@pytest.mark.parametrize("balance", [False, True])
def test_run_dealer_hands_every_run_out_once(balance):
    """Whatever order the sides ask in, each run goes out once; this process starts on
    the last share (the front of the queue with ``balance``), a worker on its own, and
    a run given back is this process's next."""
    import random

    from lidar2city.tools.engine import RunDealer

    for seed in range(20):
        rng = random.Random(seed)
        dealer = RunDealer(11, 2, balance=balance)
        first = dealer.mine()[0]
        assert first == (0 if balance else 7)  # shares (0, 3), (3, 7), (7, 11)
        if not balance:
            assert dealer.theirs(0)[0] == 0 and dealer.theirs(1)[0] == 3
        got = [first] + ([] if balance else [0, 3])
        while True:  # a worker with none left stops; this process takes from every share
            here = rng.random() < 0.5
            r, ahead = dealer.mine() if here else dealer.theirs(rng.randrange(2))
            if r is None:
                if here:
                    break
                continue
            assert len(ahead) <= 3 and r not in ahead
            got.append(r)
        assert sorted(got) == list(range(11))
        dealer.rerun.append(5)
        assert dealer.mine() == (5, []) and dealer.mine() == (None, [])
